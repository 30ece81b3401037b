"""Evaluation: every method × env × fail_prob × seed, N episodes each, batched over environment copies.

One :class:`EvalTask` per method × env × seed (:func:`evaluate_run`, shared with the unseen-layout experiment)
runs its fail_probs' cells as batches and returns table rows, touching no file, so any executor
(:mod:`hnsdt.core.compute`) can run it; :func:`evaluate_all` loads the
checkpoints, runs the tasks and writes the tables and recordings.

Metrics follow the paper: success rate, mean steps of the successful episodes, mean reward (episode return);
each is computed per seed and then reported as mean ± std over seeds.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Collection

import numpy as np
import pandas as pd

from hnsdt.agents.executor import REPLAN_REASONS, ExecutorConfig
from hnsdt.agents.navigation import step_towards
from hnsdt.agents.rollout import Agent, Episode, rollout
from hnsdt.envs.keydoor import PICK
from hnsdt.envs.layout import Layout, equal_runs
from hnsdt.envs.vector import KeyDoorVectorEnv, Streams
from hnsdt.core.methods import ARMS, resolve
from hnsdt.core.methods import method as lookup_method


@dataclass
class Cell:
    method: str
    env: str
    fail_prob: float
    seed: int

    @property
    def key(self) -> str:
        return f"{self.method}/{self.env}/fp{self.fail_prob:g}/seed{self.seed}"

    def episode_id(self, i: int) -> str:
        return f"{self.key}/ep{i}"


def checkpoint_dir(models_root: str | Path, env: str, method: str, seed: int) -> Path:
    return Path(models_root) / env / method / f"seed{seed}"


def load_model(path: str | Path, method: str, device: str = "cpu", view: bool = False):
    """``(model, checkpoint meta)`` of a learned method's checkpoint folder ``path``; ``(None, {})`` for a method
    that does not learn. ``view``: the checkpoint must hold the method's view network (unseen layouts)."""
    entry = lookup_method(method)
    if entry.training == "none":
        return None, {}
    from hnsdt.models.checkpoint import load_checkpoint

    model, meta = load_checkpoint(path, device)
    if meta.get("method", method) != method:
        raise ValueError(f"{path} holds a {meta['method']} model")
    if view and meta.get("arch") != resolve(entry.view_network).arch:
        raise ValueError(f"{path} is not a view model (train it with `python pipeline/generalisation.py train "
                         f"--method {method}`)")
    return model, meta


def build_agent(method: str, layout: Layout, executor: ExecutorConfig, model=None, meta: dict | None = None,
                epsilon: float = 0.0, agent_seed: int = 0) -> Agent:
    """The batched agent of ``method`` around its trained ``model``. ``epsilon`` and ``agent_seed`` only
    matter to the online baselines (ε-greedy noise, sampled options)."""
    entry = lookup_method(method)
    return resolve(entry.agent)(model, meta or {}, layout, executor, epsilon, agent_seed)


def training_usage(models_root: str | Path, env: str, method: str, seed: int) -> dict:
    """What a learned model was trained on, from its checkpoint: env steps (online) or dataset frames."""
    import json

    meta = json.loads((checkpoint_dir(models_root, env, method, seed) / "config.json").read_text())
    usage = meta.get("usage", {})
    return {"method": method, "env": env, "seed": seed, "training": lookup_method(method).training,
            "env_steps": usage.get("env_steps"), "dataset_frames": usage.get("dataset_frames"),
            "epochs": usage.get("epochs"), "gradient_steps": usage.get("gradient_steps"),
            "epoch_kept": usage.get("best_epoch")}  # trained to a validation plateau: the epoch whose weights it kept


def cell_seed(cell: Cell, fail_index: int) -> int:
    """The environment seed of a cell: independent of the method, so methods face the same draws."""
    return int(np.random.SeedSequence([cell.seed, fail_index, 104729]).generate_state(1)[0])


def run_cell(cell: Cell, fail_index: int, layout: Layout, max_steps: int, episodes: int, agent) -> list[Episode]:
    env = KeyDoorVectorEnv(episodes, layout, cell.fail_prob, max_steps)
    return rollout(env, agent, seed=cell_seed(cell, fail_index))


