import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from hnsdt.envs import ENV_IDS, KeyDoorEnv

UP, RIGHT, DOWN, LEFT, PICK = range(5)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_check_env_passes_on_every_registered_id(env_id):
    check_env(gym.make(env_id, fail_prob=0.2).unwrapped, skip_render_check=False)


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_seeded_resets_are_deterministic(env_id):
    def run(seed):
        env = gym.make(env_id, fail_prob=0.3)
        obs, _ = env.reset(seed=seed)
        actions = np.random.default_rng(0).integers(0, 5, 200)
        trace = [obs]
        for a in actions:
            obs, *_ = env.step(a)
            trace.append(obs)
        return np.array(trace)

    assert np.array_equal(run(7), run(7))
    assert not np.array_equal(run(7), run(8))


def test_observation_is_the_paper_state_tuple(multikeydoor):
    env = KeyDoorEnv(layout=multikeydoor)
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.int64
    assert env.layout.state_names == ["row", "col", "has_key_a", "has_key_b", "door_open_A", "door_open_B",
                                      "has_item_1", "has_item_2"]
    assert obs.tolist() == [0, 0, 0, 0, 0, 0, 0, 0]


def test_optimal_action_sequence_reaches_goal_with_expected_rewards(keydoor):
    env = KeyDoorEnv(layout=keydoor, fail_prob=0.0)
    env.reset(seed=0)
    seq = [DOWN] * 4 + [PICK] + [UP, UP, RIGHT, RIGHT] + [PICK] + [RIGHT, UP, UP, RIGHT]
    rewards = []
    for i, a in enumerate(seq):
        obs, r, term, trunc, info = env.step(a)
        rewards.append(r)
        assert term == (i == len(seq) - 1) and not trunc
    assert obs.tolist() == [0, 4, 1, 1]
    assert rewards[:-1] == pytest.approx([-0.1] * (len(seq) - 1))
    assert rewards[-1] == pytest.approx(0.9)
    assert info["success"]


def test_closed_door_traps_the_agent_without_its_key(keydoor):
    env = KeyDoorEnv(layout=keydoor)
    env.reset(seed=0, options={"state": [2, 1, 0, 0]})
    obs, *_ = env.step(RIGHT)  # enter the closed door A at (2, 2)
    assert obs[:2].tolist() == [2, 2]
    for a in [UP, RIGHT, DOWN, LEFT, PICK] * 5:
        obs, *_ = env.step(a)
        assert obs.tolist() == [2, 2, 0, 0]  # no key: cannot open, cannot leave


def test_door_opens_only_with_its_key_and_then_can_be_left(keydoor):
    env = KeyDoorEnv(layout=keydoor)
    env.reset(seed=0, options={"state": [2, 2, 1, 0]})
    assert env.step(RIGHT)[0][:2].tolist() == [2, 2]
    obs, *_ = env.step(PICK)
    assert obs.tolist() == [2, 2, 1, 1]
    assert env.step(RIGHT)[0][:2].tolist() == [2, 3]


def test_walls_and_edges_block(keydoor):
    env = KeyDoorEnv(layout=keydoor)
    env.reset(seed=0)
    assert env.step(UP)[0][:2].tolist() == [0, 0]  # edge
    assert env.step(LEFT)[0][:2].tolist() == [0, 0]
    env.reset(seed=0, options={"state": [0, 1, 0, 0]})
    assert env.step(RIGHT)[0][:2].tolist() == [0, 1]  # wall at (0, 2)


def test_goal_without_items_is_not_success(multikeydoor):
    env = KeyDoorEnv(layout=multikeydoor)
    env.reset(seed=0, options={"state": [7, 8, 1, 1, 1, 1, 1, 0]})
    obs, r, term, *_ = env.step(DOWN)
    assert obs[:2].tolist() == [8, 8] and not term and r == pytest.approx(-0.1)
    env.reset(seed=0, options={"state": [7, 8, 1, 1, 1, 1, 1, 1]})
    obs, r, term, *_ = env.step(DOWN)
    assert term and r == pytest.approx(0.9)


