"""The unseen-layout experiment: do the learned methods transfer to maps they were not trained on?

Protocol (``generalisation`` in params.yaml; README, "Unseen layouts"):

1. **Layouts** (:func:`layout_splits`): ``train`` = the family's generated layouts of seeds ``0..N-1``,
   ``heldout`` = seeds from :data:`HELDOUT_SEED` on, ``minigrid`` = grids that the ``minigrid`` package's own
   DoorKey generator makes, converted to our layouts (our dynamics, not MiniGrid's), ``drawn`` = the layout files
   of a folder (hand-drawn maps of any shape). ``validation`` (:func:`validation_layouts`, seeds from
   :data:`VALIDATION_SEED` on) is where training budgets are chosen, and is never evaluated. A generated layout
   whose grid is already in an earlier split is skipped, so no two splits share a map. Every layout is checked
   usable (a plan exists, the exact optimum succeeds within ``max_steps``) first.
2. **Collect** (:func:`collect`): noisy-planner episodes on every training layout (from its start and from random
   states), one LeRobot dataset whose frames also store the local view (``observation.view``) and the layout.
3. **Train** (:func:`plan_runs`): every method of ``generalisation.methods`` (decision transformers) and
   ``generalisation.baselines`` with its registry entry's
   ``view_network`` (the same model reading view states, :mod:`hnsdt.models.view`), the knobs of the paper's
   protocol (``train`` and ``models.<family>`` for the transformers, ``baselines.<method>`` for the others);
   offline methods on the dataset, online ones on copies that draw a training layout at every reset.
4. **Evaluate** (:func:`evaluate`): every method × seed × layout × fail_prob, ``episodes`` each, and the
   symbolic baseline as the reference; the exact optimum's expected steps per layout and fail_prob.
   ``episodes.csv`` has one row per episode with its ``split`` and ``layout``; ``summary.csv`` the means;
   ``segments.csv`` one row per sub-goal a plan-following method (HNSDT, the symbolic baseline) pursued: where
   its steps go.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from hnsdt.config import (EnvSpec, Params, baseline_settings, eval_epsilon, executor_config, fill,
                          method_executor, train_settings)
from hnsdt.envs.layout import Layout
from hnsdt.methods import METHODS, REFERENCE, resolve
from hnsdt.methods import method as lookup_method

HELDOUT_SEED = 100_000  # held-out layouts are the family's seeds from here on
VALIDATION_SEED = 200_000  # and validation layouts from here on


@dataclass(frozen=True)
class Source:
    split: str
    layout: Layout
    max_steps: int

    @property
    def name(self) -> str:
        return self.layout.name


def settings(params: Params):
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


def collect_settings(params: Params):
    """The collection of the training layouts' episodes: ``collect``'s seed, fps, licence and fail_probs, the
    noisy planner of ``planner``, ``generalisation.episodes_per_layout`` per start, and
    ``generalisation.random_episodes_per_layout`` random walks (the paper's arm's data)."""
    from hnsdt.data.collect import Behaviour, CollectConfig

    g, collect = settings(params), params.need("collect")
    behaviours = [Behaviour("noisy_planner", g.episodes_per_layout, start, g.epsilon) for start in ("layout", "random")]
    if g.random_episodes_per_layout:
        behaviours.append(Behaviour("random", g.random_episodes_per_layout, "random"))
    return CollectConfig(env_id=f"hnsdt/generated-{g.family}", layout=None, max_steps=g.max_steps,
                         fail_probs=[float(f) for f in collect.fail_probs], behaviours=behaviours, seed=collect.seed,
                         fps=collect.fps, executor=executor_config(params), license=collect.license)


def collect(params: Params, root: str | Path, provenance: dict, progress: bool = True) -> Path:
    """Collect on every training layout and write one LeRobot dataset with views (atomically)."""
    from tqdm import tqdm

    from hnsdt.data.card import card_arguments
    from hnsdt.data.collect import _batch_seed, collect_episodes
    from hnsdt.data.lerobot_io import write_dataset

    g = settings(params)
    base = collect_settings(params)
    train = training_layouts(params)
    check_sources(train, max(base.fail_probs))
    episodes = []
    for i, src in enumerate(tqdm(train, desc="collect generated layouts", unit="layout", disable=not progress)):
        cfg = replace(base, layout=src.layout, seed=_batch_seed(base.seed, 1_000_003, i))
        for ep in collect_episodes(cfg, progress=False):
            ep["layout_index"] = i
            ep["meta"]["layout_index"] = i
            episodes.append(ep)
    layouts = [s.layout for s in train]
    cfg = replace(base, layout=layouts[0])
    meta = {"repo_id": f"local/generated-{g.family}", "env_id": base.env_id, "family": g.family,
            "layout": layouts[0].name, "layouts": [lay.name for lay in layouts], "max_steps": g.max_steps,
            "fps": base.fps, "seed": base.seed, "fail_probs": list(base.fail_probs),
            "behaviours": [vars(b) for b in base.behaviours], "executor": vars(base.executor)}
    card = card_arguments(cfg, episodes, provenance, layouts)
    return write_dataset(root, meta["repo_id"], layouts, episodes, base.fps, meta, card, progress=progress,
                         view_radius=g.view_radius)


def network_configs(params: Params, method: str, seed: int):
    """``(view network config, training config)`` of one method and seed. Nothing in them depends on the maps
    the method is evaluated on: targets are clamped at ``generalisation.max_offset``, timesteps at the training
    episodes' limit."""
    from hnsdt.models.view import view_config

    g = settings(params)
    entry = lookup_method(method)
    if not entry.view_network:
        raise ValueError(f"generalisation: {method} has no network that reads views")
    lay = training_layouts(params)[0].layout
    env = EnvSpec(g.family, f"hnsdt/generated-{g.family}", lay, g.max_steps)
    view_cls = resolve(entry.view_network).config_class
    if entry.stage == "train":  # a decision transformer: `train` and `models.<family>`
        ts, models = train_settings(params), params.models
        if g.family not in models:
            raise params.error(f"missing key models.{g.family} (the decision transformers' size on the "
                               f"generalisation family {g.family})")
        try:
            cfg = view_config(entry.condition, lay.n_flags, g.view_radius, g.max_offset, g.conv_layers,
                              g.value_iterations, max_timestep=g.max_steps, dropout=params.train.dropout,
                              formulation=ts.formulation[method],
                              **models[g.family].model_dump())
        except ValueError as e:
            raise params.error(f"models.{g.family}: {e}") from None
        train_cfg = replace(ts.method_config(method, seed), symmetries=g.symmetries)
        if _budget_on_validation_layouts(params, method):  # the measure acts on the validation layouts:
            train_cfg = replace(train_cfg, validation=0.0)  # every training episode trains
        elif ts.measure.get(method, ("loss",))[0] != "loss":  # acting from held-out states needs one fixed map:
            train_cfg = replace(train_cfg, validation=0.0, epochs=ts.config.epochs)  # here, train.epochs
        return cfg, _budget(params, method, train_cfg)
    budget = g.budgets.get(method, {})  # its env_steps stand in for any family, whatever baselines.<method> maps
    own = (f"generalisation.budgets.{method}.env_steps", budget["env_steps"]) if "env_steps" in budget else None
    bs = baseline_settings(params, method, env, seed, env_steps=own)
    encoder = {"conv_layers": g.conv_layers} if hasattr(view_cls, "conv_layers") else {}  # (the LSTM's, GRU's)
    turned = {"symmetries": g.symmetries} if hasattr(bs.train, "symmetries") else {}  # (offline: episodes)
    return view_cls(**asdict(bs.model), view_radius=g.view_radius, **encoder), _budget(
        params, method, replace(bs.train, **turned))