def episode_rows(cell: Cell, episodes: list[Episode], layout: Layout, executor: ExecutorConfig) -> list[dict]:
    """One row per episode; plan-following methods also get their initial plan's length and cost and the
    cheapest plan's cost (inputs of the Theorem 1 check)."""
    from hnsdt.symbolic import SymbolicState, plan, plan_cost

    rows = []
    for i, ep in enumerate(episodes):
        row = {"method": cell.method, "env": cell.env, "fail_prob": cell.fail_prob, "seed": cell.seed,
               "episode": i, "episode_id": cell.episode_id(i), "success": bool(ep.success), "steps": ep.length,
               "reward": round(ep.ret, 6), "replans": ep.replans,
               **{f"replans_{reason}": ep.replan_counts.get(reason, 0) for reason in REPLAN_REASONS},
               "plan_length": np.nan, "plan_cost": np.nan, "optimal_plan_cost": np.nan}
        if ep.plan:
            s0 = SymbolicState.from_observation(layout, ep.states[0])
            row.update(plan_length=len(ep.plan),
                       plan_cost=plan_cost(plan(layout, s0, executor.plan_mode, executor.operators)),
                       optimal_plan_cost=plan_cost(plan(layout, s0, "cost")))
        rows.append(row)
    return rows


@lru_cache(maxsize=8)
def layout_navigator(layout: Layout):
    """The shortest-path tables of a layout (cached: a task runs its layouts one after another)."""
    from hnsdt.agents.navigation import Navigator

    return Navigator(layout)


_JUDGED_AS = {"Move": 1, "GoTo": 2}  # right_actions' kinds of operator; the others are judged as pick / open


def right_actions(episode: Episode, navigator) -> np.ndarray:
    """Per step of a plan-following episode: was its action one that achieves the operator being pursued
    fastest? A Move: the step onto its target cell; a GoTo: a move one closer along some shortest path; pick and
    open operators: pick/open. Steps with no operator are never right."""
    lay = navigator.layout
    T = episode.length
    right = np.zeros(T, dtype=bool)
    # per step: 0 no operator, 1 Move, 2 GoTo, 3 pick / open (a later segment's over an earlier one's); then
    # each kind's steps at once (the paper's Move operators make one segment per step)
    kind = np.zeros(T, dtype=np.int8)
    for seg in episode.segments:
        kind[seg.start:seg.end] = _JUDGED_AS.get(seg.operator.split("(")[0], 3)
    cells, actions, targets = episode.states[:T, :2], episode.actions[:T], episode.subgoal_targets[:T]
    move, go, other = kind == 1, kind == 2, kind == 3
    right[move] = step_towards(cells[move], targets[move]) == actions[move]
    if go.any():
        masks = episode.states[:T][go][:, lay.door_flags] @ (1 << np.arange(len(lay.doors)))
        idx = navigator.target_grid[targets[go, 0], targets[go, 1]]
        right[go] = navigator.on_shortest_path(idx, masks, cells[go], actions[go])
    right[other] = actions[other] == PICK
    return right


def segment_facts(episode: Episode, navigator, fail_prob: float) -> list[dict]:
    """One row per executed sub-goal segment of a plan-following episode, with the optimal expected steps to
    achieve its operator from the segment's first state: d / (1 − fail_prob) for a shortest path of d moves
    (d = 1 for a Move operator), 1 for pick/open; whether its first action was right (:func:`right_actions`), how
    many of its actions were, and how it ended (``outcome``: achieved, overran or broken — the replan's reason —,
    or ended with the episode). Both experiments add their own identity columns in front."""
    rows = []
    lay = navigator.layout
    right = right_actions(episode, navigator)
    for seg in episode.segments:
        end = seg.end if seg.end is not None else episode.length
        if end <= seg.start:
            continue
        state = episode.states[seg.start]
        target = tuple(int(v) for v in episode.subgoal_targets[seg.start])
        if seg.operator.startswith("Move"):
            optimal = 1 / (1 - fail_prob)
        elif seg.operator.startswith("GoTo"):
            mask = navigator.door_mask({d for d, f in zip(lay.doors, state[lay.door_flags]) if f})
            dist = navigator.distance[navigator.target_index[target], mask, state[0], state[1]]
            optimal = dist / (1 - fail_prob) if dist >= 0 else np.nan
        else:
            optimal = 1.0
        rows.append({"operator": seg.operator, "subgoal_id": seg.subgoal_id, "start": seg.start, "end": end,
                     "steps": end - seg.start, "optimal_steps": optimal, "achieved": bool(seg.achieved),
                     "outcome": seg.outcome, "first_action_right": bool(right[seg.start]),
                     "right_actions": int(right[seg.start:end].sum())})
    return rows


