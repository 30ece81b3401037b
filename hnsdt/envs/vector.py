"""N copies of a key–door world stepped at once with numpy: the same dynamics as :class:`KeyDoorEnv`.

Used by data collection and evaluation so that thousands of episodes are not bound by a Python loop per step.
Autoreset is disabled: a finished copy stays frozen (reward 0, its terminated/truncated flag repeated) until it
is reset with ``reset(options={"reset_mask": mask})``; ``done`` tells which copies have finished.

Randomness: one uniform draw per copy per step from a single generator. With ``num_envs=1`` and the same seed
this is exactly the stream :class:`KeyDoorEnv` draws, so the two produce identical trajectories.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from hnsdt.envs.keydoor import GOAL_REWARD, N_ACTIONS, PICK, STEP_REWARD, check_env_params, observation_space_for
from hnsdt.envs.layout import MOVES, Layout, load_layout

_DELTAS = np.array(MOVES + ((0, 0),), dtype=np.int64)  # pick/open does not move


class KeyDoorVectorEnv(VectorEnv):
    metadata = {"autoreset_mode": AutoresetMode.DISABLED}

    def __init__(self, num_envs: int, layout: str | Layout = "keydoor_5x5", fail_prob: float | Any = 0.0,
                 max_steps: int = 100, **_ignored: Any):
        """``fail_prob`` is one probability for every copy, or one per copy (online learners train on a mix)."""
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        per_copy = np.broadcast_to(np.asarray(fail_prob, dtype=np.float64), (int(num_envs),))
        for p in np.unique(per_copy):
            check_env_params(p, max_steps)
        self.layout = lay = load_layout(layout)
        self.num_envs = int(num_envs)
        self.fail_prob = float(per_copy[0]) if np.ndim(fail_prob) == 0 else per_copy.copy()
        self.max_steps = int(max_steps)
        self.single_observation_space = observation_space_for(lay)
        self.single_action_space = gym.spaces.Discrete(N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.nk, self.nd, self.ni = len(lay.keys), len(lay.doors), len(lay.items)
        h, w = lay.shape
        # Lookup grids: index of the key/door/item on each cell, -1 where none.
        self._key_at = np.full((h, w), -1, np.int64)
        self._door_at = np.full((h, w), -1, np.int64)
        self._item_at = np.full((h, w), -1, np.int64)
        for table, grid in ((lay.keys, self._key_at), (lay.doors, self._door_at), (lay.items, self._item_at)):
            for i, (r, c) in enumerate(table.values()):
                grid[r, c] = i
        self._door_key = np.array([lay.door_key_index(d) for d in lay.doors], dtype=np.int64)
        self._walls = lay.walls
        self._goal = np.array(lay.goal, dtype=np.int64)
        self.np_random, _ = seeding.np_random(None)
        self.state = np.zeros((self.num_envs, 2 + lay.n_flags), dtype=np.int64)
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self.terminated = np.zeros(self.num_envs, dtype=bool)
        self.truncated = np.zeros(self.num_envs, dtype=bool)
        self.state[:, :2] = lay.start

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset all copies, or those in ``options["reset_mask"]``; ``options["states"]`` (one row per reset
        copy) starts them from given states instead of the layout's start."""
        if seed is not None:
            self.np_random, _ = seeding.np_random(seed)
        options = options or {}
        mask = np.ones(self.num_envs, bool) if options.get("reset_mask") is None else np.asarray(
            options["reset_mask"], bool)
        n = int(mask.sum())
        fresh = np.zeros((n, self.state.shape[1]), dtype=np.int64)
        fresh[:, :2] = self.layout.start
        if options.get("states") is not None:
            states = np.asarray(options["states"], dtype=np.int64).reshape(n, -1)
            nvec = self.single_observation_space.nvec
            if states.shape != fresh.shape or (states < 0).any() or (states >= nvec).any():
                raise ValueError("reset states do not match this layout's observation space")
            if self._walls[states[:, 0], states[:, 1]].any():
                raise ValueError("a reset state puts the agent in a wall")
            fresh = states
        self.state[mask] = fresh
        self.steps[mask] = 0
        self.terminated[mask] = False
        self.truncated[mask] = False
        return self.state.copy(), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        if ((actions < 0) | (actions >= N_ACTIONS)).any():
            raise ValueError(f"actions must be in 0..{N_ACTIONS - 1}")
        u = self.np_random.random(self.num_envs)
        live = ~self.done
        s = self.state
        rows, cols = s[:, 0].copy(), s[:, 1].copy()  # positions before this step's moves
        nk, nd = self.nk, self.nd
        keys, doors, items = s[:, 2 : 2 + nk], s[:, 2 + nk : 2 + nk + nd], s[:, 2 + nk + nd :]
        idx = np.arange(self.num_envs)

        # Moves: fail with fail_prob, blocked by walls/edges, and impossible out of a closed door cell.
        door_here = self._door_at[rows, cols]
        trapped = (door_here >= 0) & (doors[idx, np.maximum(door_here, 0)] == 0) if nd else np.zeros_like(live)
        move_failed = (actions < PICK) & (u < self.fail_prob)
        target = s[:, :2] + _DELTAS[actions]
        h, w = self._walls.shape
        inside = (target[:, 0] >= 0) & (target[:, 0] < h) & (target[:, 1] >= 0) & (target[:, 1] < w)
        tr, tc = np.clip(target[:, 0], 0, h - 1), np.clip(target[:, 1], 0, w - 1)
        moves = live & (actions < PICK) & ~move_failed & ~trapped & inside & ~self._walls[tr, tc]
        s[moves, 0], s[moves, 1] = tr[moves], tc[moves]

        # Pick/open on the current cell (keys, items and doors never share a cell).
        pick = live & (actions == PICK)
        k = self._key_at[rows, cols]
        sel = pick & (k >= 0)
        keys[idx[sel], k[sel]] = 1
        i = self._item_at[rows, cols]
        sel = pick & (i >= 0)
        items[idx[sel], i[sel]] = 1
        if nd:
            sel = pick & (door_here >= 0)
            sel &= keys[idx, self._door_key[np.maximum(door_here, 0)]] == 1
            doors[idx[sel], door_here[sel]] = 1

        self.steps[live] += 1
        at_goal = (s[:, 0] == self._goal[0]) & (s[:, 1] == self._goal[1])
        success = live & at_goal & items.all(axis=1)
        reward = np.where(live, STEP_REWARD + GOAL_REWARD * success, 0.0)
        self.terminated |= success
        self.truncated |= live & ~success & (self.steps >= self.max_steps)
        info = {"success": success, "move_failed": live & move_failed}
        return s.copy(), reward, self.terminated.copy(), self.truncated.copy(), info
