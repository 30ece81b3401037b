"""The unseen-layout experiment (``generalisation`` in params.yaml; docs/unseen-layouts.md): do the learned
methods transfer to maps they were not trained on? This module holds what is its own: the layout splits.

**Splits** (:func:`layout_splits`): ``train`` = the family's generated layouts of seeds ``0..N-1``, ``heldout`` =
seeds from :data:`HELDOUT_SEED` on, ``minigrid`` = grids the ``minigrid`` package's own DoorKey generator makes,
converted to our layouts (our dynamics, not MiniGrid's), ``drawn`` = the layout files of a folder (hand-drawn
maps of any shape). ``validation`` (:func:`validation_layouts`, seeds from :data:`VALIDATION_SEED` on) is where
training budgets are chosen, and is never evaluated. A generated layout whose grid is already in an earlier
split is skipped, so no two splits share a map; every layout is checked usable first (:func:`check_sources`).

Its stages (:func:`hnsdt.core.stages.collect_unseen`, ``plan_unseen``, ``train_unseen``, ``evaluate_unseen``) read
these splits and run the paper protocol's collection, training and evaluation code.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hnsdt.core.config import Params
from hnsdt.envs.layout import Layout

HELDOUT_SEED = 100_000  # held-out layouts are the family's seeds from here on
VALIDATION_SEED = 200_000  # and validation layouts from here on


@dataclass(frozen=True)
class Source:
    """One evaluated or training layout: its split and step limit."""

    split: str
    layout: Layout
    max_steps: int

    @property
    def name(self) -> str:
        return self.layout.name


def settings(params: Params):
    """The experiment's section of params.yaml."""
    return params.need("generalisation")


def training_layouts(params: Params) -> list[Source]:
    """The training layouts: the family's seeds ``0..train_layouts-1``."""
    from hnsdt.envs.generate import generate

    g = settings(params)
    return [Source("train", generate(g.family, s), g.max_steps) for s in range(g.train_layouts)]


def _unseen(params: Params, split: str, first_seed: int, n: int, seen: list[Source],
            family: str | None = None) -> list[Source]:
    """``n`` generated layouts of ``family`` (default: the experiment's) from seed ``first_seed`` on, skipping
    any grid in ``seen``."""
    from hnsdt.envs.generate import generate

    g, texts, out, seed = settings(params), {s.layout.text for s in seen}, [], first_seed
    while len(out) < n:
        layout = generate(family or g.family, seed)
        if layout.text not in texts:
            out.append(Source(split, layout, g.max_steps))
        seed += 1
    return out


def validation_layouts(params: Params) -> list[Source]:
    """The layouts budgets are chosen on: seeds from :data:`VALIDATION_SEED` of the training family, or of each
    of ``validation_families``; none a training or held-out grid."""
    g = settings(params)
    train = training_layouts(params)
    seen = train + _unseen(params, "heldout", HELDOUT_SEED, g.heldout_layouts, train)
    out = [src for family in (g.validation_families or [g.family])
           for src in _unseen(params, "validation", VALIDATION_SEED, g.validation_layouts, seen, family)]
    other = _other_flags(train[:1] + out)
    if other is not None:
        raise params.error(f"generalisation.validation_families: {other.name} has {other.layout.n_flags} keys, doors "
                           f"and items, the training family {g.family} {train[0].layout.n_flags} (one network reads "
                           "both)")
    return out


def drawn_layouts(folder: str | Path, max_steps: int) -> list[Source]:
    """Every layout file (``*.txt``) of ``folder``, by name, as the split ``drawn``."""
    from hnsdt.envs.layout import load_layout

    files = sorted(Path(folder).glob("*.txt"))
    if not files:
        raise ValueError(f"generalisation.drawn.folder {folder}: no layout files (*.txt) there")
    return [Source("drawn", load_layout(f), max_steps) for f in files]


def layout_splits(params: Params, evaluated_only: bool = False) -> list[Source]:
    """Every evaluated layout of the experiment, train first; ``evaluated_only`` keeps the evaluated training
    layouts only."""
    from hnsdt.envs.minigrid_adapter import from_minigrid

    g = settings(params)
    train = training_layouts(params)
    out = train[:g.evaluated_train_layouts] if evaluated_only else list(train)
    out += _unseen(params, "heldout", HELDOUT_SEED, g.heldout_layouts, train)
    for src in g.minigrid:
        out += [Source(src.split, from_minigrid(src.id, s), src.max_steps) for s in range(src.layouts)]
    if g.drawn is not None:
        out += drawn_layouts(g.drawn.folder, g.drawn.max_steps)
    return out


def _other_flags(sources: list[Source]) -> Source | None:
    """The first layout whose keys, doors and items differ in number from the first one's (None: all alike)."""
    return next((s for s in sources if s.layout.n_flags != sources[0].layout.n_flags), None)


def check_sources(sources: list[Source], fail_prob: float) -> None:
    """Every layout usable at the highest failure probability, and all with the same flags (one network)."""
    from hnsdt.envs.generate import check_usable

    other = _other_flags(sources)
    if other is not None:
        raise ValueError(f"generalisation: layout {other.name} ({other.split}) has {other.layout.n_flags} keys, doors "
                         f"and items, the {sources[0].split} layouts {sources[0].layout.n_flags} (one network reads "
                         "every split's flags)")
    for src in sources:
        check_usable(src.layout, src.max_steps, fail_prob)