def segment_rows(cell: Cell, episodes: list[Episode], navigator) -> list[dict]:
    """The paper protocol's :func:`segment_facts` of a cell's episodes, after the cell's columns."""
    return [{"method": cell.method, "env": cell.env, "fail_prob": cell.fail_prob, "seed": cell.seed,
             "episode_id": cell.episode_id(i)} | row
            for i, ep in enumerate(episodes) for row in segment_facts(ep, navigator, cell.fail_prob)]


def training_segment_counts(dataset_root: str | Path, env: str, behaviours) -> list[dict]:
    """Sub-goal segments per operator in a dataset, over the episodes of ``behaviours`` (Theorem 2's m)."""
    from hnsdt.data.segmentation import segments_of
    from hnsdt.data.frames import load_frames
    from hnsdt.symbolic.subgoals import ID_TO_NAME

    frames = load_frames(dataset_root)
    counts: dict[str, int] = {}
    for start in np.unique(frames.episode_start):
        idx = np.flatnonzero(frames.episode_start == start)
        if len(behaviours) and frames.policy[idx[0]] not in behaviours:
            continue
        for sid, _, _ in segments_of(frames.subgoals[idx]):
            if sid:
                counts[ID_TO_NAME[sid]] = counts.get(ID_TO_NAME[sid], 0) + 1
    return [{"env": env, "operator": op, "segments": n} for op, n in sorted(counts.items())]


