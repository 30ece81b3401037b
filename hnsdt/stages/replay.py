"""Evaluated episodes made again and recorded (``hnsdt replay``): not a DVC stage."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params
from hnsdt.stages.common import provenance


def replay_unseen(params: Params, models: Path, results: Path, episode_id: str, threads: int = 1) -> tuple[dict, dict]:
    """An evaluated unseen-layout episode (``METHOD/seedK/LAYOUT/fpP/epI``, a row of ``results``/episodes.csv) made
    again and recorded (:func:`hnsdt.evaluation.layouts.rerun_layout_episode`), checked against its row;
    ``(its row, its .rrd and .mcap bytes)``."""
    import pandas as pd

    from hnsdt.compose import generalisation as gen
    from hnsdt.compose.config import eval_epsilon, layout_executor
    from hnsdt.evaluation.layouts import layout_episode_id, rerun_layout_episode

    table_path = Path(results) / "episodes.csv"
    if not table_path.is_file():
        raise FileNotFoundError(f"{table_path}: no unseen-layout results (run `dvc repro evaluate_generalisation`, "
                                "or `hnsdt generalisation evaluate --out` and point --results there)")
    table = pd.read_csv(table_path)
    ids = [layout_episode_id(*key) for key in zip(table.method, table.seed, table.layout, table.fail_prob,
                                                  table.episode)]
    if episode_id not in ids:
        raise ValueError(f"no episode {episode_id!r} in {table_path} (ids are METHOD/seedK/LAYOUT/fpP/epI of its "
                         f"columns, e.g. {ids[0]!r})")
    row = table.iloc[ids.index(episode_id)]
    fps = tuple(float(f) for f in params.need("evaluate").fail_probs)
    sources = tuple(gen.layout_splits(params, evaluated_only=True))
    outcome, files = rerun_layout_episode(sources, fps, params.need("generalisation").episodes, models,
                                          row["method"], int(row["seed"]), layout_executor(params, row["method"]),
                                          eval_epsilon(params, row["method"]), row["layout"],
                                          float(row["fail_prob"]), int(row["episode"]), threads,
                                          provenance(params))
    outcome["reward"] = float(f"{outcome['reward']:.6g}")  # (as episodes.csv writes it)
    _check_outcome(episode_id, outcome, row, table_path)
    return row, files


def replay_evaluated(params: Params, models: Path, row, table_path: Path, threads: int = 1) -> dict:
    """An evaluated episode of the paper protocol (``row`` of ``table_path``, its episodes.csv) made again
    (:func:`hnsdt.evaluation.paper.rerun_episode`), checked against its row; its .rrd and .mcap bytes."""
    from hnsdt.compose.config import env_spec, evaluate_settings, executor_config
    from hnsdt.core.methods import ARMS
    from hnsdt.evaluation.paper import Cell, rerun_episode

    settings = evaluate_settings(params)
    if row["env"] not in settings.envs:
        raise ValueError(f"{row['episode_id']}: env {row['env']} is not in train.envs of the params")
    outcome, files = rerun_episode(settings, {e: env_spec(params, e) for e in settings.envs},
                                   {arm: executor_config(params, arm) for arm in ARMS}, models,
                                   Cell(row["method"], row["env"], float(row["fail_prob"]), int(row["seed"])),
                                   int(row["episode"]), threads, provenance(params))
    _check_outcome(row["episode_id"], outcome, row, table_path)
    return files


def _check_outcome(episode_id: str, outcome: dict, row, table_path: Path) -> None:
    """An episode made again must end as its row of the evaluation says."""
    listed = {key: type(value)(row[key]) for key, value in outcome.items()}
    if outcome != listed:
        raise ValueError(f"{episode_id} ran again to {outcome}, not to {listed} as in {table_path}: the models, "
                         "params, maps or code changed since that evaluation (`dvc status` says which, for the "
                         "pipeline's own)")
