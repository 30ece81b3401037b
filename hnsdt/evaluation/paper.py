"""The paper protocol's evaluation: every method × env × fail_prob × seed, N episodes each (a :class:`Cell`),
batched over environment copies, its tables and recordings; and any of its episodes made again."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from hnsdt.agents.executor import ExecutorConfig, REPLAN_REASONS
from hnsdt.agents.rollout import Episode, rollout
from hnsdt.core.methods import ARMS, method as lookup_method
from hnsdt.envs.layout import Layout, equal_runs
from hnsdt.envs.vector import KeyDoorVectorEnv
from hnsdt.evaluation.runs import (Batch, EvalTask, Evaluation, checkpoint_dir, episode_id, load_model, rerun,
                                   training_usage)
from hnsdt.evaluation.segments import layout_navigator, segment_facts, training_segment_counts
from hnsdt.evaluation.tables import add_optimum, metrics_json, summary


@dataclass
class Cell:
    method: str
    env: str
    fail_prob: float
    seed: int

    def episode_id(self, i: int) -> str:
        return episode_id(self.method, self.env, self.fail_prob, self.seed, i)


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


def segment_rows(cell: Cell, episodes: list[Episode], navigator) -> list[dict]:
    """The paper protocol's :func:`segment_facts` of a cell's episodes, after the cell's columns."""
    return [{"method": cell.method, "env": cell.env, "fail_prob": cell.fail_prob, "seed": cell.seed,
             "episode_id": cell.episode_id(i)} | row
            for i, ep in enumerate(episodes) for row in segment_facts(ep, navigator, cell.fail_prob)]


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
    with one agent call per step for all (less time for the transformers)."""
    cells = tuple(Cell(method, env, fp, seed) for fp in fail_probs)
    per_copy = tuple(float(c.fail_prob) for c in cells for _ in range(episodes))
    seeds = tuple(cell_seed(cell, fi) for fi, cell in enumerate(cells))
    return (Batch(layout, max_steps, len(per_copy), per_copy, seeds, cells),)


def cell_task(settings, envs: dict, executors: dict[str, ExecutorConfig], models_root: str | Path, method: str,
              env: str, seed: int, rows: Callable[..., Any] = cell_outputs, log_episodes: int = 0,
              provenance: dict | None = None) -> EvalTask:
    """The paper protocol's task of one method × env × seed (:func:`paper_evaluation`): its trained model and its one
    batch, every fail_prob's cell."""
    model, meta = load_model(checkpoint_dir(models_root, env, method, seed), method, settings.device)
    batches = cell_batches(method, env, seed, settings.fail_probs, envs[env].layout, envs[env].max_steps,
                           settings.episodes)
    return EvalTask(method, seed, executors[lookup_method(method).arm], model, meta,
                    settings.eval_epsilon.get(method, 0.0), batches, rows, log_episodes, provenance)


def paper_evaluation(settings, envs: dict, executors: dict[str, ExecutorConfig], models_root: str | Path,
                     datasets: str | Path, recordings_dir: str | Path,
                     provenance: dict | None = None) -> Evaluation:
    """The paper protocol's :class:`~hnsdt.evaluation.runs.Evaluation`: every cell of ``settings``
    (:class:`hnsdt.compose.config.EvaluateSettings`) on ``envs`` (name -> :class:`hnsdt.compose.config.EnvSpec`);
    it writes ``episodes.csv``, ``summary.csv``, ``metrics.json`` and the other tables, and the episode
    recordings (of the first seed) under ``recordings_dir``, built in a temporary folder and moved into place when
    complete. ``datasets``: the root of the collected datasets (Theorem 2's training segment counts).

    The recordings live apart from the tables because rerun stamps every row of an ``.rrd`` with a
    time-based id: the tables are the same bytes on every run, the ``.rrd`` files cannot be.

    ``executors`` holds the planner settings of each arm (``{"ours": ..., "paper": ...}``,
    :func:`hnsdt.compose.config.executor_config`)."""
    missing = set(ARMS) - set(executors)
    if missing:
        raise ValueError(f"paper_evaluation: no planner settings for arm(s) {sorted(missing)}")
    rec_out = Path(recordings_dir)
    groups = [(m, e, s) for m in settings.methods for e in settings.envs for s in settings.seeds]
    tasks, params_count, usage = [], {}, []
    for method, env, seed in groups:
        log = settings.log_episodes if seed == settings.seeds[0] else 0
        tasks.append(cell_task(settings, envs, executors, models_root, method, env, seed, cell_outputs, log,
                               provenance))
        if tasks[-1].model is not None:
            params_count[f"{env}/{method}"] = sum(p.numel() for p in tasks[-1].model.parameters())
            usage.append(training_usage(models_root, env, method, seed))
    return Evaluation(tasks, partial(_write_tables, settings=settings, envs=envs, groups=groups, rec_out=rec_out,
                                     datasets=Path(datasets), usage=usage, params_count=params_count))


def _write_tables(tmp: Path, results: list, settings, envs: dict, groups: list, rec_out: Path, datasets: Path,
                  usage: list, params_count: dict) -> pd.DataFrame:
    """The paper protocol's tables into ``tmp``, and its recordings into ``rec_out`` (whole or absent)."""
    import json

    from hnsdt.core.fileio import atomic_dir
    from hnsdt.logs import LAYOUT_NAME, write_layout

    with atomic_dir(rec_out) as rec_tmp:
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
                                     "gradient_steps", "epoch_kept", "env_steps_kept", "training_exits"]).astype(
            {"env_steps": "Int64", "dataset_frames": "Int64", "epochs": "float64", "gradient_steps": "Int64",
             "epoch_kept": "Int64", "env_steps_kept": "Int64", "training_exits": "Int64"}).to_csv(
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
    :func:`paper_evaluation` ran it (every fail_prob's episodes stepped together from the same seeds, ``threads`` torch
    threads), so that the episode is the evaluation's to the bit; ``(its outcome, its .rrd and .mcap bytes)``."""
    if cell.fail_prob not in settings.fail_probs or not 0 <= episode < settings.episodes:
        raise ValueError(f"{cell.episode_id(episode)}: not an episode of this evaluation (evaluate.fail_probs "
                         f"{list(settings.fail_probs)}, evaluate.episodes {settings.episodes})")
    rows = partial(episode_recording, settings.fail_probs.index(cell.fail_prob), episode)
    task = cell_task(settings, envs, executors, models_root, cell.method, cell.env, cell.seed, rows,
                     provenance=provenance)
    return rerun(task, threads)
