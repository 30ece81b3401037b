"""The paper's own configuration (Appendices B and C): Move operators planned by BFS, a DT trained only on random
exploration labelled in hindsight by those operators, and the unconditioned pure DT."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from pyperplan import planner as pyperplan

from hnsdt.agents import ExecutorConfig, SymbolicAgent, rollout
from hnsdt.agents.dt_agents import History, _greedy
from hnsdt.agents.rollout import RandomAgent
from hnsdt.data.collect import Behaviour, CollectConfig, _episode_record, random_start_states
from hnsdt.data.segmentation import hindsight_labels
from hnsdt.models.windows import frames_from_arrays, make_windows
from hnsdt.envs import load_layout
from hnsdt.envs.vector import KeyDoorVectorEnv
from hnsdt.models.dt import DecisionTransformer, DTConfig
from hnsdt.models.train import TrainConfig, train_dt
from hnsdt.symbolic import NAME_TO_ID, SymbolicState, applicable, is_valid_plan, plan, plan_cost, psi
from hnsdt.symbolic.pddl import write_pddl

MOVE = ExecutorConfig(plan_mode="bfs", operators="move")


@pytest.mark.parametrize("name", ["keydoor_5x5", "multikeydoor_9x9", "three_keys"])
def test_move_plans_are_shortest_and_pyperplan_agrees(tmp_path, name):
    text = "@.a.#....\n....A..b.\n#####B###\n.c..C..1.\n..2....3G\n"
    layout = load_layout(text if name == "three_keys" else name)
    start = SymbolicState.initial(layout)
    ops = plan(layout, start, "bfs", "move")
    assert is_valid_plan(layout, start, ops, "move")
    assert len(ops) == plan_cost(plan(layout, start, "cost"))  # one step per operator: a shortest plan
    assert {o.name.split("(")[0] for o in ops} <= {"Move", "PickKey", "OpenDoor", "PickItem"}
    assert all(psi(o).id == NAME_TO_ID["Move"] and psi(o).target == o.target for o in ops if o.kind == "move")
    domain, problem = write_pddl(layout, tmp_path, operators="move")
    solution = pyperplan.search_plan(str(domain), str(problem), pyperplan.SEARCHES["bfs"], None)
    assert solution is not None and len(solution) == len(ops)


def test_no_move_leaves_a_closed_door(keydoor):
    door = keydoor.doors["A"]
    closed = SymbolicState(door, frozenset("a"))
    assert [o.name for o in applicable(keydoor, closed, "move")] == ["OpenDoor(A)"]
    opened = SymbolicState(door, frozenset("a"), frozenset("A"))
    assert sorted(o.name for o in applicable(keydoor, opened, "move")) == sorted(
        f"Move({door[0]},{door[1]}->{r},{c})" for r, c in ((door[0], door[1] - 1), (door[0], door[1] + 1)))


def test_move_labels_end_at_every_change_of_cell(keydoor):
    # (0,0) bump up, right to (0,1), pick on nothing, left back to (0,0): Move(0,0->0,1) covers the bump and
    # the step; the pick and the step back serve Move(0,1->0,0).
    states = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [0, 1, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0]])
    ids, targets = hindsight_labels(keydoor, states, "move")
    assert ids.tolist() == [NAME_TO_ID["Move"]] * 4
    assert targets.tolist() == [[0, 1], [0, 1], [0, 0], [0, 0]]
    with pytest.raises(ValueError, match="unknown operator set"):
        hindsight_labels(keydoor, states, "teleport")


@pytest.mark.parametrize("name", ["keydoor_5x5", "multikeydoor_9x9"])
def test_symbolic_controllers_execute_move_plans_optimally(name):
    layout = load_layout(name)
    env = KeyDoorVectorEnv(8, layout, 0.0, 100)
    episodes = rollout(env, SymbolicAgent(layout, MOVE), seed=0)
    optimal = plan_cost(plan(layout, SymbolicState.initial(layout), "cost"))
    assert all(ep.success and ep.length == optimal for ep in episodes)


@pytest.mark.parametrize("operators", ["move", "goto"])
def test_the_decomposition_judges_each_action(keydoor, operators):
    """The controllers' every action is right (first ones included) and every segment is reached in its
    minimum; an action swapped for a wrong one is counted wrong at that step and nowhere else."""
    from hnsdt.evaluation.paper import Cell, segment_rows
    from hnsdt.evaluation.segments import layout_navigator, right_actions

    config = MOVE if operators == "move" else ExecutorConfig()
    (ep,) = rollout(KeyDoorVectorEnv(1, keydoor, 0.0, 100), SymbolicAgent(keydoor, config), seed=0)
    nav = layout_navigator(keydoor)
    assert right_actions(ep, nav).all()
    rows = segment_rows(Cell("symbolic", "keydoor", 0.0, 0), [ep], nav)
    assert all(r["first_action_right"] and r["right_actions"] == r["steps"] == r["optimal_steps"]
               and r["outcome"] == "achieved" for r in rows)
    assert {r["operator"].split("(")[0] for r in rows} >= {"PickKey", "OpenDoor", "Move" if operators == "move"
                                                             else "GoTo"}
    for t in (0, 4, ep.length - 1):  # a move, the pick of the key (step 4 from the start), the last move
        wrong = ep.actions.copy()
        wrong[t] = (wrong[t] + 1) % 5
        bad = right_actions(replace(ep, actions=wrong), nav)
        assert not bad[t] and bad[np.arange(ep.length) != t].all()


def test_the_unconditioned_dt_reads_states_and_actions_only():
    cfg = DTConfig("none", n_flags=2, grid_h=5, grid_w=5, context=4, n_layers=1, n_heads=2, d_model=16)
    model = DecisionTransformer(cfg)
    names = {n.split(".")[0] for n, _ in model.named_parameters()}
    assert not names & {"subgoal_emb", "target_row_emb", "return_proj"}
    B, h = 3, 4
    batch = {"states": torch.zeros(B, h, 4, dtype=torch.long), "actions": torch.zeros(B, h, dtype=torch.long),
             "timesteps": torch.arange(h).repeat(B, 1), "pad": torch.zeros(B, h, dtype=torch.bool)}
    assert model(**batch).shape == (B, h, 5)
    interleaved = DecisionTransformer(DTConfig("none", 2, 5, 5, context=4, n_layers=1, n_heads=2, d_model=16,
                                               tokens="interleaved"))
    assert interleaved(**batch).shape == (B, h, 5)


def test_the_last_step_loss_counts_each_frame_once():
    frames = frames_from_arrays(np.zeros((6, 3), np.int64), [0, 1, 2, 3, 4, 0], np.zeros(6), [5, 5, 5, 6, 6, 6],
                                np.zeros((6, 2), np.int64), [0] * 6, range(6))
    ends = np.arange(6)
    window = make_windows(frames, ends, 4, "subgoal")["loss_mask"].sum(0)
    last = make_windows(frames, ends, 4, "subgoal", loss="last")["loss_mask"]
    assert window.sum() > 6  # early steps of a segment count in several windows
    assert last.sum() == 6 and last[:, -1].all()
    with pytest.raises(ValueError, match="loss must be one of"):
        make_windows(frames, ends, 4, "subgoal", loss="first")


def _random_walk_frames(layout, n: int, max_steps: int = 60):
    """Frames of ``n`` random walks from random cells, labelled in hindsight by Move operators."""
    starts = random_start_states(layout, n, np.random.default_rng(1))
    cfg = CollectConfig("hnsdt/KeyDoor-v0", layout, max_steps, [0.0], [Behaviour("random", n, "random")])
    episodes = [_episode_record(cfg, cfg.behaviours[0], 0.0, 0, i, ep) for i, ep in
                enumerate(rollout(KeyDoorVectorEnv(n, layout, 0.0, max_steps), RandomAgent(1), 1, starts))]
    lengths = [len(e["actions"]) for e in episodes]
    frames = frames_from_arrays(
        np.concatenate([e["states"][:-1] for e in episodes]), np.concatenate([e["actions"] for e in episodes]),
        np.concatenate([e["rewards"] for e in episodes]), np.concatenate([e["move_subgoal_ids"] for e in episodes]),
        np.concatenate([e["move_subgoal_targets"] for e in episodes]), np.repeat(np.arange(n), lengths),
        np.concatenate([np.arange(k) for k in lengths]), ["random"] * sum(lengths))
    next_states = np.concatenate([e["states"][1:] for e in episodes])
    return frames, next_states


def test_the_achieving_step_loss_counts_only_the_actions_that_achieved_their_subgoal(keydoor):
    """``loss: achieving`` (a named deviation, docs/paper-arm.md): a hindsight segment's last frame is the one
    whose transition gained the operator's effect; every formulation supervises exactly those frames."""
    from hnsdt.data.segmentation import achieved_operator
    from hnsdt.models.windows import achieving_frames, make_episodes, supervised_frames, window_ends

    frames, after = _random_walk_frames(keydoor, 12)
    gained = np.array([achieved_operator(keydoor, SymbolicState.from_observation(keydoor, s),
                                         SymbolicState.from_observation(keydoor, t), "move") is not None
                       for s, t in zip(frames.states, after)])
    achieving = achieving_frames(frames)
    assert np.array_equal(achieving, gained) and 0 < achieving.sum() < (frames.subgoals != 0).sum()
    ends = window_ends(frames, "subgoal", loss="achieving")
    assert np.array_equal(ends, np.flatnonzero(gained))
    assert make_windows(frames, ends, 4, "subgoal", loss="achieving")["loss_mask"].sum() == len(ends)
    starts = np.flatnonzero(np.r_[True, frames.episode[1:] != frames.episode[:-1]])
    lengths = np.diff(np.r_[starts, len(frames)])
    batch = make_episodes(frames, starts, lengths, "subgoal", supervised_frames(frames, "subgoal", "achieving"))
    assert batch["loss_mask"].sum() == gained.sum()
    with pytest.raises(ValueError, match="needs sub-goal labels"):
        window_ends(frames, "return", loss="achieving")