def _budget_on_validation_layouts(params: Params, method: str) -> bool:
    """Does ``method`` (a DT with a ``train.validation`` entry) stop at the plateau of its steps to the exit on
    the validation layouts (:class:`hnsdt.training.StepsToExit`)?"""
    return (lookup_method(method).stage == "train" and settings(params).validation_layouts > 0
            and method in params.train.validation)


def _budget(params: Params, method: str, train_cfg):
    """``train_cfg`` with ``generalisation.budgets.<method>`` applied: each key a field of its training config,
    with the field's type."""
    key, budget = f"generalisation.budgets.{method}", settings(params).budgets.get(method, {})
    allowed = set(vars(train_cfg)) - {"seed", "device", "behaviours"}
    unknown = sorted(set(budget) - allowed)
    if unknown:
        raise params.error(f"{key}: unknown key {unknown[0]}; expected one of {sorted(allowed)}")
    fixed = {k: v for k, v in vars(train_cfg).items() if k not in budget}
    return fill(params, key, type(train_cfg), budget, **fixed)  # (types checked as for baselines.<method>)


def plan_runs(params: Params, method: str, dataset: str | Path) -> list:
    """One :class:`hnsdt.training.TrainTask` per seed."""
    from hnsdt.data.frames import load_frames
    from hnsdt.training import TrainTask

    g = settings(params)
    if method not in g.learned:
        raise ValueError(f"method {method!r} is not in generalisation.methods {list(g.methods)} or "
                         f"generalisation.baselines {list(g.baselines)}")
    online = lookup_method(method).training == "online"
    if online:
        data = ([s.layout for s in training_layouts(params)], g.max_steps)
        facts = {"family": g.family, "train_layouts": g.train_layouts}
    else:
        from hnsdt.data.format import check_dataset

        radius = check_dataset(dataset).get("view_radius", 0)
        if radius != g.view_radius:
            raise ValueError(f"dataset {dataset}: view radius {radius} (0 = no observation.view), but "
                             f"generalisation.view_radius is {g.view_radius}; collect it with "
                             "`python pipeline/generalisation.py collect`")
        data = load_frames(dataset, method_executor(params, method).operators)  # (the paper's arm: Move labels)
        facts = {"dataset": str(dataset), "family": g.family,
                 "target_return": float(data.returns_to_go[np.unique(data.episode_start)].max())}
    net_cfg, train_cfg = network_configs(params, method, g.seeds[0])  # (the layouts are generated once)
    wanted = list(getattr(train_cfg, "behaviours", ()))
    if not online and wanted and not np.isin(data.policy, wanted).any():
        raise ValueError(f"{method} learns from {wanted} episodes and {dataset} holds none; set "
                         "generalisation.random_episodes_per_layout > 0 (random walks) and collect again")
    measure = None
    if _budget_on_validation_layouts(params, method):
        from hnsdt.training import StepsToExit

        measure = StepsToExit.on_layouts([s.layout for s in validation_layouts(params)], g.max_steps,
                                         params.train.validation[method].starts, method,
                                         method_executor(params, method), facts)
    return [TrainTask(method, seed, net_cfg, replace(train_cfg, seed=seed), data, facts, measure=measure)
            for seed in g.seeds]


