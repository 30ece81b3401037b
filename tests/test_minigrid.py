"""MiniGrid's own worlds (hnsdt.minigrid): our written-out rules, φ and the exact optimum against
MiniGrid's own stepping; the action failures; the BabyAI bot; bad ids."""

from pathlib import Path

import numpy as np
import pytest

from hnsdt.minigrid import (
    Actions, MiniGridError, WorldMDP, make_env, read_world, snapshot, world_of,
)
from hnsdt.minigrid.bot import bot_episode
from hnsdt.minigrid.world import CARRIED, GOAL, GONE, OPEN_DOOR, PICKUP
from hnsdt.minigrid.abstraction import DONE, phi, phi_live

WORLDS = ("MiniGrid-DoorKey-5x5-v0", "MiniGrid-DoorKey-6x6-v0", "MiniGrid-Unlock-v0", "MiniGrid-UnlockPickup-v0",
          "MiniGrid-KeyCorridorS3R1-v0", "MiniGrid-BlockedUnlockPickup-v0")


def _target_name(world):
    if world.task == OPEN_DOOR:
        r, c = world.doors[world.target].cell
        return f"{r},{c}"
    return world.objects[world.target].name if world.task == PICKUP else ""


@pytest.mark.parametrize("env_id", WORLDS)
def test_phi_and_the_rules_agree_with_minigrid_stepping_on_random_actions(env_id):
    """MiniGrid steps its env, World.step our state, on the same random actions (biased towards the ones that
    change something); every step the whole state, every predicate of φ and the end of the episode agree."""
    rng = np.random.default_rng(0)
    env = make_env(env_id)
    seen = set()
    for seed in range(16):
        env.reset(seed=seed)
        world, live = read_world(env, env_id, seed)
        s = world.start
        for _ in range(400):
            a = int(rng.choice(7, p=[0.15, 0.15, 0.3, 0.12, 0.1, 0.15, 0.03]))
            _, reward, terminated, truncated, _ = env.step(a)
            s, success = world.step(s, a)
            assert snapshot(world, env, live) == s
            assert phi(world, s) == phi_live(env, world.task, _target_name(world))
            assert success == terminated == (reward > 0) == (DONE in phi(world, s))
            seen |= {cell for cell in s.objects if cell in (CARRIED, GONE)} | set(s.doors)
            if terminated or truncated:
                break
    assert CARRIED in seen and 0 in seen  # (something was carried and a door opened: the walk did get somewhere)


@pytest.mark.parametrize("env_id", WORLDS + ("MiniGrid-DoorKey-16x16-v0", "MiniGrid-KeyCorridorS3R3-v0",
                                              "MiniGrid-FourRooms-v0", "MiniGrid-LavaCrossingS9N1-v0",
                                              "MiniGrid-ObstructedMaze-2Dlhb-v1", "MiniGrid-Fetch-8x8-N3-v0"))
def test_our_observation_is_minigrids_own_to_the_byte(env_id):
    """make_env's envs compute the observation with hnsdt.minigrid.view.gen_obs; on random walks (every action,
    doors opened, things carried and dropped, episodes ended and begun) it is MiniGridEnv.gen_obs's, byte for byte —
    and an env that sees through walls (Fetch) keeps MiniGrid's own."""
    from minigrid.minigrid_env import MiniGridEnv

    rng = np.random.default_rng(1)
    env = make_env(env_id)
    u = env.unwrapped
    assert ("gen_obs" in vars(u)) == (not u.see_through_walls)
    checked = set()
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        for _ in range(250):
            want = MiniGridEnv.gen_obs(u)
            assert obs["image"].dtype == want["image"].dtype and np.array_equal(obs["image"], want["image"])
            assert (obs["direction"], obs["mission"]) == (want["direction"], want["mission"])
            checked.add((u.agent_dir, u.carrying is not None))
            obs, _, terminated, truncated, _ = env.step(int(rng.choice(7, p=[0.2, 0.2, 0.3, 0.1, 0.08, 0.1, 0.02])))
            if terminated or truncated:
                break
    assert {d for d, _ in checked} == {0, 1, 2, 3}


