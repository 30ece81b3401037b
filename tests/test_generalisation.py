"""Unseen layouts: the generator, the grid observation and MiniGrid's DoorKey worlds as our layouts."""

from __future__ import annotations

import numpy as np
import pytest

from hnsdt.envs import KeyDoorVectorEnv, LayoutError, load_layout
from hnsdt.envs.generate import FAMILIES, FamilySizes, check_usable, generate, write_layout
from hnsdt.envs.observation import (DOOR_CLOSED, DOOR_OPEN, EXIT, FLOOR, ITEM, KEY, OUTSIDE, WALL, full_view,
                                    local_view)


@pytest.mark.parametrize("family", FAMILIES)
def test_same_family_and_seed_same_layout_and_seeds_differ(family):
    assert generate(family, 3).text == generate(family, 3).text
    texts = {generate(family, s).text for s in range(40)}
    assert len(texts) == 40  # 40 seeds, 40 different worlds


@pytest.mark.parametrize("family, max_steps", [("keydoor", 100), ("multikeydoor", 250)])
def test_every_generated_layout_is_solvable_by_the_planner_and_the_optimum(family, max_steps):
    for seed in range(25):
        layout = generate(family, seed)
        check_usable(layout, max_steps, fail_prob=0.3)  # raises when not
        assert load_layout(layout.text).text == layout.text  # and passes the layout-file validation


def test_the_families_have_the_papers_structure():
    for seed in range(25):
        one = generate("keydoor", seed)
        assert (list(one.keys), list(one.doors), list(one.items)) == (["a"], ["A"], [])
        two = generate("multikeydoor", seed)
        assert (list(two.keys), list(two.doors), list(two.items)) == (["a", "b"], ["A", "B"], ["1", "2"])
        # key b and item 1 lie behind door A, item 2 and the exit behind door B: none reachable without keys
        from hnsdt.envs.layout import reachable_cells

        closed = reachable_cells(two, two.start, set())
        assert two.keys["a"] in closed and two.keys["b"] not in closed and two.items["1"] not in closed
        after_a = reachable_cells(two, two.start, {"A"})
        assert two.keys["b"] in after_a and two.items["2"] not in after_a and two.goal not in after_a


def test_impossible_sizes_stop_with_one_line():
    with pytest.raises(LayoutError, match="at least 8"):
        generate("multikeydoor", 0, FamilySizes(rows=(5, 6), cols=(4, 6)))
    with pytest.raises(LayoutError, match="unknown layout family"):
        generate("maze", 0)


def test_a_generated_layout_written_out_loads_back(tmp_path):
    layout = generate("multikeydoor", 5)
    path = write_layout(layout, tmp_path / "gen.txt")
    assert load_layout(str(path)).text == layout.text


HAND_MADE = """\
@.#.G
..#..
a.A.1
"""


def test_the_local_view_shows_walls_objects_and_their_state():
    layout = load_layout(HAND_MADE)
    #   state: row, col, key a, door A, item 1
    start = np.array([0, 0, 0, 0, 0])
    view = local_view(layout, start, radius=1)[0]
    assert view.tolist() == [[OUTSIDE, OUTSIDE, OUTSIDE],
                             [OUTSIDE, FLOOR, FLOOR],   # the agent's own cell (the start is floor), then (0, 1)
                             [OUTSIDE, FLOOR, FLOOR]]
    at_door = np.array([2, 1, 0, 0, 0])
    view = local_view(layout, at_door, radius=1)[0]
    assert view.tolist() == [[FLOOR, FLOOR, WALL], [KEY + 0, FLOOR, DOOR_CLOSED + 0], [OUTSIDE] * 3]
    opened = np.array([2, 1, 1, 1, 0])  # key a held (gone from the floor), door A open
    view = local_view(layout, opened, radius=1)[0]
    assert view.tolist() == [[FLOOR, FLOOR, WALL], [FLOOR, FLOOR, DOOR_OPEN + 0], [OUTSIDE] * 3]
    whole = full_view(layout, np.array([1, 3, 1, 1, 0]))[0]
    assert whole[0, 4] == EXIT and whole[2, 4] == ITEM + 1 and whole[1, 3] == 4  # AGENT


def test_the_view_follows_the_vector_envs_states():
    layout = generate("multikeydoor", 2)
    env = KeyDoorVectorEnv(64, layout, 0.1, 50)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(60):
        obs, *_ = env.step(rng.integers(0, 5, 64))
        view = local_view(layout, obs, radius=2)
        assert view.shape == (64, 5, 5)
        # the centre is never a wall, and a held key never shows on the grid
        assert (view[:, 2, 2] != WALL).all()
        held = obs[:, 2] == 1
        assert not (full_view(layout, obs[held]) == KEY + 0).any()
        on_key = (obs[:, 0] == layout.keys["a"][0]) & (obs[:, 1] == layout.keys["a"][1])  # AGENT covers it
        assert (full_view(layout, obs[~held]) == KEY + 0).sum() == (~held & ~on_key).sum()
    assert held.any()  # (the walk does pick key a up)


