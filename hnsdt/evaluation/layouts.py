"""The unseen-layout experiment's evaluation: every method × seed on every layout of its splits (a source:
:class:`hnsdt.compose.generalisation.Source`), one batch per split's maps, beside the exact optimum; and any of
its episodes made again."""

from __future__ import annotations

from functools import lru_cache, partial
from pathlib import Path
from typing import Collection

import numpy as np
import pandas as pd

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.rollout import Episode
from hnsdt.envs.layout import Layout, equal_runs
from hnsdt.evaluation.runs import Batch, EvalTask, Evaluation, episode_id, load_model, rerun
from hnsdt.evaluation.segments import executed_segments, layout_navigator, segment_facts
from hnsdt.evaluation.tables import LAYOUT_CELL, summary


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
            name = episode_id(task.method, src.name, ids["fail_prob"], task.seed, ids["episode"])
            rows.append(ids | {"episode_id": name, "success": bool(ep.success), "steps": ep.length,
                               "reward": round(ep.ret, 6), "subgoals": executed_segments(ep), "plans": ep.plans})
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


def layout_evaluation(seeds: dict[str, list[int]], sources: tuple, fail_probs: tuple[float, ...],
                      episodes: int, executors: dict[str, ExecutorConfig], epsilons: dict[str, float],
                      models_root: str | Path, splits: Collection[str] | None = None) -> Evaluation:
    """The unseen layouts' :class:`~hnsdt.evaluation.runs.Evaluation`: every method (the keys of ``seeds``, in
    order) × its seeds on every source, ``episodes`` per layout and fail_prob (a seed's episodes are drawn from the
    seed, whichever method runs them), the checkpoints of view models at ``models_root/<method>/seed<K>``; it
    writes ``episodes.csv``, ``summary.csv`` (:func:`hnsdt.evaluation.tables.summary`), ``segments.csv``
    and ``layouts.csv``, with the exact optimum per layout and fail_prob. ``splits``: only these splits' sources,
    with the episodes they have in the whole evaluation."""
    tasks = [EvalTask(method, seed, executors[method], *load_model(Path(models_root) / method / f"seed{seed}", method,
                                                                   view=True),
                      epsilons.get(method, 0.0), layout_batches(seed, sources, fail_probs, episodes, splits),
                      layout_rows)
             for method, method_seeds in seeds.items() for seed in method_seeds]
    kept = tuple(s for s in sources if splits is None or s.split in splits)
    return Evaluation(tasks, partial(_write_tables, sources=kept, fail_probs=fail_probs),
                      desc="evaluate unseen layouts")


def _write_tables(tmp: Path, results: list, sources: tuple, fail_probs: tuple[float, ...]) -> pd.DataFrame:
    """The unseen layouts' tables into ``tmp``, the exact optimum beside every episode."""
    table = pd.DataFrame([row for batches in results for rows, _ in batches for row in rows])
    segments = pd.DataFrame([row for batches in results for _, rows in batches for row in rows])
    optimal = {(s.split, s.name, fp): _optimum(s.layout, fp, s.max_steps) for s in sources for fp in fail_probs}
    table["optimal_steps"], table["optimal_success"] = zip(*(optimal[key] for key in zip(
        table.split, table.layout, table.fail_prob)))
    table.to_csv(tmp / "episodes.csv", index=False, float_format="%.6g")
    summary(table, LAYOUT_CELL, sort=False).to_csv(tmp / "summary.csv", index=False, float_format="%.6g")
    segments.to_csv(tmp / "segments.csv", index=False, float_format="%.6g")
    layouts = pd.DataFrame([{"split": s.split, "layout": s.name, "rows": s.layout.shape[0],
                             "cols": s.layout.shape[1], "max_steps": s.max_steps} for s in sources])
    layouts.to_csv(tmp / "layouts.csv", index=False)
    return table


def layout_episode_recording(split: str, layout: str, fail_prob: float, episode: int, task: EvalTask, batch: Batch,
                             episodes: list[Episode]) -> tuple[dict, dict]:
    """The ``rows`` of an unseen-layout task re-run for one of its episodes (:func:`rerun_layout_episode`): that
    episode's outcome, as ``episodes.csv`` has it, and its recordings."""
    from hnsdt.logs import record_from_episode, recording_files

    sources = batch.key[0]
    k = [(s.split, s.name) for s in sources].index((split, layout))
    run = equal_runs(batch.copies, len(sources), "layouts")[k]
    first = next(i for i in range(run.start, run.stop) if batch.fail_prob[i] == fail_prob)
    ep = episodes[first + episode]
    meta = {"method": task.method, "seed": task.seed, "split": sources[k].split, "layout": layout,
            "fail_prob": fail_prob, "episode": episode}
    rec = record_from_episode(episode_id(task.method, layout, fail_prob, task.seed, episode), sources[k].layout,
                              ep, meta | (task.provenance or {}))
    outcome = {"success": bool(ep.success), "steps": ep.length, "reward": round(ep.ret, 6)}
    return outcome, recording_files(rec, episode_index=episode)


def rerun_layout_episode(sources: tuple, fail_probs: tuple[float, ...], episodes: int, models_root: str | Path,
                         method: str, seed: int, executor: ExecutorConfig, epsilon: float, split: str, layout: str,
                         fail_prob: float, episode: int, threads: int = 1,
                         provenance: dict | None = None) -> tuple[dict, dict]:
    """An unseen-layout episode made again: its method and seed on the maps of its split, stepped together from
    the same seeds as :func:`layout_evaluation` ran them (each map's seed is its place among ``sources``), so that
    the episode is the evaluation's to the bit; ``(its outcome, its .rrd and .mcap bytes)``."""
    src = next((s for s in sources if (s.split, s.name) == (split, layout)), None)
    name = episode_id(method, layout, fail_prob, seed, episode)
    if src is None:
        raise ValueError(f"{name}: no layout {layout} in split {split} among this evaluation's")
    if fail_prob not in fail_probs or not 0 <= episode < episodes:
        raise ValueError(f"{name}: not an episode of this evaluation (evaluate.fail_probs {list(fail_probs)}, "
                         f"generalisation.episodes {episodes})")
    batch = next(b for b in layout_batches(seed, sources, fail_probs, episodes, {src.split})
                 if src in b.key[0])
    model, meta = load_model(Path(models_root) / method / f"seed{seed}", method, view=True)
    task = EvalTask(method, seed, executor, model, meta, epsilon, (batch,),
                    partial(layout_episode_recording, split, layout, fail_prob, episode), 0, provenance)
    return rerun(task, threads)
