"""Training runs of the learned methods, one task per env × method × seed (stages `train`, `train_offline`,
`train_online`, `train_generalisation`).

:func:`plan_runs` reads the params and the data once and returns one self-contained :class:`TrainTask` per
seed; :func:`train_run` is the task: it trains and returns the model and its facts, touching no file, so any
executor (:mod:`hnsdt.core.compute`) can run it; :func:`train_all` runs the tasks and writes the checkpoints and
curves.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from hnsdt.compose.config import (EnvSpec, Params, baseline_settings, env_spec, layout_executor, method_executor,
                                  model_config, train_settings, typed_config)
from hnsdt.envs.layout import Layout
from hnsdt.core.methods import METHODS
from hnsdt.implementations import code_of, network_for, resolve
from hnsdt.core.methods import method as lookup_method
from hnsdt.evaluation.validation import StepsToExit


@dataclass(frozen=True)
class TrainTask:
    """One seed of one method: everything its trainer needs, data included."""

    method: str
    seed: int
    model_cfg: Any  # the network's config
    train_cfg: Any  # the trainer's config
    data: Any  # offline: the dataset's frames, by reference (DatasetFrames) or as Frames; online: (layout or
    #            layouts, max_steps)
    facts: dict  # what goes into the checkpoint besides the configs
    progress: bool = False  # a progress bar (when it runs in the stage's process)
    split: bool = False  # hand back the state part-way (dataset learners sharing workers; :func:`pause_at`)
    state: Any = None  # where a split run continues from
    measure: Any = None  # the validation measure when not the held-out loss (:class:`StepsToExit`)

    def frames(self):
        """An offline task's frames (read from its dataset in this process when it carries them by reference)."""
        return self.data.load() if hasattr(self.data, "load") else self.data


def plan_runs(params: Params, env: str, method: str, seeds: list[int], dataset: Path) -> list[TrainTask]:
    """One task per seed, on ``envs.<env>`` and its dataset (offline methods) or environment (online ones)."""
    training = METHODS[method].training
    frames = source = None
    if training == "dataset":
        from hnsdt.data.frames import DatasetFrames

        # with the sub-goal labels of the method's operators; the tasks carry the reference, each worker reads it
        source = DatasetFrames.of(dataset, method_executor(params, method).operators)
        frames = source.load()
    runs = []
    if METHODS[method].stage == "train":  # a decision transformer: knobs under `train` and `models`
        ts = train_settings(params)
        if method not in ts.methods:
            raise ValueError(f"method {method!r} is not in train.methods {list(ts.methods)}")
        model_cfg = model_config(params, env, method)
        if model_cfg.condition == "subgoal":
            _check_operator_coverage(frames, params, env_spec(params, env), method, ts.behaviours[method])
        starts = np.unique(frames.episode_start)
        facts = {"dataset": str(dataset), "target_return": float(frames.returns_to_go[starts].max())}  # pure DT's
        measure = None
        kind, n_starts = ts.measure.get(method, ("loss", 0))
        if kind == "steps":
            from hnsdt.models.train import validation_episodes

            cfg = ts.method_config(method, seed=0)
            used = np.isin(frames.policy, list(cfg.behaviours)) if cfg.behaviours else np.ones(len(frames), bool)
            held_out = validation_episodes(frames, cfg.validation) & used
            measure = StepsToExit.from_held_out(frames, held_out, n_starts, method, env_spec(params, env),
                                                method_executor(params, method), facts)
        return [TrainTask(method, seed, model_cfg, ts.method_config(method, seed), source, facts, measure=measure)
                for seed in seeds]
    kind = "offline" if training == "dataset" else "online"  # a baseline: knobs under `baselines.<method>`
    listed = getattr(params.baselines, kind)
    if method not in listed:
        raise ValueError(f"method {method!r} is not in baselines.{kind} {list(listed)}")
    for seed in seeds:
        bs = baseline_settings(params, method, env, seed)
        if kind == "offline":
            data, facts = source, {"dataset": str(dataset)}
        else:
            data, facts = (bs.env.layout, bs.env.max_steps), {}
        measure = None
        if getattr(bs.train, "patience", 0) and not getattr(bs.train, "validation", 0):  # (validation: an offline
            # learner's held-out episodes' loss) greedy steps to the exit from the map's start (where the online
            # learners train from) and, with starts > 1, random states of it (as the offline datasets' random starts)
            measure = StepsToExit.on_layouts([bs.env.layout], bs.env.max_steps, bs.train.starts, method,
                                             method_executor(params, method), facts)
        runs.append(TrainTask(method, seed, bs.model, bs.train, data, facts, measure=measure))
    return runs


