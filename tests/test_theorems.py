import math

import pandas as pd
import pytest

from hnsdt.evaluation.theorems import pac_bound, theorem1, theorem2


def _segments():
    rows = [  # operator A: achieved in 5 and 7 steps, optimum 5 -> excess 1; B: one success, one failure
        ("ep0", "A", 5, 5.0, True), ("ep0", "B", 1, 1.0, True),
        ("ep1", "A", 7, 5.0, True), ("ep1", "B", 3, 1.0, False),
    ]
    return pd.DataFrame([{"method": "hnsdt", "env": "e", "fail_prob": 0.1, "episode_id": ep, "operator": op,
                          "steps": st, "optimal_steps": opt, "achieved": ok} for ep, op, st, opt, ok in rows])


def _episodes():
    return pd.DataFrame([{"method": "hnsdt", "env": "e", "fail_prob": 0.1, "episode_id": ep, "success": ok,
                          "plan_cost": 14, "optimal_plan_cost": 14, "plan_length": 2}
                         for ep, ok in (("ep0", True), ("ep1", True))])


def test_theorem1_estimates_and_bound():
    summ = pd.DataFrame([{"method": "hnsdt", "env": "e", "fail_prob": 0.1, "regret": 0.3}])
    row = theorem1(_segments(), _episodes(), summ, gamma=0.5, bound_b=1.1).iloc[0]
    assert row.eps_sym == 0 and row.eps_exec == pytest.approx(1.0) and row.rho == pytest.approx(0.5)
    assert row.bound == pytest.approx(0 / 0.5 + 1.0 / 0.25 + 0.5 * 1.1 / 0.25)
    assert row.holds and row.looseness == pytest.approx(row.bound / 0.3)


def test_theorem1_can_be_violated():
    summ = pd.DataFrame([{"method": "hnsdt", "env": "e", "fail_prob": 0.1, "regret": 50.0}])
    assert not theorem1(_segments(), _episodes(), summ, gamma=0.5, bound_b=1.1).iloc[0].holds


def test_pac_bound_formula_and_monotonicity():
    m, K, d, delta = 1000, 5, 10, 0.05
    expected = 1 - math.sqrt((2 * d * math.log(math.e * m / d) + 2 * math.log(4 * K / delta)) / m)
    assert pac_bound(m, K, d, delta) == pytest.approx(expected)
    assert pac_bound(10 * m, K, d, delta) > pac_bound(m, K, d, delta)
    assert pac_bound(0, K, d, delta) == float("-inf")
    assert pac_bound(100, K, 600_000, delta) == float("-inf")  # fewer segments than the VC dimension: vacuous
    assert pac_bound(141, 5, 5, 0.05) < 1.0


def test_theorem2_measures_episodes_with_no_failed_segment():
    counts = pd.DataFrame([{"env": "e", "operator": "A", "segments": 400}, {"env": "e", "operator": "B", "segments": 90}])
    row = theorem2(_segments(), _episodes(), counts, vc_dimension=2, delta=0.05).iloc[0]
    assert row.m == 90 and row.K == 2
    assert row.measured == pytest.approx(0.5)  # ep1 had a failed B segment
    assert row.bound == pytest.approx(pac_bound(90, 2, 2, 0.05))