def test_a_view_that_differs_from_minigrids_is_caught():
    """The check above can fail: a view that lets the agent see through walls differs on a DoorKey world."""
    from minigrid.minigrid_env import MiniGridEnv

    from hnsdt.minigrid import view

    env = make_env("MiniGrid-DoorKey-8x8-v0")
    env.reset(seed=3)
    u = env.unwrapped
    see_all = lambda v, n: [True] * (n * n)  # noqa: E731
    original, view._visible = view._visible, see_all
    try:
        differs = []
        for _ in range(8):  # (turning round on the spot: walls in view from every side)
            env.step(1)
            differs.append(not np.array_equal(view.gen_obs(u)["image"], MiniGridEnv.gen_obs(u)["image"]))
        assert any(differs)
    finally:
        view._visible = original


def test_a_predicate_the_rules_get_wrong_is_caught():
    """The check above can fail: with toggle made to open a locked door without its key, φ disagrees."""
    env_id = "MiniGrid-DoorKey-5x5-v0"
    env = make_env(env_id)
    env.reset(seed=0)
    world, live = read_world(env, env_id, 0)
    wrong = world.start._replace(doors=(0,))  # what a rule that ignored the key would give
    assert phi(world, wrong) != phi_live(env, world.task)


def test_action_failures_leave_the_world_unchanged_and_count_the_step():
    env_id = "MiniGrid-DoorKey-5x5-v0"
    env = make_env(env_id, fail_prob=1.0)
    env.reset(seed=3)
    world, live = read_world(env, env_id, 3)
    for a in (Actions.left, Actions.right, Actions.forward):
        *_, info = env.step(a)
        assert info["move_failed"] and snapshot(world, env, live) == world.start
    assert env.unwrapped.step_count == 3
    *_, info = env.step(Actions.toggle)  # never fails
    assert not info["move_failed"]
    # The same seed draws the same failures; another failure_seed other ones on the same world.
    runs = []
    for failure_seed in (0, 0, 1):
        env = make_env(env_id, fail_prob=0.5)
        env.reset(seed=3, options={"failure_seed": failure_seed})
        assert read_world(env, env_id, 3)[0].start == world.start
        runs.append([env.step(Actions.left)[-1]["move_failed"] for _ in range(40)])
    assert runs[0] == runs[1] != runs[2]


@pytest.mark.parametrize("env_id, fail_prob", [("MiniGrid-DoorKey-5x5-v0", 0.0), ("MiniGrid-DoorKey-5x5-v0", 0.3),
                                               ("MiniGrid-Unlock-v0", 0.2)])
def test_the_optimum_is_what_its_policy_gets_in_minigrid(env_id, fail_prob):
    """The optimal policy, played in MiniGrid's own env with its failures: at fail_prob 0 exactly the optimum's
    steps and reward; with failures its mean reward and steps within 4 standard errors over 300 episodes."""
    world = world_of(env_id, 5)
    mdp = WorldMDP(world)
    opt, policy = mdp.solve(fail_prob, keep_policy=True)
    env = make_env(env_id, fail_prob)
    rewards, steps = [], []
    for k in range(300 if fail_prob else 1):
        env.reset(seed=5, options={"failure_seed": k})
        w, live = read_world(env, env_id, 5)
        for t in range(world.max_steps):
            s = snapshot(w, env, live)
            _, reward, terminated, truncated, _ = env.step(int(policy[t, mdp.index[s]]))
            if terminated or truncated:
                break
        rewards.append(reward)
        steps.append(t + 1)
    assert opt.success == pytest.approx(1.0)
    if not fail_prob:
        assert (steps[0], rewards[0]) == (opt.steps, pytest.approx(opt.ret))
        return
    for values, expected in ((rewards, opt.ret), (steps, opt.steps)):
        assert abs(np.mean(values) - expected) < 4 * np.std(values) / np.sqrt(len(values)) + 1e-9


def test_the_settled_shortcut_gives_what_every_step_gives():
    mdp = WorldMDP(world_of("MiniGrid-KeyCorridorS3R1-v0", 2))
    for p in (0.0, 0.2):
        fast, slow = mdp.solve(p)[0], mdp.solve(p, settle=False)[0]
        for a, b in zip((fast.success, fast.ret, fast.steps), (slow.success, slow.ret, slow.steps)):
            assert a == pytest.approx(b, abs=1e-12)


