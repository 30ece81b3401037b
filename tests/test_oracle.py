import numpy as np
import pytest

from hnsdt.agents import SymbolicAgent, rollout
from hnsdt.envs import KeyDoorVectorEnv, load_layout
from hnsdt.envs.oracle import MDP, optimum
from hnsdt.symbolic import NoPlanError, SymbolicState, plan, plan_cost


def test_state_counts_match_the_paper_layouts(keydoor, multikeydoor):
    assert len(MDP(keydoor)) == 84 and len(MDP(multikeydoor)) == 4160


@pytest.mark.parametrize("fail_prob, gamma", [(0.0, 1.0), (0.3, 1.0), (0.3, 0.9)])
def test_stopping_once_the_live_states_values_repeat_changes_no_bit(keydoor, multikeydoor, fail_prob, gamma):
    """solve() stops when the values of the states that can still succeed repeat (every layout has states that
    cannot, whose return falls forever): the same bits as every step of the horizon, which it runs when no state
    is known to be live."""
    from hnsdt.envs.generate import generate

    for layout in (keydoor, multikeydoor, generate("keydoor_maze", 0)):
        every_step = MDP(layout)
        assert 0 < every_step.alive.sum() < len(every_step)  # (live and dead states both)
        every_step.alive = np.zeros_like(every_step.alive)
        assert MDP(layout).solve(fail_prob, 250, gamma) == every_step.solve(fail_prob, 250, gamma)


@pytest.mark.parametrize("p,T", [(0.5, 3), (0.3, 5), (0.0, 2)])
def test_value_iteration_against_a_hand_computed_corridor(p, T):
    """'@G': move right until it works. Success at step k has probability (1-p) p^(k-1)."""
    layout = load_layout("@G")
    probs = np.array([(1 - p) * p ** (k - 1) for k in range(1, T + 1)])
    success = probs.sum()
    ret = sum(pk * (-0.1 * k + 1.0) for k, pk in enumerate(probs, 1)) + (1 - success) * (-0.1 * T)
    steps = sum(pk * k for k, pk in enumerate(probs, 1)) / success
    opt = optimum(layout, p, T)
    assert opt.success == pytest.approx(success)
    assert opt.ret == pytest.approx(ret)
    assert opt.steps == pytest.approx(steps)


@pytest.mark.parametrize("p,T,gamma", [(0.5, 3, 0.9), (0.3, 6, 0.5)])
def test_discounted_value_against_the_hand_computed_corridor(p, T, gamma):
    """Theorem 1's V*_γ: the same corridor, each step's reward discounted by γ^t."""
    cost = lambda k: sum(-0.1 * gamma**t for t in range(k))  # noqa: E731
    value = sum((1 - p) * p ** (k - 1) * (cost(k) + gamma ** (k - 1)) for k in range(1, T + 1))
    value += p**T * cost(T)
    assert optimum(load_layout("@G"), p, T, gamma).ret == pytest.approx(value)


def test_a_two_step_detour_layout_by_hand():
    """'@a#\\n.A.G'... kept tiny: key, door, goal in a row; at fail 0 the optimum is the planner's cost."""
    layout = load_layout("@aAG")
    opt = optimum(layout, 0.0, 20)
    assert opt.steps == 5 and opt.ret == pytest.approx(-0.5 + 1.0) and opt.success == 1.0


@pytest.mark.parametrize("name,max_steps", [("keydoor_5x5", 100), ("multikeydoor_9x9", 250)])
def test_optimum_at_fail_zero_equals_the_cheapest_plan(name, max_steps):
    layout = load_layout(name)
    opt = optimum(layout, 0.0, max_steps)
    assert opt.steps == plan_cost(plan(layout, SymbolicState.initial(layout), "cost"))


@pytest.mark.parametrize("name", ["keydoor_5x5", "multikeydoor_9x9"])
def test_fewest_steps_from_any_state_is_the_cheapest_plans_cost(name):
    """From every state the planner can solve, the fewest steps at fail 0 are its cheapest plan's cost (the
    floor of a validation by acting); capped at the horizon; a wall cell is refused."""
    layout = load_layout(name)
    mdp = MDP(layout)
    pick = np.random.default_rng(0).choice(len(mdp), size=40, replace=False)
    states, done = mdp.states[pick], mdp.done[pick]
    fewest = mdp.fewest_steps(states, 250)
    assert (fewest[done] == 0).all()
    for state, steps in zip(states[~done], fewest[~done]):
        try:
            cost = plan_cost(plan(layout, SymbolicState.from_observation(layout, state), "cost"))
        except NoPlanError:  # (a key used up on the wrong door): no policy succeeds either
            assert steps == 250
            continue
        assert steps == cost
    assert (mdp.fewest_steps(states, 3) == np.minimum(fewest, 3)).all()
    wall = next((r, c) for r in range(layout.shape[0]) for c in range(layout.shape[1])
                if (r, c) not in set(map(tuple, layout.free_cells())))
    with pytest.raises(ValueError, match="not one of the layout's"):
        mdp.fewest_steps(np.array([[*wall] + [0] * layout.n_flags]), 10)


def test_symbolic_agent_is_near_optimal_in_expectation(keydoor):
    opt = optimum(keydoor, 0.2, 100)
    eps = rollout(KeyDoorVectorEnv(2000, keydoor, 0.2, 100), SymbolicAgent(keydoor), seed=11)
    lengths = np.array([e.length for e in eps])
    assert abs(lengths.mean() - opt.steps) < 4 * lengths.std() / np.sqrt(len(lengths))
    assert opt.success > 0.999