# -- evaluation -------------------------------------------------------------------------------------------

@lru_cache(maxsize=None)
def _optimum(layout: Layout, fail_prob: float, max_steps: int) -> tuple[float, float]:
    from hnsdt.oracle import optimum

    best = optimum(layout, fail_prob, max_steps)
    return float(best.steps), float(best.success)


def episode_seed(seed: int, layout_index: int) -> int:
    """The environment seed of a layout for one seed: the same for every method."""
    return int(np.random.SeedSequence([seed, layout_index, 7207]).generate_state(1)[0])


def layout_rows(task, batch, episodes) -> tuple[list[dict], list[dict]]:
    """``(episode rows, sub-goal segment rows)`` of a layout's batch (``batch.key``: the layout's source and the
    episodes per fail_prob), for :func:`hnsdt.evaluation.evaluate.evaluate_run`; only plan-following methods
    have segments (:func:`hnsdt.evaluation.evaluate.segment_facts`)."""
    from hnsdt.evaluation.evaluate import layout_navigator, segment_facts

    src, per_fail_prob = batch.key
    navigator = layout_navigator(src.layout) if any(ep.segments for ep in episodes) else None
    rows, segments = [], []
    for i, ep in enumerate(episodes):
        ids = {"method": task.method, "seed": task.seed, "split": src.split, "layout": src.name,
               "fail_prob": float(batch.fail_prob[i]), "episode": i % per_fail_prob}
        rows.append(ids | {"success": bool(ep.success), "steps": ep.length, "reward": round(ep.ret, 6)})
        if ep.segments:
            segments += [ids | row for row in segment_facts(ep, navigator, ids["fail_prob"])]
    return rows, segments


