import numpy as np
import pytest

from hnsdt.agents import ExecutorConfig, PlanExecutor, SymbolicAgent, rollout
from hnsdt.envs import KeyDoorVectorEnv, load_layout
from hnsdt.envs.oracle import optimum


@pytest.mark.parametrize("name,max_steps", [("keydoor_5x5", 100), ("multikeydoor_9x9", 250)])
@pytest.mark.parametrize("fail_prob", [0.0, 0.1, 0.2, 0.3])
def test_symbolic_baseline_is_the_exact_optimum(name, max_steps, fail_prob):
    """The symbolic baseline's success and mean steps are the exact optimum's (value iteration over every state,
    :mod:`hnsdt.envs.oracle`) within 4 standard errors of 400 episodes: at fail_prob 0.3 on Case 2 (34.6 steps)
    ± 0.7 steps. A planner that wastes 5 % of its steps on a no-op fails every case (tried)."""
    layout = load_layout(name)
    best = optimum(layout, fail_prob, max_steps)
    episodes = rollout(KeyDoorVectorEnv(400, layout, fail_prob, max_steps), SymbolicAgent(layout), seed=3)
    success = np.array([e.success for e in episodes])
    assert success.mean() >= best.success - 4 * np.sqrt(best.success * (1 - best.success) / len(success)) - 1e-9
    steps = np.array([e.length for e in episodes if e.success], dtype=float)
    if fail_prob == 0.0:
        assert (steps == best.steps).all()
    else:
        assert abs(steps.mean() - best.steps) <= 4 * steps.std() / np.sqrt(len(steps)), (steps.mean(), best.steps)


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