def test_the_steps_measure_acts_from_held_out_states_and_keys_the_record(keydoor):
    """``measure: steps``: distinct held-out states the planner can solve, the method's own agent on them at
    fail_prob 0, the same value on every call; training records it as ``validation_steps``."""
    from hnsdt.compose.config import EnvSpec
    from hnsdt.models.train import train_decision_transformer, validation_episodes
    from hnsdt.evaluation.validation import StepsToExit

    frames, _ = _random_walk_frames(keydoor, 12)
    held = validation_episodes(frames, 0.25)
    env = EnvSpec("keydoor", "hnsdt/KeyDoor-v0", keydoor, 30)
    measure = StepsToExit.from_held_out(frames, held, 16, "hnsdt_paper", env, MOVE, {})
    (course,) = measure.courses
    assert len(course.starts) == 16 and len(np.unique(course.starts, axis=0)) == 16
    assert all((frames.states[held] == s).all(1).any() for s in course.starts)
    cfg = DTConfig("subgoal", keydoor.n_flags, *keydoor.shape, context=4, n_layers=1, d_model=32, max_timestep=100,
                   formulation="episode")
    tc = TrainConfig(epochs=3, batch_size=64, seed=0, validation=0.25, patience=5, device="cpu")
    model, _, usage = train_decision_transformer(frames, cfg, tc, progress=False, measure=measure)
    values = [h["value"] for h in usage["validation_steps"]]
    assert len(values) == 3 and all(0 < v <= 30 for v in values) and "validation_loss" not in usage
    assert measure(model) == measure(model) == values[usage["best_epoch"] - 1]