def per_seed_metrics(table: pd.DataFrame) -> pd.DataFrame:
    """success rate, mean steps on success (NaN when none succeeded), mean reward: one row per cell."""
    g = table.groupby(["method", "env", "fail_prob", "seed"])
    out = g.agg(success=("success", "mean"), reward=("reward", "mean"), episodes=("success", "size"))
    out["steps"] = table[table.success].groupby(["method", "env", "fail_prob", "seed"])["steps"].mean()
    return out.reset_index()


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Mean ± std over seeds of the per-seed metrics: one row per method × env × fail_prob."""
    per_seed = per_seed_metrics(table)
    g = per_seed.groupby(["method", "env", "fail_prob"])
    out = g.agg(success_mean=("success", "mean"), success_std=("success", "std"),
                steps_mean=("steps", "mean"), steps_std=("steps", "std"),
                reward_mean=("reward", "mean"), reward_std=("reward", "std"), seeds=("seed", "nunique"))
    return out.fillna({"success_std": 0.0, "steps_std": 0.0, "reward_std": 0.0}).reset_index()


def add_optimum(summ: pd.DataFrame, envs: dict) -> pd.DataFrame:
    """Attach the exact optimum of each env × fail_prob (value iteration, :mod:`hnsdt.envs.oracle`) and every
    method's ratios to it: success / optimal success, steps / optimal expected steps, and the regret
    V* − V^π in expected return."""
    from hnsdt.envs.oracle import optimum

    opt = {(e, f): optimum(envs[e].layout, f, envs[e].max_steps) for e, f in set(zip(summ.env, summ.fail_prob))}
    out = summ.copy()
    out["opt_success"] = [opt[(e, f)].success for e, f in zip(out.env, out.fail_prob)]
    out["opt_steps"] = [opt[(e, f)].steps for e, f in zip(out.env, out.fail_prob)]
    out["opt_reward"] = [opt[(e, f)].ret for e, f in zip(out.env, out.fail_prob)]
    out["success_ratio"] = out.success_mean / out.opt_success
    out["steps_ratio"] = out.steps_mean / out.opt_steps
    out["regret"] = out.opt_reward - out.reward_mean
    return out


def metrics_json(summ: pd.DataFrame) -> dict:
    """Nested {env: {method: {fail_prob: {metric: value}}}} for `dvc metrics show`."""
    out: dict = {}
    for row in summ.itertuples():
        cell = out.setdefault(row.env, {}).setdefault(row.method, {})
        cell[f"fail_{row.fail_prob:g}"] = {
            k: (None if pd.isna(getattr(row, k)) else round(float(getattr(row, k)), 4))
            for k in ("success_mean", "success_std", "steps_mean", "steps_std", "reward_mean", "reward_std",
                      "success_ratio", "steps_ratio", "regret") if k in summ
        }
    return out


@dataclass(frozen=True)
class Batch:
    """One rollout of a method: ``copies`` copies of one layout (or of several, one per equal run of copies), with
    one failure probability for all or one per copy, from one environment seed — or one per equal run of copies
    (a tuple: the paper protocol's cells or a split's maps, each drawing what it would alone,
    :class:`hnsdt.envs.vector.Streams`); the agent draws from each ``seed + 1``.
    ``key`` is what the experiment's rows need to know about the batch (the paper protocol: its cells, :class:`Cell`;
    unseen layouts: the sources of its maps and the episodes per fail_prob)."""

    layout: Layout | tuple[Layout, ...]  # one, or one per equal run of copies (unseen layouts: a split's maps)
    max_steps: int
    copies: int
    fail_prob: float | tuple[float, ...]
    seed: int | tuple[int, ...]
    key: Any


@dataclass(frozen=True)
class EvalTask:
    """One method and training seed of an evaluation: its trained model and every batch it runs. ``rows`` (a
    module-level function, so any executor can ship it) turns a batch's episodes into the experiment's rows:
    ``rows(task, batch, episodes)``. Both experiments run through :func:`evaluate_run`; they differ in the
    batches they plan and the rows they write."""

    method: str
    seed: int
    executor: ExecutorConfig  # its arm's planner
    model: Any  # None for the symbolic method
    meta: dict  # the checkpoint's facts
    epsilon: float  # online methods' exploration
    batches: tuple[Batch, ...]
    rows: Callable[..., Any]
    log_episodes: int = 0  # the paper protocol: the first this many episodes of each cell come back recorded
    provenance: dict | None = None  # ... with these facts in each recording (revision, params digest)


def run_batch(task: EvalTask, batch: Batch) -> list[Episode]:
    agent_seed = batch.seed + 1 if np.ndim(batch.seed) == 0 else Streams([s + 1 for s in batch.seed], batch.copies)
    agent = build_agent(task.method, batch.layout, task.executor, task.model, task.meta, task.epsilon, agent_seed)
    fail_prob = np.asarray(batch.fail_prob, dtype=np.float64) if isinstance(batch.fail_prob, tuple) else batch.fail_prob
    return rollout(KeyDoorVectorEnv(batch.copies, batch.layout, fail_prob, batch.max_steps), agent, seed=batch.seed)


def evaluate_run(task: EvalTask) -> list:
    """Every batch of the task, in order: ``task.rows`` of each."""
    return [task.rows(task, batch, run_batch(task, batch)) for batch in task.batches]


def cell_outputs(task: EvalTask, batch: Batch, episodes: list[Episode]) -> list[tuple]:
    """The paper protocol's rows of each cell of a batch: ``(episode rows, segment rows, recordings of its first
    log_episodes episodes)`` per cell, in the batch's order (:func:`cell_recordings`)."""
    navigator = layout_navigator(batch.layout)
    out = []
    for cell, rows in zip(batch.key, equal_runs(batch.copies, len(batch.key), "cells")):
        eps = episodes[rows]
        out.append((episode_rows(cell, eps, batch.layout, task.executor), segment_rows(cell, eps, navigator),
                    cell_recordings(cell, batch.layout, eps[:task.log_episodes], task.provenance)))
    return out


def recording_path(cell: Cell, episode: int) -> Path:
    """Where an episode's recordings lie in the recordings folder, without the suffix."""
    return Path(cell.method) / cell.env / f"fp{cell.fail_prob:g}" / f"seed{cell.seed}" / f"ep{episode}"


def cell_recordings(cell: Cell, layout: Layout, episodes: list[Episode], provenance: dict | None,
                    first: int = 0) -> list[dict]:
    """Each episode's ``.rrd`` and ``.mcap`` files as bytes (:func:`hnsdt.logs.recording_files`), made where the
    cell ran (the main process, rendering and writing them alone after the runs, had spent most of its 14.6 s there);
    ``episodes`` are the cell's from its episode ``first`` on."""
    if not episodes:
        return []
    from hnsdt.logs import record_from_episode, recording_files

    out = []
    for i, ep in enumerate(episodes, first):
        meta = {"method": cell.method, "env": cell.env, "fail_prob": cell.fail_prob, "seed": cell.seed, "episode": i}
        out.append(recording_files(record_from_episode(cell.episode_id(i), layout, ep, meta | (provenance or {})),
                                   episode_index=i))
    return out