def test_the_optimum_beats_the_babyai_bot_and_the_bot_solves_its_worlds():
    for env_id in ("MiniGrid-DoorKey-8x8-v0", "MiniGrid-UnlockPickup-v0"):
        for seed in range(3):
            ep = bot_episode(env_id, seed)
            opt = WorldMDP(world_of(env_id, seed)).solve(0.0)[0]
            assert ep.success and not ep.error
            assert ep.steps >= opt.steps and ep.reward <= opt.ret + 1e-12


def test_the_worlds_say_what_ends_them():
    assert world_of("MiniGrid-DoorKey-8x8-v0", 0).task == GOAL
    assert world_of("MiniGrid-Unlock-v0", 0).task == OPEN_DOOR
    up = world_of("MiniGrid-UnlockPickup-v0", 0)
    assert up.task == PICKUP and up.objects[up.target].kind == "box"


@pytest.mark.parametrize("env_id, message", [
    ("MiniGrid-NoSuchWorld-v0", "is not a registered gymnasium id"),
    ("CartPole-v1", "is not a MiniGrid env"),
    ("MiniGrid-Empty-8x8-v0", "has no key and locked door"),
    ("MiniGrid-LavaCrossingS9N1-v0", "cell type 'lava'"),
])
def test_a_world_that_is_not_a_key_door_world_is_one_clear_line(env_id, message):
    with pytest.raises(MiniGridError, match=message) as err:
        world_of(env_id, 0)
    assert "\n" not in str(err.value)


def test_the_reference_stage_writes_both_references_and_a_bad_world_writes_nothing(tmp_path):
    """The stage on one world (one seed, one fail_prob): the optimum's row and the bot's, each world's summary;
    a world the params do not name, or an id that is no key-door world, is one line and leaves no output."""
    import yaml

    from hnsdt.compose.params import ParamsError, validate
    from hnsdt.evaluation.minigrid import read_csv
    from hnsdt.stages.minigrid_reference import minigrid_reference
    from conftest import REPO

    raw = yaml.safe_load((Path(REPO) / "params.yaml").read_text())
    raw["minigrid"].update(envs={"dk5": {"id": "MiniGrid-DoorKey-5x5-v0"}, "empty": {"id": "MiniGrid-Empty-5x5-v0"}},
                           test_seeds={"first": 100007, "count": 1}, fail_probs=[0.0], episodes=2)
    params = validate(raw)
    out = minigrid_reference(params, "dk5", tmp_path / "dk5")
    rows = read_csv((out / "reference.csv").read_text())
    assert [(r["method"], r["seed"], r["episodes"]) for r in rows] == [
        ("optimum", 100007, 0), ("babyai_bot", 100007, 2), ("symbolic", 100007, 2)]
    assert rows[0]["success"] == pytest.approx(1.0) and min(rows[1]["steps"], rows[2]["steps"]) >= rows[0]["steps"]
    assert rows[2]["plans"] >= 1 and rows[1]["success"] == rows[2]["success"] == 1.0
    assert len(read_csv((out / "summary.csv").read_text())) == 3
    with pytest.raises(ParamsError, match="minigrid.envs has no 'nope'"):
        minigrid_reference(params, "nope", tmp_path / "nope")
    with pytest.raises(MiniGridError, match="has no key and locked door"):
        minigrid_reference(params, "empty", tmp_path / "empty")
    assert not (tmp_path / "nope").exists() and not (tmp_path / "empty").exists()


def _plan_names(env_id, seed=0, mode="cost"):
    from hnsdt.minigrid.operators import PlanState
    from hnsdt.minigrid.planner import plan

    world = world_of(env_id, seed)
    return [op.name(world) for op in plan(world, PlanState.of(world.start), mode)]


def test_plans_carry_one_object_at_a_time():
    """DoorKey: key, door, goal. UnlockPickup: the key must be put down before the box is picked up. Blocked
    UnlockPickup: the ball in front of the door is moved and put down, then the key fetched."""
    assert _plan_names("MiniGrid-DoorKey-8x8-v0") == [
        "GoTo(yellow key)", "PickUp(yellow key)", "GoTo(yellow door)", "Open(yellow door)", "GoTo(goal)"]
    up = _plan_names("MiniGrid-UnlockPickup-v0")
    assert up[-2:][1].startswith("PickUp(") and up[-2:][1].endswith("box)") and "Drop" in up
    assert up.index("Drop") > next(i for i, n in enumerate(up) if n.startswith("Open("))
    blocked = _plan_names("MiniGrid-BlockedUnlockPickup-v0")
    assert blocked[:3] == [blocked[0], blocked[1], "Drop"] and blocked[1].endswith("ball)")
    for mode in ("bfs", "cost"):  # both searches find a plan of the same operators here
        assert len(_plan_names("MiniGrid-KeyCorridorS3R1-v0", 3, mode)) >= 4


