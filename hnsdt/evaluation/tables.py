"""The summary tables of an evaluation: per-seed metrics, their mean ± std over seeds, the exact optimum beside
them, and the nested metrics file."""

from __future__ import annotations

import numpy as np
import pandas as pd


PAPER_CELL = ("method", "env", "fail_prob")  # a cell of the paper protocol: one map
LAYOUT_CELL = ("method", "split", "fail_prob")  # a cell of the unseen-layout experiment: a split of several maps


def per_seed_metrics(table: pd.DataFrame, cell: tuple[str, ...] = PAPER_CELL) -> pd.DataFrame:
    """One row per cell × seed: success rate, mean reward, mean steps on success (NaN when none succeeded) and,
    where the episodes carry their exact optimum (``optimal_steps``, ``optimal_success``: the unseen layouts'),
    steps / optimal steps on success and the optimum's success rate."""
    keys = [*cell, "seed"]
    g = table.groupby(keys, sort=False)  # (seeds in the order evaluated: the mean over them rounds as it always has)
    out = g.agg(success=("success", "mean"), reward=("reward", "mean"), episodes=("success", "size"))
    won = table[table.success]
    out["steps"] = won.groupby(keys, sort=False)["steps"].mean()
    if "optimal_steps" in table:
        ratio = table.assign(ratio=np.where(table.success, table.steps / table.optimal_steps, np.nan))
        out["steps_ratio"] = ratio.groupby(keys, sort=False)["ratio"].mean()
        out["optimal_success"] = g["optimal_success"].mean()
    return out.reset_index()


def summary(table: pd.DataFrame, cell: tuple[str, ...] = PAPER_CELL, sort: bool = True) -> pd.DataFrame:
    """The summary of either experiment's episodes: per cell (:data:`PAPER_CELL`, :data:`LAYOUT_CELL`), the mean ±
    std over seeds of :func:`per_seed_metrics` (a std is 0 where fewer than two seeds have the metric) and the
    number of seeds; with the episodes' optimum, the optimum's success beside them; over a split of several
    maps, how many. ``sort``: cells sorted (the paper protocol's tables), or in the order evaluated (the unseen
    layouts', whose report sections follow it)."""
    per_seed = per_seed_metrics(table, cell)
    metrics = ["success", "steps", "reward"] + (["steps_ratio"] if "steps_ratio" in per_seed else [])
    stats = {f"{m}_{stat}": (m, stat) for m in metrics for stat in ("mean", "std")} | {"seeds": ("seed", "nunique")}
    if "optimal_success" in per_seed:
        stats["optimal_success"] = ("optimal_success", "mean")
    out = per_seed.groupby(list(cell), sort=sort).agg(**stats)
    out = out.fillna({f"{m}_std": 0.0 for m in metrics}).reset_index()
    if "split" in cell:
        out["layouts"] = out["split"].map(table.groupby("split")["layout"].nunique())
    return out


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