def cell_batches(method: str, env: str, seed: int, fail_probs, layout: Layout, max_steps: int,
                 episodes: int) -> tuple[Batch, ...]:
    """The paper protocol's batch of one method × env × seed: a cell of ``episodes`` copies per fail_prob, each
    cell with its own env seed (:func:`cell_seed`), stepped together — the same episodes as a batch per cell,
    with one agent call per step for all (about 40 % less time for the transformers, measured)."""
    cells = tuple(Cell(method, env, fp, seed) for fp in fail_probs)
    per_copy = tuple(float(c.fail_prob) for c in cells for _ in range(episodes))
    seeds = tuple(cell_seed(cell, fi) for fi, cell in enumerate(cells))
    return (Batch(layout, max_steps, len(per_copy), per_copy, seeds, cells),)


def cell_task(settings, envs: dict, executors: dict[str, ExecutorConfig], models_root: str | Path, method: str,
              env: str, seed: int, rows: Callable[..., Any] = cell_outputs, log_episodes: int = 0,
              provenance: dict | None = None) -> EvalTask:
    """The paper protocol's task of one method × env × seed (:func:`evaluate_all`): its trained model and its one
    batch, every fail_prob's cell."""
    model, meta = load_model(checkpoint_dir(models_root, env, method, seed), method, settings.device)
    batches = cell_batches(method, env, seed, settings.fail_probs, envs[env].layout, envs[env].max_steps,
                           settings.episodes)
    return EvalTask(method, seed, executors[lookup_method(method).arm], model, meta,
                    settings.eval_epsilon.get(method, 0.0), batches, rows, log_episodes, provenance)


def evaluate_all(settings, envs: dict, executors: dict[str, ExecutorConfig], models_root: str | Path,
                 out_dir: str | Path, datasets: str | Path, progress: bool = True,
                 recordings_dir: str | Path | None = None,
                 compute=None, provenance: dict | None = None) -> pd.DataFrame:
    """Run every cell of ``settings`` (:class:`hnsdt.core.config.EvaluateSettings`) on ``envs`` (name ->
    :class:`hnsdt.core.config.EnvSpec`) and ``compute``'s executor, write ``episodes.csv``, ``summary.csv``,
    ``metrics.json`` under ``out_dir`` and the episode recordings (of the first seed) under ``recordings_dir``
    (default: ``recordings`` beside ``out_dir``), each built in a temporary folder and moved into place when
    complete. ``datasets``: the root of the collected datasets (Theorem 2's training segment counts).

    The recordings live apart from the tables because rerun stamps every row of an ``.rrd`` with a
    time-based id: the tables are the same bytes on every run, the ``.rrd`` files cannot be.

    ``executors`` holds the planner settings of each arm (``{"ours": ..., "paper": ...}``,
    :func:`hnsdt.core.config.executor_config`)."""
    import json

    from hnsdt.core.compute import Compute, run_tasks
    from hnsdt.core.fileio import atomic_dir
    from hnsdt.logs import LAYOUT_NAME, write_layout

    missing = set(ARMS) - set(executors)
    if missing:
        raise ValueError(f"evaluate_all: no planner settings for arm(s) {sorted(missing)}")
    out = Path(out_dir)
    rec_out = Path(recordings_dir) if recordings_dir is not None else out.parent / "recordings"
    groups = [(m, e, s) for m in settings.methods for e in settings.envs for s in settings.seeds]
    tasks, params_count, usage = [], {}, []
    for method, env, seed in groups:
        log = settings.log_episodes if seed == settings.seeds[0] else 0
        tasks.append(cell_task(settings, envs, executors, models_root, method, env, seed, cell_outputs, log,
                               provenance))
        if tasks[-1].model is not None:
            params_count[f"{env}/{method}"] = sum(p.numel() for p in tasks[-1].model.parameters())
            usage.append(training_usage(models_root, env, method, seed))
    results = run_tasks(evaluate_run, tasks, compute or Compute(), desc="evaluate", progress=progress)
    with atomic_dir(out) as tmp, atomic_dir(rec_out) as rec_tmp:
        tmp.mkdir()
        rec_tmp.mkdir()
        write_layout(rec_tmp / LAYOUT_NAME)  # Foxglove: Layouts -> Import, then open any .mcap below
        rows, seg_rows = [], []
        cells = dict(zip(groups, results))
        for method, env, fi, fail_prob, seed in [(m, e, fi, f, s) for m in settings.methods for e in settings.envs
                                                 for fi, f in enumerate(settings.fail_probs)
                                                 for s in settings.seeds]:
            (per_cell,) = cells[(method, env, seed)]  # its one batch
            cell_rows, cell_segs, recorded = per_cell[fi]
            for i, files in enumerate(recorded):
                rel = recording_path(Cell(method, env, fail_prob, seed), i)
                (rec_tmp / rel.parent).mkdir(parents=True, exist_ok=True)
                for suffix, data in files.items():  # (".rrd", ".mcap")
                    (rec_tmp / rel.with_suffix(suffix)).write_bytes(data)
                    cell_rows[i][suffix[1:]] = str(Path(rec_out.name) / rel.with_suffix(suffix))
            rows += cell_rows
            seg_rows += cell_segs
        table = pd.DataFrame(rows)
        for col in ("rrd", "mcap"):
            if col not in table:
                table[col] = ""
        table[["rrd", "mcap"]] = table[["rrd", "mcap"]].fillna("")
        table.to_csv(tmp / "episodes.csv", index=False)
        pd.DataFrame(seg_rows).to_csv(tmp / "segments.csv", index=False)
        counts = [r for e in settings.envs for r in training_segment_counts(
            Path(datasets) / e, e, settings.train_behaviours)]
        pd.DataFrame(counts, columns=["env", "operator", "segments"]).to_csv(tmp / "training_segments.csv",
                                                                           index=False)
        pd.DataFrame(usage, columns=["method", "env", "seed", "training", "env_steps", "dataset_frames", "epochs",
                                     "gradient_steps", "epoch_kept"]).astype(
            {"env_steps": "Int64", "dataset_frames": "Int64", "epochs": "float64", "gradient_steps": "Int64",
             "epoch_kept": "Int64"}).to_csv(
            tmp / "training_usage.csv", index=False)
        (tmp / "model_parameters.json").write_text(json.dumps(params_count, indent=2, sort_keys=True) + "\n")
        summ = add_optimum(summary(table), envs)
        summ.to_csv(tmp / "summary.csv", index=False, float_format="%.6g")
        (tmp / "metrics.json").write_text(json.dumps(metrics_json(summ), indent=2, sort_keys=True) + "\n")
    return table