def test_minigrid_doorkey_grids_convert_cell_by_cell():
    from hnsdt.envs.minigrid_adapter import SYMBOLS, from_minigrid, minigrid_cells

    for env_id, seed in [("MiniGrid-DoorKey-8x8-v0", 0), ("MiniGrid-DoorKey-8x8-v0", 7),
                         ("MiniGrid-DoorKey-16x16-v0", 3)]:
        cells = minigrid_cells(env_id, seed)
        layout = from_minigrid(env_id, seed)
        rows = layout.text.splitlines()
        assert len(rows) == len(cells) and all(len(r) == len(c) for r, c in zip(rows, cells))
        for r, row in enumerate(cells):
            for c, kind in enumerate(row):
                assert rows[r][c] == SYMBOLS[kind], (env_id, seed, r, c, kind)
        assert sum(row.count("door_locked") for row in cells) == 1 and layout.doors and layout.keys
        check_usable(layout, 250, 0.3)


@pytest.mark.parametrize("env_id, family", [("hnsdt/KeyDoor-v0", "keydoor"), ("hnsdt/MultiKeyDoor-v0", "multikeydoor")])
def test_the_gymnasium_envs_expose_the_view_on_any_layout(env_id, family):
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    layout = generate(family, 11)
    env = gym.make(env_id, layout=layout, view_radius=2, fail_prob=0.2)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs) and obs["view"].shape == (5, 5)
    for a in [1, 2, 4, 3, 0, 4]:
        obs, *_ = env.step(a)
        assert (obs["view"] == local_view(layout, obs["state"], 2)[0]).all()
    plain = gym.make(env_id, layout=layout)  # the default: the paper's state alone
    assert isinstance(plain.reset(seed=1)[0], np.ndarray)
    assert plain.observation_space.shape == (2 + layout.n_flags,)


def test_the_view_dt_reads_nothing_tied_to_one_map():
    """Two windows that differ only by where on the map they are (same views, flags, actions, and a target at
    the same offset from the agent) get the same action logits: the model cannot memorise absolute cells."""
    import torch

    from hnsdt.models.view_dt import ViewDecisionTransformer, view_config

    torch.manual_seed(0)
    cfg = view_config("subgoal", n_flags=2, view_radius=1, max_offset=9, context=3, n_layers=1, n_heads=2,
                      d_model=16, max_timestep=50)
    model = ViewDecisionTransformer(cfg).eval()
    rng = np.random.default_rng(0)
    codes = rng.integers(0, 8, (1, 3, 9))
    flags = rng.integers(0, 2, (1, 3, 2))
    pos_a = np.array([[[1, 1], [1, 2], [2, 2]]])
    pos_b = pos_a + [3, 4]
    window = {"actions": torch.tensor([[1, 2, 0]]), "timesteps": torch.tensor([[0, 1, 2]]),
              "pad": torch.zeros(1, 3, dtype=torch.bool), "subgoal_ids": torch.tensor([7])}
    out = []
    for pos in (pos_a, pos_b):
        states = torch.from_numpy(np.concatenate([pos, codes, flags], axis=-1))
        target = torch.from_numpy(pos[:, -1] + [2, -1])
        with torch.no_grad():
            out.append(model(states, **window, subgoal_targets=target))
    assert torch.allclose(out[0], out[1])
    with torch.no_grad():  # ... while another offset is another token
        moved = model(torch.from_numpy(np.concatenate([pos_a, codes, flags], axis=-1)), **window,
                      subgoal_targets=torch.from_numpy(pos_a[:, -1] + [0, 3]))
    assert not torch.allclose(out[0], moved)


def test_hnsdt_with_the_view_dt_trains_on_some_layouts_and_runs_on_others():
    """Smoke run of the generalisation path: frames of view states from two generated layouts, a few gradient
    steps, then HNSDT with that DT on a held-out layout of another size and on a MiniGrid grid."""
    from hnsdt.agents.dt_agents import HNSDTAgent
    from hnsdt.agents.executor import ExecutorConfig
    from hnsdt.agents.rollout import rollout
    from hnsdt.data.collect import Behaviour, CollectConfig, collect_episodes
    from hnsdt.data.windows import frames_from_arrays
    from hnsdt.envs.minigrid_adapter import from_minigrid
    from hnsdt.models.train import TrainConfig, train_dt
    from hnsdt.models.view_dt import ViewDecisionTransformer, view_config, view_states

    parts, n = [], 0
    for i, layout in enumerate([generate("keydoor", 0), generate("keydoor", 1)]):
        cfg = CollectConfig(env_id="gen", layout=layout, max_steps=50, fail_probs=[0.1],
                            behaviours=[Behaviour("noisy_planner", 4, "random", 0.1)], seed=i)
        for rec in collect_episodes(cfg, progress=False):
            t = len(rec["actions"])
            parts.append((view_states(layout, rec["states"][:t], 2), rec["actions"], rec["rewards"],
                          rec["subgoal_ids"], rec["subgoal_targets"], np.full(t, n), np.arange(t)))
            n += 1
    frames = frames_from_arrays(*(np.concatenate(col) for col in zip(*parts)))
    cfg = view_config("subgoal", 2, 2, 15, context=4, n_layers=1, n_heads=2, d_model=16, max_timestep=50)
    model, curve = train_dt(frames, cfg, TrainConfig(epochs=1, max_steps=3, batch_size=32), progress=False,
                            network=ViewDecisionTransformer)
    assert curve[-1]["step"] == 3
    for layout in (generate("keydoor", 500), from_minigrid("MiniGrid-DoorKey-8x8-v0", 5)):
        episodes = rollout(KeyDoorVectorEnv(3, layout, 0.1, 30), HNSDTAgent(layout, model, ExecutorConfig()), seed=0)
        assert len(episodes) == 3 and all(1 <= ep.length <= 30 for ep in episodes)
