"""The paper's two theorems, evaluated on measured quantities.

Theorem 1 (hierarchical performance bound)::

    V* − V^hyb ≤ ε_sym/(1−γ) + ε_exec/(1−γ)² + ρB/(1−γ)²

in the theorem's own units: values are discounted returns with the theorem's γ, costs are in reward units
(a step costs |r_step| = 0.1). Estimated from evaluation episodes of a plan-following method, per env × fail_prob:

* measured side: V*_γ(s₀) − V^π_γ(s₀), with V*_γ the exact optimum (value iteration with discount γ,
  :mod:`hnsdt.envs.oracle`) and V^π_γ the mean discounted return of the episodes
  (Σ_{t<T} γ^t r_step + 1{success} γ^{T−1} r_goal);
* ε_sym: the executed initial plan's extra cost over the cheapest plan, |r_step| × (extra steps without
  failures) — undiscounted, so an upper bound on the discounted extra cost;
* ε_exec: the largest, over operators, of the mean discounted cost of achieving the operator minus its optimal
  expected discounted cost from the segment's start state: a segment of n steps costs
  |r_step|(1 − γⁿ)/(1 − γ); a shortest path of d moves that each fail with probability p costs
  |r_step|(1 − qᵈ)/(1 − γ) in expectation, q = γ(1 − p)/(1 − γp) (the moment generating function of a sum of
  d geometric trials); pick/open costs |r_step|;
* ρ: the largest per-operator failure rate (segments that ended without their effect);
* B: a bound on the extra cost of one failure, in reward units (param).

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

from hnsdt.envs.keydoor import GOAL_REWARD, STEP_REWARD
from hnsdt.core.methods import PROPOSED


def step_cost(steps, gamma: float) -> np.ndarray:
    """Discounted cost of ``steps`` consecutive steps, |r_step|(1 − γⁿ)/(1 − γ), in reward units."""
    return -STEP_REWARD * (1 - gamma ** np.asarray(steps, dtype=np.float64)) / (1 - gamma)


def discounted_returns(steps, success, gamma: float) -> np.ndarray:
    """Each episode's discounted return, from its length and outcome (the reward is −0.1 a step, +1 more on
    the step that succeeds)."""
    steps = np.asarray(steps, dtype=np.float64)
    return -step_cost(steps, gamma) + np.asarray(success, dtype=np.float64) * GOAL_REWARD * gamma ** (steps - 1)


def optimal_operator_cost(optimal_steps, fail_prob: float, gamma: float, is_move) -> np.ndarray:
    """Expected discounted cost of achieving an operator optimally: d moves (d = optimal_steps·(1 − p)) that
    each take a geometric number of tries, or one pick/open step."""
    d = np.asarray(optimal_steps, dtype=np.float64) * (1 - fail_prob)
    q = gamma * (1 - fail_prob) / (1 - gamma * fail_prob)
    moves = -STEP_REWARD * (1 - q**d) / (1 - gamma)
    return np.where(is_move, moves, -STEP_REWARD)


def theorem1(segments: pd.DataFrame, episodes: pd.DataFrame, v_star: dict, gamma: float, bound_b: float,
             method: str = PROPOSED) -> pd.DataFrame:
    """One row per env × fail_prob: ε_sym, ε_exec, ρ, the bound, and the measured regret V*_γ − V^π_γ.
    ``v_star[(env, fail_prob)]`` is the optimal discounted value of the start state."""
    rows = []
    seg = segments[segments.method == method]
    for (env, fail_prob), s in seg.groupby(["env", "fail_prob"]):
        ep = episodes[(episodes.method == method) & (episodes.env == env) & (episodes.fail_prob == fail_prob)]
        per_op = s.groupby("operator").agg(failure=("achieved", lambda a: 1.0 - a.mean()))
        done = s[s.achieved]
        cost = step_cost(done.steps, gamma)
        best = optimal_operator_cost(done.optimal_steps, fail_prob, gamma, done.operator.str.startswith("GoTo"))
        excess = pd.Series(cost - best, index=done.index).groupby(done.operator).mean()
        eps_exec = max(0.0, float(excess.max())) if len(excess) else float("nan")
        rho = float(per_op.failure.max())
        eps_sym = -STEP_REWARD * float((ep.plan_cost - ep.optimal_plan_cost).mean())
        bound = eps_sym / (1 - gamma) + eps_exec / (1 - gamma) ** 2 + rho * bound_b / (1 - gamma) ** 2
        value = float(discounted_returns(ep.steps, ep.success, gamma).mean())
        regret = v_star[(env, fail_prob)] - value
        rows.append({"env": env, "fail_prob": fail_prob, "eps_sym": eps_sym, "eps_exec": eps_exec, "rho": rho,
                     "B": bound_b, "gamma": gamma, "bound": bound, "v_star": v_star[(env, fail_prob)],
                     "v_method": value, "measured_regret": regret, "holds": bool(regret <= bound + 1e-9),
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
             delta: float, method: str = PROPOSED) -> pd.DataFrame:
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
