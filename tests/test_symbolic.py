from collections import deque

import numpy as np
import pytest
from pyperplan import planner as pyperplan

from hnsdt.envs import KeyDoorEnv, load_layout
from hnsdt.symbolic import (
    ID_TO_NAME, NAME_TO_ID, VOCAB_SIZE, SymbolicState, applicable, apply, is_valid_plan, phi, plan, plan_cost, psi,
)
from hnsdt.symbolic.pddl import write_pddl

LAYOUTS = ["keydoor_5x5", "multikeydoor_9x9"]


def test_phi_lists_the_true_predicates(multikeydoor):
    obs = np.array([8, 8, 1, 0, 1, 0, 1, 1])
    assert phi(multikeydoor, obs) == {"At(8,8)", "HasKey(a)", "DoorOpen(A)", "HasItem(1)", "HasItem(2)", "Done"}
    assert "Done" not in phi(multikeydoor, np.array([8, 8, 1, 0, 1, 0, 1, 0]))


def test_phi_reads_the_observations_values_whatever_their_dtype(multikeydoor):
    """(φ is cached by an observation's bytes: an int32 and an int64 vector with the same bytes hold other values.)"""
    wide = np.array([8, 8, 1, 0, 1, 0, 1, 1])
    narrow = wide.astype(np.int32)
    assert phi(multikeydoor, wide) == phi(multikeydoor, narrow) == phi(multikeydoor, list(wide))
    same_bytes = np.frombuffer(wide[:4].tobytes(), dtype=np.int32)  # [8, 0, 8, 0, 1, 0, 0, 0]
    assert phi(multikeydoor, same_bytes) == {"At(8,0)", "HasKey(a)", "DoorOpen(A)"}


def test_an_operator_sent_to_another_process_hashes_as_one_made_there(multikeydoor):
    """Operators cache their hash (the executor hashes its plan at every step); a pickled one is rebuilt from its
    fields, so a worker under another hash seed finds it in its own sets and caches."""
    import pickle
    import subprocess
    import sys

    op = plan(multikeydoor, SymbolicState.initial(multikeydoor))[0]
    hash(op)  # (cached here, under this process's seed)
    check = ("import pickle, sys; op = pickle.loads(sys.stdin.buffer.read()); "
             "assert hash(op) == hash((op.kind, op.obj, op.target)), 'stale hash'; print(op.name)")
    out = subprocess.run([sys.executable, "-c", check], input=pickle.dumps(op), capture_output=True,
                         env={"PYTHONHASHSEED": "123", "PATH": ""}, check=True)
    assert out.stdout.decode().strip() == op.name == "GoTo(key a)"


def _exact_shortest_steps(layout, start_obs):
    """Breadth-first search over the full deterministic low-level state space (fail_prob 0)."""
    env = KeyDoorEnv(layout=layout, max_steps=10**6)
    start = tuple(start_obs)
    dist = {start: 0}
    queue = deque([start])
    while queue:
        s = queue.popleft()
        if SymbolicState.from_observation(layout, np.array(s)).done(layout):
            return dist[s]
        for a in range(5):
            env.reset(options={"state": np.array(s)})
            nxt = tuple(env.step(a)[0])
            if nxt not in dist:
                dist[nxt] = dist[s] + 1
                queue.append(nxt)
    return None


@pytest.mark.parametrize("name", LAYOUTS)
def test_cost_mode_is_optimal_against_exhaustive_low_level_search(name):
    layout = load_layout(name)
    rng = np.random.default_rng(0)
    starts = [SymbolicState.initial(layout)]
    for _ in range(6):  # and from random states holding random flags
        cell = layout.free_cells()[rng.integers(len(layout.free_cells()))]
        if cell in layout.doors.values():
            continue
        flags = rng.integers(0, 2, layout.n_flags)
        starts.append(SymbolicState.from_observation(layout, np.array([*cell, *flags])))
    for s in starts:
        ops = plan(layout, s, "cost")
        assert is_valid_plan(layout, s, ops)
        assert plan_cost(ops) == _exact_shortest_steps(layout, s.to_observation(layout))


@pytest.mark.parametrize("name", LAYOUTS)
def test_bfs_mode_has_the_fewest_operators(name):
    layout = load_layout(name)
    start = SymbolicState.initial(layout)
    ops = plan(layout, start, "bfs")
    assert is_valid_plan(layout, start, ops)
    # No shorter operator sequence exists: enumerate every sequence one shorter.
    frontier = {start}
    for _ in range(len(ops) - 1):
        frontier = {apply(o, s) for s in frontier for o in applicable(layout, s)}
        assert not any(s.done(layout) for s in frontier)


def test_paper_plans(keydoor, multikeydoor):
    assert [o.name for o in plan(keydoor, SymbolicState.initial(keydoor))] == [
        "GoTo(key a)", "PickKey(a)", "GoTo(door A)", "OpenDoor(A)", "GoTo(exit)"]
    ops = plan(multikeydoor, SymbolicState.initial(multikeydoor), "cost")
    assert len(ops) == 13 and plan_cost(ops) == 26
    assert plan_cost(plan(multikeydoor, SymbolicState.initial(multikeydoor), "bfs")) >= 26


def test_operator_preconditions_and_effects(keydoor):
    s = SymbolicState((2, 2), frozenset(), frozenset())  # on the closed door without the key: trapped
    assert applicable(keydoor, s) == []
    s = SymbolicState((4, 0))
    names = [o.name for o in applicable(keydoor, s)]
    assert "PickKey(a)" in names and "GoTo(exit)" not in names
    pick = next(o for o in applicable(keydoor, s) if o.name == "PickKey(a)")
    assert pick.achieved(apply(pick, s).predicates(keydoor))


def test_psi_vocabulary_is_fixed_and_readable(multikeydoor):
    ops = plan(multikeydoor, SymbolicState.initial(multikeydoor))
    ids = [psi(o).id for o in ops]
    assert len(set(ids)) == len(ids) and all(0 < i < VOCAB_SIZE for i in ids)
    assert [ID_TO_NAME[i] for i in ids] == [o.name for o in ops]
    assert psi(ops[0]).target == (2, 0) and NAME_TO_ID["GoTo(exit)"] == VOCAB_SIZE - 2 and NAME_TO_ID["Move"] == VOCAB_SIZE - 1
    assert ID_TO_NAME[0] == "none"


@pytest.mark.parametrize("name", LAYOUTS + ["three_keys"])
def test_pddl_export_solved_by_pyperplan_with_the_same_plan_length(tmp_path, name):
    text = "@.a.#....\n....A..b.\n#####B###\n.c..C..1.\n..2....3G\n"
    layout = load_layout(text if name == "three_keys" else name)
    domain, problem = write_pddl(layout, tmp_path)
    solution = pyperplan.search_plan(str(domain), str(problem), pyperplan.SEARCHES["bfs"], None)
    assert solution is not None
    assert len(solution) == len(plan(layout, SymbolicState.initial(layout), "bfs"))


def test_pddl_from_a_mid_episode_state(tmp_path, multikeydoor):
    state = SymbolicState((4, 5), frozenset("ab"), frozenset("A"), frozenset())
    domain, problem = write_pddl(multikeydoor, tmp_path, state)
    solution = pyperplan.search_plan(str(domain), str(problem), pyperplan.SEARCHES["bfs"], None)
    assert len(solution) == len(plan(multikeydoor, state, "bfs"))