def test_without_drop_the_carrying_worlds_have_no_plan(monkeypatch):
    """The Drop operator is what makes UnlockPickup solvable: without it the planner finds no plan."""
    from hnsdt.minigrid import operators
    from hnsdt.minigrid.planner import NoPlanError

    every = operators.applicable
    monkeypatch.setattr("hnsdt.minigrid.planner.applicable",
                        lambda world, s: [op for op in every(world, s) if op.kind != operators.DROP])
    with pytest.raises(NoPlanError):
        _plan_names("MiniGrid-UnlockPickup-v0")


@pytest.mark.parametrize("env_id", ["MiniGrid-DoorKey-8x8-v0", "MiniGrid-Unlock-v0", "MiniGrid-UnlockPickup-v0",
                                    "MiniGrid-KeyCorridorS3R1-v0", "MiniGrid-BlockedUnlockPickup-v0"])
def test_the_symbolic_agent_solves_minigrid_worlds_in_minigrids_own_env(env_id):
    """Planner + controllers, played in MiniGrid's env: every world solved with and without failures, never
    faster than the exact optimum, at fail_prob 0 within 1.3 times its steps (the planner does not count turns
    and puts a carried object down where its controller finds room)."""
    from hnsdt.minigrid.controllers import symbolic_episode

    for seed in range(3):
        calm, rough = symbolic_episode(env_id, seed), symbolic_episode(env_id, seed, 0.3, failure_seed=1)
        assert calm.success and rough.success and calm.plans >= 1 and not calm.error
        if env_id != "MiniGrid-BlockedUnlockPickup-v0":  # (its optimum takes 10 s a world)
            best = WorldMDP(world_of(env_id, seed)).solve(0.0)[0].steps
            assert best <= calm.steps <= 1.3 * best


@pytest.mark.parametrize("env_id", ["MiniGrid-DoorKey-8x8-v0", "MiniGrid-Unlock-v0", "MiniGrid-UnlockPickup-v0",
                                    "MiniGrid-KeyCorridorS3R1-v0", "MiniGrid-KeyCorridorS3R3-v0",
                                    "MiniGrid-BlockedUnlockPickup-v0"])
def test_pddl_export_solved_by_pyperplan_with_the_same_plan_length(tmp_path, env_id):
    """pyperplan's breadth-first search on the exported domain finds plans of as many operators as ours, from
    each world's start (three worlds) and from the middle of an episode (the symbolic agent's state after 9
    steps in MiniGrid's env)."""
    import logging

    from pyperplan import planner as pyperplan

    from hnsdt.minigrid.controllers import SymbolicAgent
    from hnsdt.minigrid.operators import PlanState
    from hnsdt.minigrid.pddl import write_pddl
    from hnsdt.minigrid.planner import plan

    logging.disable(logging.CRITICAL)  # (pyperplan logs every search at INFO)
    try:
        for seed in range(3):
            env = make_env(env_id)
            env.reset(seed=seed)
            world, live = read_world(env, env_id, seed)
            agent = SymbolicAgent(world, "bfs")
            for _ in range(9):
                env.step(agent.act(snapshot(world, env, live)))
            for state in (world.start, snapshot(world, env, live)):
                domain, problem = write_pddl(world, tmp_path / f"{seed}", state)
                solution = pyperplan.search_plan(str(domain), str(problem), pyperplan.SEARCHES["bfs"], None)
                assert solution is not None and len(solution) == len(plan(world, PlanState.of(state), "bfs"))
    finally:
        logging.disable(logging.NOTSET)


def test_hnsdt_plan_and_pddl_take_a_minigrid_id(tmp_path):
    from conftest import hnsdt_cli

    out = hnsdt_cli("plan", "--env", "MiniGrid-UnlockPickup-v0", "--seed", "1")
    assert out.returncode == 0 and "Drop" in out.stdout and "PickUp(" in out.stdout, out.stderr
    out = hnsdt_cli("pddl", "--env", "MiniGrid-DoorKey-5x5-v0", "--out", str(tmp_path))
    assert out.returncode == 0 and "(:goal (at c-" in (tmp_path / "problem.pddl").read_text()
    bad = hnsdt_cli("plan", "--env", "MiniGrid-Empty-5x5-v0")
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "no key and locked door" in bad.stderr