def episode_recording(cell_index: int, episode: int, task: EvalTask, batch: Batch,
                      episodes: list[Episode]) -> tuple[dict, dict]:
    """The ``rows`` of a task re-run for one of its episodes (:func:`rerun_episode`): that episode's outcome, as
    ``episodes.csv`` has it, and its recordings."""
    cell = batch.key[cell_index]
    ep = episodes[equal_runs(batch.copies, len(batch.key), "cells")[cell_index]][episode]
    outcome = {"success": bool(ep.success), "steps": ep.length, "reward": round(ep.ret, 6), "replans": ep.replans}
    return outcome, cell_recordings(cell, batch.layout, [ep], task.provenance, first=episode)[0]


def rerun_episode(settings, envs: dict, executors: dict[str, ExecutorConfig], models_root: str | Path, cell: Cell,
                  episode: int, threads: int = 1, provenance: dict | None = None) -> tuple[dict, dict]:
    """An evaluated episode made again, for an episode that was not recorded: its method × env × seed run as
    :func:`evaluate_all` ran it (every fail_prob's episodes stepped together from the same seeds, ``threads`` torch
    threads), so that the episode is the evaluation's to the bit; ``(its outcome, its .rrd and .mcap bytes)``."""
    from functools import partial

    if cell.fail_prob not in settings.fail_probs or not 0 <= episode < settings.episodes:
        raise ValueError(f"{cell.episode_id(episode)}: not an episode of this evaluation (evaluate.fail_probs "
                         f"{list(settings.fail_probs)}, evaluate.episodes {settings.episodes})")
    rows = partial(episode_recording, settings.fail_probs.index(cell.fail_prob), episode)
    task = cell_task(settings, envs, executors, models_root, cell.method, cell.env, cell.seed, rows,
                     provenance=provenance)
    return _run_here(task, threads)


def _run_here(task: EvalTask, threads: int) -> tuple[dict, dict]:
    """A re-run's one task in this process, through the pickles and thread count a worker's runs have: the
    ``(outcome, files)`` its ``rows`` made of its one batch."""
    from hnsdt.core.compute import Compute, run_tasks

    ((outcome, files),), = run_tasks(evaluate_run, [task], Compute(workers=1, threads=threads), progress=False)
    return outcome, files


