"""N copies of a key–door world stepped at once with numpy, through the same rules as :class:`KeyDoorEnv`
(:mod:`hnsdt.envs.dynamics`).

Used by data collection and evaluation so that thousands of episodes are not bound by a Python loop per step.
Autoreset is disabled: a finished copy stays frozen (reward 0, its terminated/truncated flag repeated) until it
is reset with ``reset(options={"reset_mask": mask})``; ``done`` tells which copies have finished.

Randomness: one uniform draw per copy per step from a single generator. With ``num_envs=1`` and the same seed
this is exactly the stream :class:`KeyDoorEnv` draws, so the two produce identical trajectories. ``reset(seed=[s1,
s2, ...])`` instead gives each equal run of copies its own generator (:class:`Streams`): a batch of k cells draws,
copy for copy, what each cell's own env would (the evaluation steps its fail_probs' cells as one batch).
"""

from __future__ import annotations

from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from hnsdt.envs.dynamics import GOAL_REWARD, N_ACTIONS, STEP_REWARD, Rules
from hnsdt.envs.keydoor import check_env_params, observation_space_for
from hnsdt.envs.layout import Layout, equal_runs, layout_runs, load_layout


class Streams:
    """Independent generators side by side: the first ``n / len(seeds)`` copies draw from the first seed's
    generator, the next as many from the second's, and so on — each run of copies gets exactly the numbers a batch
    of its own would. Draws are for every copy at once (``random(n)``, ``integers(low, high, n)``), as a batched
    env or agent makes them."""

    def __init__(self, seeds: Sequence[int], n: int):
        self.generators = [seeding.np_random(int(s))[0] for s in seeds]
        self.n, self.runs = n, equal_runs(n, len(self.generators), "random streams")

    def _draw(self, size: int, draw) -> np.ndarray:
        if size != self.n:
            raise ValueError(f"random streams for {self.n} copies asked for {size} draws")
        return np.concatenate([draw(g, rows.stop - rows.start) for g, rows in zip(self.generators, self.runs)])

    def random(self, size: int) -> np.ndarray:
        return self._draw(size, lambda g, k: g.random(k))

    def integers(self, low: int, high: int, size: int) -> np.ndarray:
        return self._draw(size, lambda g, k: g.integers(low, high, k))


def generator(seed: int | Sequence[int] | None, n: int) -> np.random.Generator | Streams:
    """The random source of a batch of ``n`` copies: one generator from an int seed (or none), one per equal run
    of copies from a sequence of seeds (:class:`Streams`)."""
    if seed is None or np.ndim(seed) == 0:
        return seeding.np_random(seed)[0]
    return Streams(seed, n)


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

    def __init__(self, num_envs: int, layout: str | Layout | tuple[Layout, ...] = "keydoor_5x5",
                 fail_prob: float | Any = 0.0, max_steps: int = 100, **_ignored: Any):
        """``fail_prob`` is one probability for every copy, or one per copy (online learners train on a mix).
        ``layout``: one for every copy, or a tuple of layouts with the same flags, one per equal run of copies
        (:func:`hnsdt.envs.layout.layout_runs`: the unseen-layout evaluation steps a split's maps together)."""
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        per_copy = np.broadcast_to(np.asarray(fail_prob, dtype=np.float64), (int(num_envs),))
        for p in np.unique(per_copy):
            check_env_params(p, max_steps)
        self.layout = lay = load_layout(layout) if not isinstance(layout, tuple) else layout
        self.num_envs = int(num_envs)
        self.runs = [(Rules(one), rows) for one, rows in layout_runs(lay, self.num_envs)]
        if len({rules.layout.state_size for rules, _ in self.runs}) > 1:
            raise ValueError("the layouts of one batch must have the same keys, doors and items")
        self.fail_prob = float(per_copy[0]) if np.ndim(fail_prob) == 0 else per_copy.copy()
        shapes = np.array([rules.layout.shape for rules, _ in self.runs])
        self.single_observation_space = gym.spaces.MultiDiscrete(  # (several maps: rows and cols of the largest)
            list(shapes.max(axis=0)) + list(observation_space_for(self.runs[0][0].layout).nvec[2:]), dtype=np.int64)
        self.single_action_space = gym.spaces.Discrete(N_ACTIONS)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.np_random, _ = seeding.np_random(None)
        self.state = self._initial_states()
        self._start_clock(self.num_envs, max_steps)

    def _initial_states(self) -> np.ndarray:
        return np.concatenate([rules.initial_states(rows.stop - rows.start) for rules, rows in self.runs])

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all copies, or those in ``options["reset_mask"]``; ``options["states"]`` (one row per reset
        copy) starts them from given states instead of the layout's start. ``seed``: one generator, or one per
        equal run of copies (a sequence, :class:`Streams`)."""
        if seed is not None:
            self.np_random = generator(seed, self.num_envs)
        options = options or {}
        mask = np.ones(self.num_envs, bool) if options.get("reset_mask") is None else np.asarray(
            options["reset_mask"], bool)
        n = int(mask.sum())
        fresh = self._initial_states()[mask]
        if options.get("states") is not None:
            states = np.asarray(options["states"], dtype=np.int64).reshape(n, -1)
            nvec = self.single_observation_space.nvec
            if states.shape != fresh.shape or (states < 0).any() or (states >= nvec).any():
                raise ValueError("reset states do not match this layout's observation space")
            full = self.state.copy()
            full[mask] = states
            for rules, rows in self.runs:  # (several maps: each run within its own)
                (h, w), r, c = rules.layout.shape, full[rows, 0], full[rows, 1]
                if (((r >= h) | (c >= w)) & mask[rows]).any():
                    raise ValueError("reset states do not match this layout's observation space")
                if rules.layout.walls[np.minimum(r, h - 1), np.minimum(c, w - 1)][mask[rows]].any():
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
        fail = np.broadcast_to(self.fail_prob, (self.num_envs,))
        # each map's copies through its rules (in place: the runs are views of the state)
        success, move_failed = (np.concatenate(parts) for parts in zip(*(
            rules.step(s[rows], actions[rows], u[rows], fail[rows], live[rows]) for rules, rows in self.runs)))
        reward = self._tick(live, success)
        info = {"success": success, "move_failed": move_failed}
        return s.copy(), reward, self.terminated.copy(), self.truncated.copy(), info
