import numpy as np
import pytest

from hnsdt.agents import ExecutorConfig, PlanExecutor, SymbolicAgent, rollout
from hnsdt.envs import KeyDoorVectorEnv, load_layout


@pytest.mark.parametrize("name,max_steps", [("keydoor_5x5", 100), ("multikeydoor_9x9", 250)])
@pytest.mark.parametrize("fail_prob", [0.0, 0.1, 0.2, 0.3])
def test_symbolic_baseline_succeeds(name, max_steps, fail_prob):
    layout = load_layout(name)
    episodes = rollout(KeyDoorVectorEnv(200, layout, fail_prob, max_steps), SymbolicAgent(layout), seed=3)
    assert np.mean([e.success for e in episodes]) >= 0.99
    if fail_prob == 0.0:
        optimal = 14 if name == "keydoor_5x5" else 26
        assert all(e.length == optimal for e in episodes)
    else:  # each move takes 1/(1-p) attempts on average
        mean = np.mean([e.length for e in episodes])
        assert mean > (14 if name == "keydoor_5x5" else 26)


def test_executor_advances_when_effects_hold(keydoor):
    ex = PlanExecutor(keydoor).start(np.array([0, 0, 0, 0]))
    assert ex.operator.name == "GoTo(key a)"
    for cell in ([1, 0], [2, 0], [3, 0]):
        assert ex.observe(np.array([*cell, 0, 0])).name == "GoTo(key a)"
    assert ex.observe(np.array([4, 0, 0, 0])).name == "PickKey(a)"
    assert ex.observe(np.array([4, 0, 1, 0])).name == "GoTo(door A)"
    assert [s.operator for s in ex.segments] == ["GoTo(key a)", "PickKey(a)", "GoTo(door A)"]
    assert ex.segments[0].achieved and (ex.segments[0].start, ex.segments[0].end) == (0, 4)
    assert ex.replans == 0


def test_executor_replans_on_overrun(keydoor):
    ex = PlanExecutor(keydoor, ExecutorConfig(allowance_factor=1.0, allowance_min=2)).start(np.array([0, 0, 0, 0]))
    for _ in range(5):  # GoTo(key a) costs 4 steps; standing still overruns it
        ex.observe(np.array([0, 0, 0, 0]))
    assert ex.replans == 1 and "overran GoTo(key a)" in ex.replan_reasons[0]
    assert ex.operator.name == "GoTo(key a)" and not ex.segments[0].achieved
    assert ex.segments[0].outcome == "overran" and ex.replan_counts == {"overran": 1, "broken": 0, "exhausted": 0}


def test_executor_replans_when_preconditions_break(keydoor):
    ex = PlanExecutor(keydoor).start(np.array([3, 0, 0, 0]))
    ex.observe(np.array([4, 0, 0, 0]))
    assert ex.operator.name == "PickKey(a)"
    ex.observe(np.array([3, 0, 0, 0]))  # walked off the key instead of picking it: At(key) no longer holds
    assert ex.replans == 1 and "preconditions broken at PickKey(a)" in ex.replan_reasons[0]
    assert ex.operator.name == "GoTo(key a)"
    assert [s.outcome for s in ex.segments] == ["achieved", "broken", ""]  # the new GoTo is still open
    assert ex.replan_counts["broken"] == 1


def test_executor_is_stuck_when_trapped(keydoor):
    ex = PlanExecutor(keydoor).start(np.array([2, 1, 0, 0]))
    ex.observe(np.array([2, 2, 0, 0]))  # stepped into the closed door without the key
    assert ex.stuck and ex.operator is None