def layout_batches(seed: int, sources: tuple[Source, ...], fail_probs: tuple[float, ...], episodes: int) -> tuple:
    """One batch per layout: its episodes at every failure probability run together (copies with their own
    fail_prob), one agent call per step for all."""
    from hnsdt.evaluation.evaluate import Batch

    per_copy = tuple(float(p) for p in np.repeat(np.asarray(fail_probs, dtype=np.float64), episodes))
    return tuple(Batch(src.layout, src.max_steps, len(per_copy), per_copy, episode_seed(seed, li), (src, episodes))
                 for li, src in enumerate(sources))


def evaluate(params: Params, models_root: str | Path, out_dir: str | Path, compute=None,
             progress: bool = True) -> pd.DataFrame:
    """Run every method × seed on every evaluated layout; write ``episodes.csv``, ``summary.csv``,
    ``segments.csv`` and ``layouts.csv``."""
    from hnsdt.compute import Compute, run_tasks
    from hnsdt.evaluation.evaluate import EvalTask, evaluate_run
    from hnsdt.fileio import atomic_dir
    from hnsdt.models.checkpoint import load_checkpoint

    g = settings(params)
    fps = tuple(float(f) for f in params.need("evaluate").fail_probs)
    sources = tuple(layout_splits(params, evaluated_only=True))
    check_sources(sources, max(fps))
    methods = [*g.learned, REFERENCE]
    tasks = []
    for method in methods:
        executor = method_executor(params, method)  # (its arm's planner: the paper's arm plans over Move)
        for seed in g.seeds:
            if method == REFERENCE:
                model, meta, eps = None, {}, 0.0
            else:
                path = Path(models_root) / method / f"seed{seed}"
                model, meta = load_checkpoint(path)
                if meta.get("arch") != resolve(METHODS[method].view_network).arch:
                    raise ValueError(f"{path} is not a view model (train it with `python pipeline/generalisation.py "
                                     f"train --method {method}`)")
                eps = eval_epsilon(params, method)
            tasks.append(EvalTask(method, seed, executor, model, meta, eps,
                                  layout_batches(seed, sources, fps, g.episodes), layout_rows))
    results = run_tasks(evaluate_run, tasks, compute or Compute(), desc="evaluate unseen layouts", progress=progress)
    table = pd.DataFrame([row for batches in results for rows, _ in batches for row in rows])
    segments = pd.DataFrame([row for batches in results for _, rows in batches for row in rows])
    optimal = {(s.name, fp): _optimum(s.layout, fp, s.max_steps) for s in sources for fp in fps}
    table["optimal_steps"], table["optimal_success"] = zip(*(optimal[key] for key in zip(table.layout, table.fail_prob)))
    with atomic_dir(Path(out_dir)) as tmp:
        tmp.mkdir()
        table.to_csv(tmp / "episodes.csv", index=False, float_format="%.6g")
        summary(table).to_csv(tmp / "summary.csv", index=False, float_format="%.6g")
        segments.to_csv(tmp / "segments.csv", index=False, float_format="%.6g")
        layouts = pd.DataFrame([{"split": s.split, "layout": s.name, "rows": s.layout.shape[0],
                                 "cols": s.layout.shape[1], "max_steps": s.max_steps} for s in sources])
        layouts.to_csv(tmp / "layouts.csv", index=False)
    return table


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per method × split × fail_prob: success and steps / optimum (successful episodes), mean and std over
    seeds; each seed's values are means over its layouts' episodes; the exact optimum's success beside them."""
    t = table.assign(ratio=np.where(table["success"], table["steps"] / table["optimal_steps"], np.nan))
    per_seed = t.groupby(["method", "split", "fail_prob", "seed"], sort=False).agg(
        success=("success", "mean"), steps_ratio=("ratio", "mean"), optimal=("optimal_success", "mean")).reset_index()
    out = per_seed.groupby(["method", "split", "fail_prob"], sort=False).agg(
        success_mean=("success", "mean"), success_std=("success", "std"),
        steps_ratio_mean=("steps_ratio", "mean"), steps_ratio_std=("steps_ratio", "std"),
        optimal_success=("optimal", "mean"), seeds=("seed", "nunique")).reset_index()
    layouts = table.groupby("split")["layout"].nunique()
    out["layouts"] = out["split"].map(layouts)
    return out
