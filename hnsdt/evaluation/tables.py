"""The summary tables of an evaluation: per-seed metrics, their mean ± std over seeds, the exact optimum beside
them, and the nested metrics file."""

from __future__ import annotations

import numpy as np
import pandas as pd


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