def test_a_minigrid_dataset_is_read_by_stock_lerobot_with_its_sub_goal_segmentation(tmp_path):
    """Noisy symbolic-agent episodes on DoorKey-5x5 as a LeRobot dataset: stock LeRobotDataset reads every frame;
    each frame's task is its operator's name and its sub-goal kind that operator's; the operators of a successful
    episode end with GoTo(goal); the same settings write the same bytes."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from hnsdt.data.card import data_md5
    from hnsdt.data.minigrid_dataset import write_minigrid_dataset
    from hnsdt.minigrid.collect import SUBGOAL_NAMES, collect_episodes

    meta = dict(env_id="MiniGrid-DoorKey-5x5-v0", world_seeds=[0, 1, 2], fail_probs=[0.0, 0.3], epsilon=0.2, seed=4,
                license="apache-2.0")
    roots = []
    for copy in ("a", "b"):
        episodes = collect_episodes("MiniGrid-DoorKey-5x5-v0", [0, 1, 2], [0.0, 0.3], 1, 0.2, 4)
        roots.append(write_minigrid_dataset(tmp_path / copy, "local/dk5", episodes, 10, meta))
    assert data_md5(roots[0]) == data_md5(roots[1])
    ds = LeRobotDataset("local/dk5", root=roots[0])
    assert ds.num_episodes == 6 and ds.num_frames == sum(len(e["actions"]) for e in episodes)
    def kind_of(task: str) -> str:
        named = {"none": "none", "Drop": "drop", "GoTo(goal)": "goto_goal"}
        if task in named:
            return named[task]
        if task.startswith("GoTo("):
            return "goto_door" if task.endswith(" door)") else "goto_object"
        return "pickup" if task.startswith("PickUp(") else "open"

    for i in range(ds.num_frames):
        f = ds[i]
        assert SUBGOAL_NAMES[int(f["subgoal"])] == kind_of(f["task"])
        assert f["observation.view"].shape == (147,) and 0 <= int(f["action"]) <= 6
    ends = [e["names"][-1] for e in episodes if e["success"]]
    assert ends and set(ends) == {"GoTo(goal)"} and sum(e["success"] for e in episodes) >= 5
    with pytest.raises(ValueError, match="no episodes"):
        write_minigrid_dataset(tmp_path / "empty", "local/x", [], 10, meta)
    assert not (tmp_path / "empty").exists()


def test_recordings_show_facing_and_carrying_and_rerun_verifies_them(tmp_path):
    """The symbolic agent's and the bot's episodes as .rrd (checked by `rerun rrd verify`) and .mcap: MiniGrid's
    own frames, and per step which way the agent faces and what it carries — the key between picking it up and
    the door, nothing before."""
    import json
    import subprocess
    import sys

    from mcap.reader import make_reader

    from hnsdt.evaluation.minigrid import recordings

    files = recordings("MiniGrid-DoorKey-5x5-v0", 2, [0.2], {"git_revision": "test"})
    assert sorted(files) == ["babyai_bot_fp0.2.mcap", "babyai_bot_fp0.2.rrd", "symbolic_fp0.2.mcap",
                             "symbolic_fp0.2.rrd"]
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    rrds = [str(p) for p in sorted(tmp_path.glob("*.rrd"))]
    verify = subprocess.run([str(Path(sys.executable).parent / "rerun"), "rrd", "verify", *rrds],
                            capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr[-2000:]
    reader = make_reader(open(tmp_path / "symbolic_fp0.2.mcap", "rb"))
    topics = {}
    for _, channel, message in reader.iter_messages():
        topics.setdefault(channel.topic, []).append(message.data)
    assert set(topics) == {"/world", "/events", "/step"}
    steps = [json.loads(m) for m in topics["/step"]]
    carried = [s["carrying"] for s in steps]
    assert carried[0] == "" and "yellow key" in carried and {s["direction"] for s in steps} <= {
        "east", "south", "west", "north"} and len({s["direction"] for s in steps}) > 1
    events = [m.decode(errors="ignore") for m in topics["/events"]]
    assert any("carrying yellow key" in e for e in events) and any("success" in e for e in events)
    assert len(topics["/world"]) == len(steps)
