"""N copies of a key–door world stepped at once with numpy, through the same rules as :class:`KeyDoorEnv`
(:mod:`hnsdt.envs.dynamics`).

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

from hnsdt.envs.dynamics import GOAL_REWARD, N_ACTIONS, STEP_REWARD, Rules
from hnsdt.envs.keydoor import check_env_params, observation_space_for
from hnsdt.envs.layout import Layout, load_layout


class EpisodeClock:
    """Each copy's step count and end flags, and the reward of a batched step: what every batched env keeps."""

    def _start_clock(self, num_envs: int, max_steps: int) -> None:
        self.max_steps = int(max_steps)
        self.steps = np.zeros(num_envs, dtype=np.int64)
        self.terminated = np.zeros(num_envs, dtype=bool)
        self.truncated = np.zeros(num_envs, dtype=bool)

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated

    def _restart(self, mask: np.ndarray) -> None:
        self.steps[mask] = 0
        self.terminated[mask] = False
        self.truncated[mask] = False

    def _tick(self, live: np.ndarray, success: np.ndarray) -> np.ndarray:
        """Count the step of the ``live`` copies, end those that succeeded or ran out of steps; the rewards."""
        self.steps[live] += 1
        self.terminated |= success
        self.truncated |= live & ~success & (self.steps >= self.max_steps)
        return np.where(live, STEP_REWARD + GOAL_REWARD * success, 0.0)


class KeyDoorVectorEnv(EpisodeClock, VectorEnv):
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
        self.single_observation_space = observation_space_for(lay)
        self.single_action_space = gym.spaces.Discrete(N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.rules = Rules(lay)
        self.np_random, _ = seeding.np_random(None)
        self.state = self.rules.initial_states(self.num_envs)
        self._start_clock(self.num_envs, max_steps)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset all copies, or those in ``options["reset_mask"]``; ``options["states"]`` (one row per reset
        copy) starts them from given states instead of the layout's start."""
        if seed is not None:
            self.np_random, _ = seeding.np_random(seed)
        options = options or {}
        mask = np.ones(self.num_envs, bool) if options.get("reset_mask") is None else np.asarray(
            options["reset_mask"], bool)
        n = int(mask.sum())
        fresh = self.rules.initial_states(n)
        if options.get("states") is not None:
            states = np.asarray(options["states"], dtype=np.int64).reshape(n, -1)
            nvec = self.single_observation_space.nvec
            if states.shape != fresh.shape or (states < 0).any() or (states >= nvec).any():
                raise ValueError("reset states do not match this layout's observation space")
            if self.layout.walls[states[:, 0], states[:, 1]].any():
                raise ValueError("a reset state puts the agent in a wall")
            fresh = states
        self.state[mask] = fresh
        self._restart(mask)
        return self.state.copy(), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        if ((actions < 0) | (actions >= N_ACTIONS)).any():
            raise ValueError(f"actions must be in 0..{N_ACTIONS - 1}")
        u = self.np_random.random(self.num_envs)
        live = ~self.done
        s = self.state
        success, move_failed = self.rules.step(s, actions, u, self.fail_prob, live)
        reward = self._tick(live, success)
        info = {"success": success, "move_failed": move_failed}
        return s.copy(), reward, self.terminated.copy(), self.truncated.copy(), info