# -- many layouts (the unseen-layout experiment) ----------------------------------------------------------
# A source is a layout placed in a split with its step limit (:class:`hnsdt.generalisation.Source`: ``split``,
# ``layout``, ``max_steps``, ``name``); every method × seed runs on every source, one batch per layout.

@lru_cache(maxsize=None)
def _optimum(layout: Layout, fail_prob: float, max_steps: int) -> tuple[float, float]:
    from hnsdt.envs.oracle import optimum

    best = optimum(layout, fail_prob, max_steps)
    return float(best.steps), float(best.success)


def episode_seed(seed: int, layout_index: int) -> int:
    """The environment seed of a layout for one seed: the same for every method."""
    return int(np.random.SeedSequence([seed, layout_index, 7207]).generate_state(1)[0])


def layout_rows(task: EvalTask, batch: Batch, episodes: list[Episode]) -> tuple[list[dict], list[dict]]:
    """``(episode rows, sub-goal segment rows)`` of a batch of layouts (``batch.key``: the sources of its runs of
    copies and the episodes per fail_prob); only plan-following methods have segments (:func:`segment_facts`)."""
    sources, per_fail_prob = batch.key
    rows, segments = [], []
    for src, run in zip(sources, equal_runs(batch.copies, len(sources), "layouts")):
        eps = episodes[run]
        navigator = layout_navigator(src.layout) if any(ep.segments for ep in eps) else None
        for i, ep in enumerate(eps):
            ids = {"method": task.method, "seed": task.seed, "split": src.split, "layout": src.name,
                   "fail_prob": float(batch.fail_prob[run.start + i]), "episode": i % per_fail_prob}
            rows.append(ids | {"success": bool(ep.success), "steps": ep.length, "reward": round(ep.ret, 6)})
            if ep.segments:
                segments += [ids | row for row in segment_facts(ep, navigator, ids["fail_prob"])]
    return rows, segments


def layout_batches(seed: int, sources: tuple, fail_probs: tuple[float, ...], episodes: int,
                   splits: Collection[str] | None = None) -> tuple[Batch, ...]:
    """One batch per run of consecutive sources with the same split and step limit (a split's maps): each map's
    episodes at every failure probability (copies with their own fail_prob) from its own env seed, every map of
    the batch stepped together, one agent call per step for all (the same episodes as a batch per map).
    ``splits``: only these splits' maps, each with the episodes it has among all (its seed is its place)."""
    from itertools import groupby

    per_layout = tuple(float(p) for p in np.repeat(np.asarray(fail_probs, dtype=np.float64), episodes))
    kept = [(i, s) for i, s in enumerate(sources) if splits is None or s.split in splits]
    batches = []
    for _, run in groupby(kept, key=lambda item: (item[1].split, item[1].max_steps)):
        indices, srcs = zip(*run)
        batches.append(Batch(tuple(s.layout for s in srcs), srcs[0].max_steps, len(per_layout) * len(srcs),
                             per_layout * len(srcs), tuple(episode_seed(seed, li) for li in indices),
                             (srcs, episodes)))
    return tuple(batches)


def evaluate_layouts(seeds: dict[str, list[int]], sources: tuple, fail_probs: tuple[float, ...],
                     episodes: int, executors: dict[str, ExecutorConfig], epsilons: dict[str, float],
                     models_root: str | Path, out_dir: str | Path, compute=None, progress: bool = True,
                     splits: Collection[str] | None = None) -> pd.DataFrame:
    """Every method (the keys of ``seeds``, in order) × its seeds on every source, ``episodes`` per layout and
    fail_prob (a seed's episodes are drawn from the seed, whichever method runs them), the checkpoints of view models
    at ``models_root/<method>/seed<K>``; write ``episodes.csv``, ``summary.csv`` (:func:`layout_summary`),
    ``segments.csv`` and ``layouts.csv`` under ``out_dir``, with the exact optimum per layout and fail_prob.
    ``splits``: only these splits' sources, with the episodes they have in the whole evaluation."""
    from hnsdt.core.compute import Compute, run_tasks
    from hnsdt.core.fileio import atomic_dir

    tasks = [EvalTask(method, seed, executors[method], *load_model(Path(models_root) / method / f"seed{seed}", method,
                                                                   view=True),
                      epsilons.get(method, 0.0), layout_batches(seed, sources, fail_probs, episodes, splits),
                      layout_rows)
             for method, method_seeds in seeds.items() for seed in method_seeds]
    results = run_tasks(evaluate_run, tasks, compute or Compute(), desc="evaluate unseen layouts", progress=progress)
    sources = tuple(s for s in sources if splits is None or s.split in splits)
    table = pd.DataFrame([row for batches in results for rows, _ in batches for row in rows])
    segments = pd.DataFrame([row for batches in results for _, rows in batches for row in rows])
    optimal = {(s.name, fp): _optimum(s.layout, fp, s.max_steps) for s in sources for fp in fail_probs}
    table["optimal_steps"], table["optimal_success"] = zip(*(optimal[key]
                                                            for key in zip(table.layout, table.fail_prob)))
    with atomic_dir(Path(out_dir)) as tmp:
        tmp.mkdir()
        table.to_csv(tmp / "episodes.csv", index=False, float_format="%.6g")
        layout_summary(table).to_csv(tmp / "summary.csv", index=False, float_format="%.6g")
        segments.to_csv(tmp / "segments.csv", index=False, float_format="%.6g")
        layouts = pd.DataFrame([{"split": s.split, "layout": s.name, "rows": s.layout.shape[0],
                                 "cols": s.layout.shape[1], "max_steps": s.max_steps} for s in sources])
        layouts.to_csv(tmp / "layouts.csv", index=False)
    return table