def test_truncation_at_max_steps(keydoor):
    env = KeyDoorEnv(layout=keydoor, max_steps=7)
    env.reset(seed=0)
    for i in range(7):
        _, _, term, trunc, _ = env.step(UP)
        assert not term and trunc == (i == 6)


@pytest.mark.parametrize("fail_prob", [0.1, 0.3])
def test_move_failure_rate_within_statistical_bounds(keydoor, fail_prob):
    env = KeyDoorEnv(layout=keydoor, fail_prob=fail_prob, max_steps=10**6)
    env.reset(seed=3, options={"state": [1, 0, 0, 0]})
    n, failures = 4000, 0
    for i in range(n):
        a = DOWN if env.state[0] == 1 else UP  # bounce between (1,0) and (2,0): every move is possible
        before = env.state[:2].copy()
        obs, *_ , info = env.step(a)
        failures += int(np.array_equal(obs[:2], before))
        assert info["move_failed"] == np.array_equal(obs[:2], before)
    sd = np.sqrt(fail_prob * (1 - fail_prob) / n)
    assert abs(failures / n - fail_prob) < 4 * sd


def test_pick_never_fails(keydoor):
    env = KeyDoorEnv(layout=keydoor, fail_prob=1.0)
    env.reset(seed=0, options={"state": [4, 0, 0, 0]})
    assert env.step(PICK)[0].tolist() == [4, 0, 1, 0]
    assert env.step(UP)[0][:2].tolist() == [4, 0]  # every move fails at fail_prob 1


def test_render_modes(keydoor):
    env = KeyDoorEnv(layout=keydoor, render_mode="ansi")
    env.reset(seed=0)
    assert env.render() == "@.#.G\n..#..\n..A..\n..#..\na.#..\n"
    env = KeyDoorEnv(layout=keydoor, render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (80, 80, 3) and img.dtype == np.uint8
    assert tuple(img[8, 8]) == (220, 40, 40)  # the agent's disc at the centre of cell (0, 0)


@pytest.mark.parametrize("px", [1, 5, 16])
def test_an_rgb_frame_shows_each_cells_colour_and_the_agent_as_a_disc(keydoor, px):
    from hnsdt.envs.render import CLASSES, COLOURS, cell_classes, render_rgb

    state = np.array([2, 3, 1, 1])  # on the floor right of the open door, the key held
    img = render_rgb(keydoor, state, px)
    cells = np.array([[COLOURS[CLASSES[c]] for c in row] for row in cell_classes(keydoor, state)], dtype=np.uint8)
    expected = cells.repeat(px, axis=0).repeat(px, axis=1)
    assert img.shape == expected.shape and img.dtype == np.uint8
    differs = (img != expected).any(-1)
    agent_cell = np.zeros_like(differs)
    agent_cell[2 * px:3 * px, 3 * px:4 * px] = True
    assert not (differs & ~agent_cell).any()  # every other pixel is its cell's colour
    assert (img[differs] == COLOURS["agent"]).all()  # ... and in the agent's cell, its colour or the cell's
    assert tuple(img[2 * px + px // 2, 3 * px + px // 2]) == COLOURS["agent"]
    if px > 1:  # a disc: the cell's own colour shows at its corners
        assert tuple(img[2 * px, 3 * px]) == COLOURS["floor"] and 0.3 < differs.sum() / px**2 < 0.5


@pytest.mark.parametrize("kwargs,match", [
    ({"fail_prob": 1.5}, "fail_prob"), ({"max_steps": 0}, "max_steps"), ({"render_mode": "human"}, "render_mode"),
])
def test_bad_arguments_fail_clearly(kwargs, match):
    with pytest.raises(ValueError, match=match):
        KeyDoorEnv(**kwargs)


def test_reset_state_is_validated(keydoor):
    env = KeyDoorEnv(layout=keydoor)
    with pytest.raises(ValueError, match="wall"):
        env.reset(options={"state": [0, 2, 0, 0]})
    with pytest.raises(ValueError, match="not a valid observation"):
        env.reset(options={"state": [9, 0, 0, 0]})
