"""The paper's two theorems, evaluated on measured quantities.

Theorem 1 (hierarchical performance bound)::

    V* − V^hyb ≤ ε_sym/(1−γ) + ε_exec/(1−γ)² + ρB/(1−γ)²

estimated from evaluation episodes of a plan-following method, per env × fail_prob:

* ε_sym: cost of the executed initial plan minus the cheapest plan's cost (steps without failures);
* ε_exec: the largest, over operators, of (mean steps to achieve the operator − its optimal expected steps
  from the segment's start state; a shortest path of d moves takes d/(1−p) in expectation, pick/open 1);
* ρ: the largest per-operator failure rate (segments that ended without their effect);
* B: a bound on the extra cost of one failure (param), γ the discount (param).

The measured side is the undiscounted regret V* − V^π in expected return (from :mod:`hnsdt.oracle`).

Theorem 2 (PAC sub-goal completion)::

    Pr[all K sub-goals succeed] ≥ 1 − sqrt((2d·log(e·m/d) + 2·log(4K/δ)) / m)

with m the smallest number of training segments of any operator in the plan, K the plan length, d a stated
VC-dimension proxy and δ the confidence. The measured side is the fraction of episodes in which no sub-goal
segment failed.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd


def theorem1(segments: pd.DataFrame, episodes: pd.DataFrame, summ: pd.DataFrame, gamma: float, bound_b: float,
             method: str = "hnsdt") -> pd.DataFrame:
    """One row per env × fail_prob: the estimated ε_sym, ε_exec, ρ, the bound, the measured regret."""
    rows = []
    seg = segments[segments.method == method]
    for (env, fail_prob), s in seg.groupby(["env", "fail_prob"]):
        ep = episodes[(episodes.method == method) & (episodes.env == env) & (episodes.fail_prob == fail_prob)]
        per_op = s.groupby("operator").agg(failure=("achieved", lambda a: 1.0 - a.mean()))
        done = s[s.achieved]
        excess = (done.steps - done.optimal_steps).groupby(done.operator).mean()
        eps_exec = max(0.0, float(excess.max())) if len(excess) else float("nan")
        rho = float(per_op.failure.max())
        eps_sym = float((ep.plan_cost - ep.optimal_plan_cost).mean())
        bound = eps_sym / (1 - gamma) + eps_exec / (1 - gamma) ** 2 + rho * bound_b / (1 - gamma) ** 2
        cell = summ[(summ.method == method) & (summ.env == env) & (summ.fail_prob == fail_prob)]
        regret = float(cell.regret.iloc[0]) if len(cell) else float("nan")
        rows.append({"env": env, "fail_prob": fail_prob, "eps_sym": eps_sym, "eps_exec": eps_exec, "rho": rho,
                     "B": bound_b, "gamma": gamma, "bound": bound, "measured_regret": regret,
                     "holds": bool(regret <= bound + 1e-9),
                     "looseness": bound / regret if regret > 1e-9 else float("inf")})
    return pd.DataFrame(rows)


def pac_bound(m: int, K: int, d: float, delta: float) -> float:
    """Theorem 2's lower bound on Pr[all K sub-goals succeed]. The VC argument needs m ≥ d; with fewer
    segments than the VC dimension it says nothing, which we return as −inf (vacuous)."""
    if m <= 0 or d <= 0 or m < d:
        return float("-inf")
    radicand = (2 * d * math.log(math.e * m / d) + 2 * math.log(4 * K / delta)) / m
    return 1.0 - math.sqrt(radicand)


def theorem2(segments: pd.DataFrame, episodes: pd.DataFrame, train_counts: pd.DataFrame, vc_dimension: float,
             delta: float, method: str = "hnsdt") -> pd.DataFrame:
    """One row per env × fail_prob: m, K, the PAC lower bound and the measured all-sub-goals success rate."""
    rows = []
    seg = segments[segments.method == method]
    for (env, fail_prob), s in seg.groupby(["env", "fail_prob"]):
        ep = episodes[(episodes.method == method) & (episodes.env == env) & (episodes.fail_prob == fail_prob)]
        failed = s[~s.achieved].groupby("episode_id").size()
        all_ok = ep.success & ~ep.episode_id.isin(failed.index)
        ops = s.operator.unique()
        counts = train_counts[(train_counts.env == env) & train_counts.operator.isin(ops)]
        m = int(counts.segments.min()) if len(counts) == len(ops) else 0  # an unseen operator: m = 0
        K = int(np.ceil(ep.plan_length.mean()))
        rows.append({"env": env, "fail_prob": fail_prob, "m": m, "K": K, "d": vc_dimension, "delta": delta,
                     "bound": pac_bound(m, K, vc_dimension, delta), "measured": float(all_ok.mean()),
                     "holds": bool(all_ok.mean() >= pac_bound(m, K, vc_dimension, delta))})
    return pd.DataFrame(rows)