def layout_episode_id(method: str, seed: int, layout: str, fail_prob: float, episode: int) -> str:
    """An unseen-layout episode's id: ``METHOD/seedK/LAYOUT/fpP/epI`` (the layout's name may hold slashes)."""
    return f"{method}/seed{seed}/{layout}/fp{fail_prob:g}/ep{episode}"


def layout_episode_recording(layout: str, fail_prob: float, episode: int, task: EvalTask, batch: Batch,
                             episodes: list[Episode]) -> tuple[dict, dict]:
    """The ``rows`` of an unseen-layout task re-run for one of its episodes (:func:`rerun_layout_episode`): that
    episode's outcome, as ``episodes.csv`` has it, and its recordings."""
    from hnsdt.logs import record_from_episode, recording_files

    sources = batch.key[0]
    k = [s.name for s in sources].index(layout)
    run = equal_runs(batch.copies, len(sources), "layouts")[k]
    first = next(i for i in range(run.start, run.stop) if batch.fail_prob[i] == fail_prob)
    ep = episodes[first + episode]
    meta = {"method": task.method, "seed": task.seed, "split": sources[k].split, "layout": layout,
            "fail_prob": fail_prob, "episode": episode}
    rec = record_from_episode(layout_episode_id(task.method, task.seed, layout, fail_prob, episode), sources[k].layout,
                              ep, meta | (task.provenance or {}))
    outcome = {"success": bool(ep.success), "steps": ep.length, "reward": round(ep.ret, 6)}
    return outcome, recording_files(rec, episode_index=episode)


def rerun_layout_episode(sources: tuple, fail_probs: tuple[float, ...], episodes: int, models_root: str | Path,
                         method: str, seed: int, executor: ExecutorConfig, epsilon: float, layout: str,
                         fail_prob: float, episode: int, threads: int = 1,
                         provenance: dict | None = None) -> tuple[dict, dict]:
    """An unseen-layout episode made again: its method and seed on the maps of its split, stepped together from
    the same seeds as :func:`evaluate_layouts` ran them (each map's seed is its place among ``sources``), so that
    the episode is the evaluation's to the bit; ``(its outcome, its .rrd and .mcap bytes)``."""
    from functools import partial

    src = next((s for s in sources if s.name == layout), None)
    episode_id = layout_episode_id(method, seed, layout, fail_prob, episode)
    if src is None:
        raise ValueError(f"{episode_id}: no layout {layout} among this evaluation's")
    if fail_prob not in fail_probs or not 0 <= episode < episodes:
        raise ValueError(f"{episode_id}: not an episode of this evaluation (evaluate.fail_probs {list(fail_probs)}, "
                         f"generalisation.episodes {episodes})")
    batch = next(b for b in layout_batches(seed, sources, fail_probs, episodes, {src.split})
                 if layout in [s.name for s in b.key[0]])
    model, meta = load_model(Path(models_root) / method / f"seed{seed}", method, view=True)
    task = EvalTask(method, seed, executor, model, meta, epsilon, (batch,),
                    partial(layout_episode_recording, layout, fail_prob, episode), 0, provenance)
    return _run_here(task, threads)


def layout_summary(table: pd.DataFrame) -> pd.DataFrame:
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
