"""The unseen-layout experiment (``generalisation`` in params.yaml; docs/unseen-layouts.md): do the learned
methods transfer to maps they were not trained on? What is its own are the layout splits (:func:`layout_splits`):
``train`` = the family's generated layouts of seeds ``0..N-1``, ``heldout`` = seeds from :data:`HELDOUT_SEED` on,
``minigrid`` = the ``minigrid`` package's own DoorKey grids converted to our layouts (our dynamics), ``drawn`` =
the layout files of a folder (maps of any shape); ``validation`` (seeds from :data:`VALIDATION_SEED` on) chooses
training budgets and is never evaluated. No two splits share a grid. Its stages (:mod:`hnsdt.stages`,
``*_unseen``) run the paper protocol's collection, training and evaluation code on these splits. A layout is
named by its generator and seed, its MiniGrid id and seed, or (drawn) its file's name without the folder.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from hnsdt.compose.config import Params
from hnsdt.envs.generate import check_usable, generate
from hnsdt.envs.layout import Layout, LayoutError, parse_layout

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


def training_layouts(params: Params) -> list[Source]:
    """The training layouts: the family's seeds ``0..train_layouts-1``."""
    g = params.need("generalisation")
    return [Source("train", generate(g.family, s), g.max_steps) for s in range(g.train_layouts)]


def _unseen(params: Params, split: str, seed: int, n: int, seen: list[Source], family: str | None = None):
    """``n`` generated layouts of ``family`` (default: the experiment's) from ``seed`` on, skipping any grid in
    ``seen``."""
    g, texts, out = params.need("generalisation"), {s.layout.text for s in seen}, []
    while len(out) < n:
        layout = generate(family or g.family, seed)
        out += [Source(split, layout, g.max_steps)] if layout.text not in texts else []
        seed += 1
    return out


def _heldout(params: Params, train: list[Source]) -> list[Source]:
    return _unseen(params, "heldout", HELDOUT_SEED, params.need("generalisation").heldout_layouts, train)


def validation_layouts(params: Params) -> list[Source]:
    """The layouts budgets are chosen on: seeds from :data:`VALIDATION_SEED` of the training family, or of each
    of ``validation_families``; none a training or held-out grid."""
    g, train = params.need("generalisation"), training_layouts(params)
    seen = train + _heldout(params, train)
    out = [src for family in (g.validation_families or [g.family])
           for src in _unseen(params, "validation", VALIDATION_SEED, g.validation_layouts, seen, family)]
    _same_flags(train[:1] + out, lambda msg: params.error(f"generalisation.validation_families: {msg}"))
    return out


def drawn_layouts(folder: str | Path, max_steps: int) -> list[Source]:
    """Every layout file (``*.txt``) of ``folder`` and the folders in it, in path order, named by its file name
    without ``.txt`` (two files of one name are refused), as the split ``drawn``; a folder with bad maps is
    refused naming every one of them."""
    files = sorted(Path(folder).rglob("*.txt"))
    if not files:
        raise ValueError(f"generalisation.drawn.folder {folder}: no layout files (*.txt) there")
    twice = sorted(name for name, n in Counter(f.stem for f in files).items() if n > 1)
    if twice:
        raise ValueError(f"generalisation.drawn.folder {folder}: maps of the same name in two folders: "
                         + ", ".join(twice))
    out, bad = [], []
    for f in files:
        try:
            out.append(Source("drawn", parse_layout(f.read_text(), name=f.stem), max_steps))
        except LayoutError as e:
            bad.append(str(e))
    if bad:
        raise LayoutError(f"{folder}: {len(bad)} of {len(files)} maps cannot be used: " + "; ".join(bad))
    return out


def layout_splits(params: Params, evaluated_only: bool = False) -> list[Source]:
    """Every evaluated layout of the experiment, train first; ``evaluated_only`` keeps the evaluated training
    layouts only."""
    from hnsdt.envs.minigrid_adapter import from_minigrid

    g, train = params.need("generalisation"), training_layouts(params)
    out = (train[:g.evaluated_train_layouts] if evaluated_only else train) + _heldout(params, train)
    for src in g.minigrid:
        out += [Source(src.split, from_minigrid(src.id, s), src.max_steps) for s in range(src.layouts)]
    return out + (drawn_layouts(g.drawn.folder, g.drawn.max_steps) if g.drawn is not None else [])


def _same_flags(sources: list[Source], error) -> None:
    """One network reads every layout: all must have the first one's number of keys, doors and items (every
    other layout is named)."""
    others = [s for s in sources if s.layout.n_flags != sources[0].layout.n_flags]
    if others:
        named = ", ".join(f"{s.name} ({s.split}) has {s.layout.n_flags}" for s in others)
        raise error(f"layout {named} keys, doors and items, the {sources[0].split} layouts "
                    f"{sources[0].layout.n_flags} (one network reads every split's flags)")


def check_sources(sources: list[Source], fail_prob: float, yardsticks: int | None = None) -> None:
    """Every layout usable at the highest failure probability (a plan from the start, and the exact optimum
    finishing within the step limit), all with the same flags (one network), no two of a split with one name; the
    refusal names every layout at fault. ``yardsticks``: only the first that many are measured against the optimum
    (the evaluated ones); the others, training data alone, need a plan — a maze whose way is too long for the
    optimum to finish every time within the limit at ``fail_prob`` still shows the way."""
    _same_flags(sources, lambda msg: ValueError(f"generalisation: {msg}"))
    names = [(s.split, s.name) for s in sources]
    twice = sorted({f"{name} ({split})" for split, name in names if names.count((split, name)) > 1})
    if twice:
        raise ValueError(f"generalisation: two layouts of a split share the name {', '.join(twice)}")
    bad = []
    for i, src in enumerate(sources):
        try:
            check_usable(src.layout, src.max_steps, fail_prob, 0.99 if yardsticks is None or i < yardsticks else 0.0)
        except LayoutError as e:
            bad.append(f"{e} ({src.split})")
    if bad:
        raise LayoutError(f"{len(bad)} of {len(sources)} layouts cannot be used: " + "; ".join(bad))
