import gymnasium as gym
import numpy as np
import pytest

from hnsdt.envs import KeyDoorEnv, KeyDoorVectorEnv


def _single_trace(layout, fail_prob, seed, actions, max_steps, start=None):
    env = KeyDoorEnv(layout=layout, fail_prob=fail_prob, max_steps=max_steps)
    obs, _ = env.reset(seed=seed, options={"state": start} if start is not None else None)
    trace = [(obs, 0.0, False, False)]
    for a in actions:
        obs, r, term, trunc, _ = env.step(a)
        trace.append((obs, r, term, trunc))
        if term or trunc:
            break
    return trace


@pytest.mark.parametrize("name", ["keydoor", "multikeydoor"])
@pytest.mark.parametrize("fail_prob", [0.0, 0.25])
def test_one_copy_replays_the_single_env_exactly(request, name, fail_prob):
    layout = request.getfixturevalue(name)
    for seed in range(5):
        actions = np.random.default_rng(100 + seed).integers(0, 5, 300)
        # Start somewhere interesting too: a random free cell holding every key.
        start = None if seed % 2 == 0 else np.array([*layout.keys[layout.key_names[0]], *[1] * layout.n_flags])
        ref = _single_trace(layout, fail_prob, seed, actions, 120, start)
        venv = KeyDoorVectorEnv(1, layout, fail_prob, 120)
        obs, _ = venv.reset(seed=seed, options={"states": start[None]} if start is not None else None)
        assert np.array_equal(obs[0], ref[0][0])
        for (r_obs, r_rew, r_term, r_trunc), a in zip(ref[1:], actions):
            obs, rew, term, trunc, _ = venv.step([a])
            assert np.array_equal(obs[0], r_obs)
            assert rew[0] == pytest.approx(r_rew) and term[0] == r_term and trunc[0] == r_trunc


def test_many_copies_match_the_single_env_without_failures(multikeydoor):
    n, steps = 16, 250
    actions = np.random.default_rng(5).integers(0, 5, (steps, n))
    venv = KeyDoorVectorEnv(n, multikeydoor, 0.0, steps)
    venv.reset(seed=0)
    batch = [venv.step(actions[t]) for t in range(steps)]
    for i in range(n):
        ref = _single_trace(multikeydoor, 0.0, 0, actions[:, i], steps)
        for t, (r_obs, r_rew, r_term, r_trunc) in enumerate(ref[1:]):
            obs, rew, term, trunc, _ = batch[t]
            assert np.array_equal(obs[i], r_obs) and rew[i] == pytest.approx(r_rew)


def test_finished_copies_freeze_until_reset(keydoor):
    venv = KeyDoorVectorEnv(2, keydoor, 0.0, 3)
    venv.reset(seed=0)
    for _ in range(3):
        venv.step([2, 2])
    assert venv.truncated.all()
    obs, rew, _, trunc, _ = venv.step([1, 1])
    assert np.all(rew == 0) and trunc.all() and obs[:, 0].tolist() == [3, 3]
    obs, _ = venv.reset(options={"reset_mask": np.array([True, False])})
    assert obs[0].tolist() == [0, 0, 0, 0] and obs[1].tolist() == [3, 0, 0, 0]
    assert venv.done.tolist() == [False, True]


def test_failure_rate_of_batched_moves(keydoor):
    n = 2000
    venv = KeyDoorVectorEnv(n, keydoor, 0.2, 100)
    venv.reset(seed=1)
    _, _, _, _, info = venv.step(np.full(n, 2))  # everyone moves down from (0, 0): always possible
    rate = info["move_failed"].mean()
    assert abs(rate - 0.2) < 4 * np.sqrt(0.2 * 0.8 / n)


def test_make_vec_gives_the_batched_env():
    envs = gym.make_vec("hnsdt/KeyDoor-v0", num_envs=3, vectorization_mode="vector_entry_point", fail_prob=0.1)
    obs, _ = envs.reset(seed=0)
    assert isinstance(envs, KeyDoorVectorEnv) and obs.shape == (3, 4) and envs.fail_prob == 0.1


def test_random_streams_split_the_copies_evenly(keydoor):
    """reset(seed=[...]): one generator per equal run of copies (the evaluation's cells stepped together)."""
    venv = KeyDoorVectorEnv(6, keydoor, 0.3, 20)
    venv.reset(seed=[1, 2])
    both = np.array([venv.step(np.zeros(6, int))[0] for _ in range(10)])
    for i, seed in enumerate((1, 2)):
        alone = KeyDoorVectorEnv(3, keydoor, 0.3, 20)
        alone.reset(seed=seed)
        assert np.array_equal(both[:, 3 * i:3 * i + 3], [alone.step(np.zeros(3, int))[0] for _ in range(10)])
    with pytest.raises(ValueError, match="5 copies do not split evenly over 2 random streams"):
        KeyDoorVectorEnv(5, keydoor, 0.3, 20).reset(seed=[1, 2])


def test_a_batch_over_several_maps_steps_each_run_on_its_own(keydoor):
    """A tuple of layouts: one per equal run of copies, each stepped by its own map's rules."""
    from hnsdt.envs.generate import generate

    other = generate("keydoor", 3)
    both = KeyDoorVectorEnv(4, (keydoor, other), 0.0, 20)
    obs, _ = both.reset(seed=[1, 2])
    assert [tuple(o[:2]) for o in obs] == [keydoor.start] * 2 + [other.start] * 2
    with pytest.raises(ValueError, match="5 copies do not split evenly over 2 layouts"):
        KeyDoorVectorEnv(5, (keydoor, other), 0.0, 20)
    with pytest.raises(ValueError, match="the layouts of one batch must have the same keys, doors and items"):
        KeyDoorVectorEnv(2, (keydoor, generate("multikeydoor", 0)), 0.0, 20)
