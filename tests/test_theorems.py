import math

import numpy as np
import pandas as pd
import pytest

from hnsdt.evaluation.theorems import discounted_returns, optimal_operator_cost, pac_bound, theorem1, theorem2


def _segments():
    rows = [  # operator GoTo(A): achieved in 5 and 7 steps, optimum 5 -> excess 1; B: one success, one failure
        ("ep0", "GoTo(A)", 5, 5.0, True), ("ep0", "B", 1, 1.0, True),
        ("ep1", "GoTo(A)", 7, 5.0, True), ("ep1", "B", 3, 1.0, False),
    ]
    return pd.DataFrame([{"method": "hnsdt", "env": "e", "fail_prob": 0.1, "episode_id": ep, "operator": op,
                          "steps": st, "optimal_steps": opt, "achieved": ok} for ep, op, st, opt, ok in rows])


def _episodes(steps=(10, 12)):
    return pd.DataFrame([{"method": "hnsdt", "env": "e", "fail_prob": 0.1, "episode_id": f"ep{i}", "success": True,
                          "steps": n, "plan_cost": 14, "optimal_plan_cost": 14, "plan_length": 2}
                         for i, n in enumerate(steps)])


def _series_cost(n, gamma):
    return sum(0.1 * gamma**t for t in range(n))


def test_theorem1_in_discounted_reward_units():
    gamma, p = 0.5, 0.1
    row = theorem1(_segments(), _episodes(), {("e", p): 0.2}, gamma=gamma, bound_b=1.1).iloc[0]
    # operator GoTo(A): d = 5 * (1 - p) = 4.5 moves; its segments cost the discounted sum of their 5 and 7 steps
    best_a = optimal_operator_cost([5.0], p, gamma, [True])[0]
    excess_a = (_series_cost(5, gamma) + _series_cost(7, gamma)) / 2 - best_a
    excess_b = _series_cost(1, gamma) - 0.1  # pick/open: one step, optimal
    assert row.eps_sym == 0 and row.eps_exec == pytest.approx(max(excess_a, excess_b))
    assert row.rho == pytest.approx(0.5)
    assert row.bound == pytest.approx(row.eps_exec / 0.25 + 0.5 * 1.1 / 0.25)
    value = np.mean([-_series_cost(n, gamma) + gamma ** (n - 1) for n in (10, 12)])
    assert row.v_method == pytest.approx(value) and row.measured_regret == pytest.approx(0.2 - value)
    assert row.holds


def test_theorem1_can_be_violated():
    assert not theorem1(_segments(), _episodes(), {("e", 0.1): 50.0}, gamma=0.5, bound_b=1.1).iloc[0].holds


@pytest.mark.parametrize("d, p, gamma", [(1, 0.3, 0.9), (4, 0.2, 0.8), (3, 0.0, 0.9)])
def test_optimal_operator_cost_is_the_expected_discounted_cost_of_geometric_moves(d, p, gamma):
    """d moves, each repeated until it works (probability 1 - p): simulate the discounted step cost."""
    rng = np.random.default_rng(0)
    n = rng.geometric(1 - p, size=(200_000, d)).sum(axis=1)  # steps to finish
    simulated = (0.1 * (1 - gamma**n) / (1 - gamma)).mean()
    exact = optimal_operator_cost([d / (1 - p)], p, gamma, [True])[0]
    assert exact == pytest.approx(simulated, rel=2e-3)


def test_discounted_returns_match_the_reward_stream():
    gamma = 0.9
    rewards = [-0.1] * 6
    rewards[-1] += 1.0  # success on the sixth step
    assert discounted_returns([6], [True], gamma)[0] == pytest.approx(sum(r * gamma**t for t, r in enumerate(rewards)))
    assert discounted_returns([4], [False], gamma)[0] == pytest.approx(sum(-0.1 * gamma**t for t in range(4)))


def test_pac_bound_formula_and_monotonicity():
    m, K, d, delta = 1000, 5, 10, 0.05
    expected = 1 - math.sqrt((2 * d * math.log(math.e * m / d) + 2 * math.log(4 * K / delta)) / m)
    assert pac_bound(m, K, d, delta) == pytest.approx(expected)
    assert pac_bound(10 * m, K, d, delta) > pac_bound(m, K, d, delta)
    assert pac_bound(0, K, d, delta) == float("-inf")
    assert pac_bound(100, K, 600_000, delta) == float("-inf")  # fewer segments than the VC dimension: vacuous
    assert pac_bound(141, 5, 5, 0.05) < 1.0


def test_theorem2_measures_episodes_with_no_failed_segment():
    counts = pd.DataFrame([{"env": "e", "operator": "GoTo(A)", "segments": 400}, {"env": "e", "operator": "B", "segments": 90}])
    row = theorem2(_segments(), _episodes(), counts, vc_dimension=2, delta=0.05).iloc[0]
    assert row.m == 90 and row.K == 2
    assert row.measured == pytest.approx(0.5)  # ep1 had a failed B segment
    assert row.bound == pytest.approx(pac_bound(90, 2, 2, 0.05))