def _check_operator_coverage(frames, params: Params, env: EnvSpec, method: str, behaviours) -> None:
    """Every operator the method's planner can hand its DT must have at least one training segment (Theorem 2's
    m ≥ 1); a dataset too small for that is an error naming the missing operators, before any training."""
    from hnsdt.symbolic.subgoals import NAME_TO_ID

    layout = env.layout
    names = ([f"PickKey({k})" for k in layout.keys] + [f"OpenDoor({d})" for d in layout.doors]
             + [f"PickItem({i})" for i in layout.items])
    if method_executor(params, method).operators == "move":
        names.append("Move")
    else:
        names += ([f"GoTo(key {k})" for k in layout.keys] + [f"GoTo(door {d})" for d in layout.doors]
                  + [f"GoTo(item {i})" for i in layout.items] + ["GoTo(exit)"])
    used = np.isin(frames.policy, list(behaviours)) if len(behaviours) else np.ones(len(frames), bool)
    present = set(np.unique(frames.subgoals[used]).tolist())
    missing = [name for name in names if NAME_TO_ID[name] not in present]
    if missing:
        raise ValueError(f"{method} on {env.name}: the training episodes (behaviours {list(behaviours) or 'all'}) "
                         f"give no segment of {', '.join(missing)}; collect more episodes of those behaviours "
                         "(collect.behaviours in params.yaml)")


@dataclass(frozen=True)
class SeedStack:
    """An online learner's seeds as one task, trained in lockstep (:class:`~hnsdt.baselines.online.OnlineRun`):
    each seed gets the bytes it gets alone (tested), and torch's per-step cost — most of a small network's step —
    is paid once for all of them."""

    runs: tuple[TrainTask, ...]


def seed_stacks(runs: list[TrainTask], compute) -> list[SeedStack]:
    """One stack per local worker, seeds in order (5 seeds on 2 workers: 3 and 2); on Ray one per seed."""
    stacks = compute.local_workers(len(runs)) if compute.executor == "local" else len(runs)
    return [SeedStack(tuple(runs[i] for i in part)) for part in np.array_split(np.arange(len(runs)), stacks)]


