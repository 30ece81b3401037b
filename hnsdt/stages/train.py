"""Stages `train`, `train_offline`, `train_online`: one learned method on one paper map, every seed."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params, compute_settings


def train(params: Params, env: str, method: str, dataset: Path, out: Path, curves: Path,
          seeds: list[int] | None = None, compute=None, progress: bool = True) -> None:
    """Stages `train`, `train_offline`, `train_online`: one method on one env, every seed (``train.seeds``
    unless ``seeds``) a task on ``compute``'s executor. Same seed, same weights, whatever the executor and
    however many workers (tested)."""
    from hnsdt.compose.config import env_spec, train_settings
    from hnsdt.compose.training import plan_runs, train_all

    ts = train_settings(params)
    if env not in ts.envs:
        raise ValueError(f"env {env!r} is not in train.envs {list(ts.envs)}")
    env_spec(params, env)
    seeds = list(seeds) if seeds is not None else list(ts.seeds)
    runs = plan_runs(params, env, method, seeds, dataset)
    train_all(runs, env, out, curves, compute or compute_settings(params), progress=progress)
    print(f"wrote {', '.join(f'seed{s}' for s in seeds)} -> {out}/ (curves: {curves}/)")