@pytest.mark.learning
def test_a_dt_trained_on_random_exploration_reaches_move_subgoals_from_unseen_starts(keydoor):
    """The paper's claim for its HNSDT, at the sub-goal level: trained only on random walks labelled in
    hindsight, the DT reaches the cell a Move operator names, starting from cells no training episode started
    on (fail_prob 0, a fresh context window, within the executor's 6-step allowance)."""
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    starts = random_start_states(keydoor, 400, rng)
    starts = starts[(starts[:, 0] + starts[:, 1]) % 2 == 0][:100]  # training episodes start on "even" cells
    cfg = CollectConfig("hnsdt/KeyDoor-v0", keydoor, 100, [0.0], [Behaviour("random", len(starts), "random")])
    episodes = [_episode_record(cfg, cfg.behaviours[0], 0.0, 0, i, ep) for i, ep in
                enumerate(rollout(KeyDoorVectorEnv(len(starts), keydoor, 0.0, 100), RandomAgent(0), 0, starts))]
    lengths = [len(e["actions"]) for e in episodes]
    frames = frames_from_arrays(
        np.concatenate([e["states"][:-1] for e in episodes]), np.concatenate([e["actions"] for e in episodes]),
        np.concatenate([e["rewards"] for e in episodes]), np.concatenate([e["move_subgoal_ids"] for e in episodes]),
        np.concatenate([e["move_subgoal_targets"] for e in episodes]), np.repeat(np.arange(len(episodes)), lengths),
        np.concatenate([np.arange(n) for n in lengths]))
    model_cfg = DTConfig("subgoal", keydoor.n_flags, *keydoor.shape, context=4, n_layers=2, n_heads=4, d_model=64,
                         max_timestep=100)
    model, _ = train_dt(frames, model_cfg, TrainConfig(epochs=10, device="cpu", loss="last"), progress=False)

    tests = []  # every legal Move from every odd cell, with every key/door situation
    for cell in keydoor.free_cells():
        if sum(cell) % 2:
            for flags in ([0, 0], [1, 0], [1, 1]):
                state = np.array([*cell, *flags])
                tests += [(state, op) for op in applicable(keydoor, SymbolicState.from_observation(keydoor, state),
                                                           "move") if op.kind == "move"]
    env = KeyDoorVectorEnv(len(tests), keydoor, 0.0, 6)
    obs, _ = env.reset(seed=0, options={"states": np.stack([s for s, _ in tests])})
    history = History(obs, model_cfg.context)
    goal_ids = np.array([psi(op).id for _, op in tests])
    targets = np.array([op.target for _, op in tests])
    reached = np.zeros(len(tests), bool)
    for _ in range(6):
        rows = np.flatnonzero(~reached)
        if len(rows) == 0:
            break
        actions = np.full(len(tests), 4)
        actions[rows] = _greedy(model, history.window(rows) | {"subgoal_ids": goal_ids[rows],
                                                               "subgoal_targets": targets[rows]})
        obs, *_ = env.step(actions)
        history.record_action(rows, actions)
        history.push(rows, obs)
        reached |= (obs[:, :2] == targets).all(1)
    assert len(tests) >= 80 and reached.mean() >= 0.95, f"{reached.mean():.3f} of {len(tests)} Move sub-goals"