def pause_at(task: TrainTask) -> int | None:
    """Where a seed that shares workers with other seeds hands back its state (``stop_after``), or None: it runs
    to its end. A fixed budget pauses once, half-way (half its epochs); a run that a validation plateau ends —
    after an epoch nobody knows beforehand, often before half its cap — pauses after every epoch, so the seeds
    take turns epoch by epoch and no core waits alone for the last seed's epochs. (Online learners' seeds share
    no worker: they train in stacks, :func:`seed_stacks`.)"""
    if not task.split:
        return None
    cfg = task.train_cfg
    if task.measure is not None or getattr(cfg, "validation", 0) > 0:  # stops at a plateau
        return (task.state.epoch if task.state is not None else 0) + 1
    return None if task.state is not None else (cfg.epochs // 2 or None)


def _trained(task: TrainTask, model, curve: list[dict], usage: dict):
    """A task's result: ``(model, checkpoint facts, curve)``."""
    model.cpu()
    return model, {"seed": task.seed, **task.facts, "train": asdict(task.train_cfg), "usage": usage,
                   "curve": curve}, curve


def train_run(task: TrainTask | SeedStack):
    """Train one seed: ``(model, checkpoint facts, curve)``; a :class:`SeedStack`, a list of them (an online
    learner's seed alone is a stack of one). With ``task.split``, a dataset learner stops part-way
    (:func:`pause_at`) and returns :class:`~hnsdt.core.compute.Continue` with its state (a
    :class:`~hnsdt.models.fit.FitState`): the executor queues the rest behind the other seeds' parts, so 5 seeds
    on 2 workers take about 2.5 seed-times, not 3, and the weights are the same bytes as in one go (tested)."""
    from hnsdt.core.compute import Continue

    runs = task.runs if isinstance(task, SeedStack) else (task,)
    first = runs[0]
    trainer, network = resolve(code_of(first.method).trainer), network_for(first.method, first.model_cfg)
    if METHODS[first.method].training == "online":  # on (layout(s), max_steps), every seed of the stack at once
        out = trainer(*first.data, first.model_cfg, [r.train_cfg for r in runs], progress=first.progress,
                      desc=f"{first.method} seed {', '.join(str(r.seed) for r in runs)}", network=network,
                      measure=first.measure)
        results = [_trained(run, *result) for run, result in zip(runs, out)]
        return results if isinstance(task, SeedStack) else results[0]
    extra = {"measure": task.measure} if task.measure is not None else {}  # (DTs; offline baselines with patience)
    out = trainer(task.frames(), task.model_cfg, task.train_cfg, progress=task.progress,
                  desc=f"{task.method} seed {task.seed}", network=network, state=task.state,
                  stop_after=pause_at(task), **extra)
    if not isinstance(out, tuple):  # paused part-way
        return Continue(replace(task, state=out))
    return _trained(task, *out)


def train_all(runs: list[TrainTask], env: str, out: Path, curves: Path, compute, progress: bool = True) -> None:
    """Run every seed's task on ``compute`` (an online learner's seeds in stacks, :func:`seed_stacks`) and write
    ``out/seedK/`` checkpoints and ``curves/seedK.csv``, each folder complete or absent; a seed finished by a
    run that was killed is taken from what it kept (:func:`hnsdt.core.fileio.finished_tasks`)."""
    import pandas as pd

    from hnsdt.core.compute import run_tasks
    from hnsdt.core.fileio import atomic_dir, finished_tasks
    from hnsdt.models.checkpoint import save_checkpoint

    inline = compute.executor == "local" and compute.local_workers(len(runs)) == 1
    method = runs[0].method
    online = METHODS[method].training == "online"
    tasks = [replace(r, progress=progress and inline) for r in runs]
    # seeds paused part-way where they share workers (in one process a pause would only cost a model rebuild)
    tasks = seed_stacks(tasks, compute) if online else [replace(t, split=not inline) for t in tasks]
    if compute.executor == "ray" and not online:  # the frames themselves, through Ray's object store: a cluster's
        tasks = [replace(t, data=t.frames()) for t in tasks]  # nodes need no copy of the dataset
    with finished_tasks(out) as keep:  # (a seed finished before a kill is not trained again)
        results = run_tasks(train_run, tasks, compute, desc=f"train {env} {method}",
                            progress=progress and not inline, keep=keep)
        if online:
            results = [result for stack in results for result in stack]
        with atomic_dir(out) as staging, atomic_dir(curves) as curve_staging:
            staging.mkdir()
            curve_staging.mkdir()
            for run, (model, facts, curve) in zip(runs, results):
                save_checkpoint(model, staging / f"seed{run.seed}", {"env": env, "method": method, **facts})
                pd.DataFrame(curve).to_csv(curve_staging / f"seed{run.seed}.csv", index=False)
                print(f"trained {method} on {env}, seed {run.seed}: {_usage_text(facts['usage'])}; "
                      f"final {_last_metric(curve)}", flush=True)


def _usage_text(usage: dict) -> str:
    """The training record in one short line: a validation history (a list per epoch or evaluation, in the
    checkpoint's ``config.json``) shows as its length and best value."""
    parts = []
    for key, value in usage.items():
        if isinstance(value, list) and value:
            best = min(value, key=lambda h: h["value"])
            unit, count = ("epoch", "epochs") if "epoch" in best else ("step", "evaluations")
            value = f"{len(value)} {count}, best {best['value']:.4g} at {unit} {best[unit]}"
        parts.append(f"{key} {value}")
    return ", ".join(parts)


def _last_metric(curve: list[dict]) -> str:
    last = curve[-1] if curve else {}
    return ", ".join(f"{k} {last[k]:.4f}" for k in ("loss", "success") if k in last and last[k] == last[k])


# -- the unseen-layout experiment: view networks over many layouts ---------------------------------------

def require_dt_size(params: Params) -> None:
    """One line when the unseen-layout experiment trains a decision transformer on a family without a size in
    ``models`` — checked before any work (an experiment's stage collects first)."""
    g = params.need("generalisation")
    if g.family not in params.models and any(lookup_method(m).stage == "train" for m in g.learned):
        raise params.error(f"missing key models.{g.family} (the decision transformers' size on the "
                           f"generalisation family {g.family})")


def layout_network_configs(params: Params, method: str, seed: int, layout: Layout):
    """``(view network config, training config)`` of one method and seed of the unseen-layout experiment
    (``generalisation`` in params.yaml), ``layout`` one of its training layouts (their flags). Nothing in them
    depends on the maps the method is evaluated on: targets are clamped at ``generalisation.max_offset``,
    timesteps at the training episodes' limit."""
    from hnsdt.models.view import view_config

    g = params.need("generalisation")
    entry = lookup_method(method)
    if not code_of(method).view_network:
        raise ValueError(f"generalisation: {method} has no network that reads views")
    env = EnvSpec(g.family, f"hnsdt/generated-{g.family}", layout, g.max_steps)
    view_cls = resolve(code_of(method).view_network).config_class
    if entry.stage == "train":  # a decision transformer: `train` and `models.<family>`
        ts, models = train_settings(params), params.models
        require_dt_size(params)
        try:
            cfg = view_config(entry.condition, layout.n_flags, g.view_radius, g.max_offset, g.conv_layers,
                              g.value_iterations, g.whole_map, max_timestep=g.max_steps, dropout=params.train.dropout,
                              formulation=ts.formulation[method],
                              **models[g.family].model_dump())
        except ValueError as e:
            raise params.error(f"models.{g.family}: {e}") from None
        train_cfg = replace(ts.method_config(method, seed), symmetries=g.symmetries)
        if g.validation_layouts and _stops_on_validation_layouts(params, method):  # the measure acts on the
            train_cfg = replace(train_cfg, validation=0.0)  # validation layouts: every training episode trains
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


def _stops_on_validation_layouts(params: Params, method: str, train_cfg=None) -> bool:
    """Does ``method`` stop at the plateau of its steps to the exit on the validation layouts
    (:class:`StepsToExit`), given some? A DT with a ``train.validation`` entry does, an offline baseline with
    ``patience`` (``train_cfg``, its training config) does, unless its own budget holds out episodes
    (:func:`_held_out_budget`)."""
    if lookup_method(method).stage == "train":
        return method in params.train.validation
    return getattr(train_cfg, "patience", 0) > 0 and not _held_out_budget(params, method)


def _held_out_budget(params: Params, method: str) -> bool:
    """Does ``generalisation.budgets.<method>`` itself set ``validation`` > 0 — an offline baseline that holds that
    share of its episodes out and stops at the plateau of their loss (the paper maps' rule), not of the validation
    layouts' steps? (A share it inherits from ``baselines.<method>`` does not count: the budget chooses.)"""
    return params.need("generalisation").budgets.get(method, {}).get("validation", 0) > 0


def _budget(params: Params, method: str, train_cfg):
    """``train_cfg`` with ``generalisation.budgets.<method>`` applied: each key a field of its training config,
    with the field's type."""
    key, budget = f"generalisation.budgets.{method}", params.need("generalisation").budgets.get(method, {})
    allowed = set(vars(train_cfg)) - {"seed", "device", "behaviours"}
    unknown = sorted(set(budget) - allowed)
    if unknown:
        raise params.error(f"{key}: unknown key {unknown[0]}; expected one of {sorted(allowed)}")
    fixed = {k: v for k, v in vars(train_cfg).items() if k not in budget}
    return typed_config(params, key, type(train_cfg), budget, **fixed)  # (checked as baselines.<method>)


def plan_layout_runs(params: Params, method: str, dataset: str | Path, layouts: list[Layout],
                     validation: Callable[[], list[Layout]]) -> list[TrainTask]:
    """One task per training seed of ``method`` (``generalisation.seeds_of``): its view network on the training
    ``layouts`` (online methods) or on their ``dataset`` (offline ones, by reference: :class:`DatasetFrames`);
    ``validation()`` gives the layouts a budget measured by acting stops on (:class:`StepsToExit`)."""
    from hnsdt.data.frames import DatasetFrames

    g = params.need("generalisation")
    if method not in g.learned:
        raise ValueError(f"method {method!r} is not in generalisation.methods {list(g.methods)} or "
                         f"generalisation.baselines {list(g.baselines)}")
    online = lookup_method(method).training == "online"
    if online:
        data = (list(layouts), g.max_steps)
        facts = {"family": g.family, "train_layouts": g.train_layouts}
    else:
        from hnsdt.data.format import check_dataset

        radius = check_dataset(dataset).get("view_radius", 0)
        if radius != g.view_radius:
            raise ValueError(f"dataset {dataset}: view radius {radius} (0 = no observation.view), but "
                             f"generalisation.view_radius is {g.view_radius}; collect it with "
                             "`python pipeline/generalisation.py collect`")
        source = DatasetFrames.of(dataset, layout_executor(params, method).operators,  # (Move: hindsight labels)
                                  whole_map=g.whole_map and lookup_method(method).stage == "train")
        frames = source.load()
        facts = {"dataset": str(dataset), "family": g.family,
                 "target_return": float(frames.returns_to_go[np.unique(frames.episode_start)].max())}
    seeds = g.seeds_of(method)
    net_cfg, train_cfg = layout_network_configs(params, method, seeds[0], layouts[0])
    wanted = list(getattr(train_cfg, "behaviours", ()))
    if not online and wanted and not np.isin(frames.policy, wanted).any():
        raise ValueError(f"{method} learns from {wanted} episodes and {dataset} holds none; set "
                         "generalisation.random_episodes_per_layout > 0 (random walks) and collect again")
    measure, stops = None, _stops_on_validation_layouts(params, method, train_cfg)
    if g.validation_layouts and stops:
        starts = g.validation_starts or (params.train.validation[method].starts if method in params.train.validation
                                         else train_cfg.starts)
        measure = StepsToExit.on_layouts(validation(), g.max_steps, starts, method, layout_executor(params, method),
                                         facts)
        if getattr(train_cfg, "validation", 0):  # (an offline baseline: every training episode trains)
            train_cfg = replace(train_cfg, validation=0.0)
    elif stops and lookup_method(method).stage != "train":  # (a DT falls back on its held-out episodes)
        raise params.error(f"generalisation.budgets.{method}.patience stops on the validation layouts: set "
                           "generalisation.validation_layouts > 0")
    return [TrainTask(method, seed, net_cfg, replace(train_cfg, seed=seed), data if online else source, facts,
                      measure=measure) for seed in seeds]
