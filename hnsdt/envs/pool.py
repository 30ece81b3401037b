"""Copies of the world that each play one layout of a pool, for the online learners of the generalisation
experiment: whenever a copy resets it draws a new layout (seeded), so one policy learns over every training map.

The interface is :class:`~hnsdt.envs.vector.KeyDoorVectorEnv`'s (batched ``reset`` with ``reset_mask``,
``step``, no autoreset), through the same rules (:mod:`hnsdt.envs.dynamics`), but the observations are view
states (``row, col, view codes, flags``, :func:`hnsdt.envs.observation.view_states`): each copy's own map around
its agent, so that rows of different layouts mean the same thing. Every layout must have the same flags.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from gymnasium.utils import seeding

from hnsdt.envs.dynamics import Rules
from hnsdt.envs.keydoor import check_env_params
from hnsdt.envs.layout import Layout
from hnsdt.envs.observation import view_states
from hnsdt.envs.vector import EpisodeClock


class LayoutPoolVectorEnv(EpisodeClock):
    def __init__(self, layouts: Sequence[Layout], num_envs: int, fail_prob: float | Any, max_steps: int,
                 view_radius: int):
        if not layouts:
            raise ValueError("a layout pool needs at least one layout")
        flags = {lay.n_flags for lay in layouts}
        if len(flags) != 1:
            raise ValueError(f"the layouts of a pool must have the same flags, got counts {sorted(flags)}")
        self.layouts, self.rules = list(layouts), [Rules(lay) for lay in layouts]
        self.num_envs, self.view_radius = int(num_envs), int(view_radius)
        self.fail_prob = np.broadcast_to(np.asarray(fail_prob, dtype=np.float64), (self.num_envs,)).copy()
        for p in np.unique(self.fail_prob):
            check_env_params(p, max_steps)
        self.np_random, _ = seeding.np_random(None)
        self.which = np.zeros(self.num_envs, dtype=np.int64)  # each copy's layout
        self.state = np.zeros((self.num_envs, 2 + flags.pop()), dtype=np.int64)
        self._start_clock(self.num_envs, max_steps)

    def _by_layout(self, mask: np.ndarray):
        """``(layout index, boolean rows)`` for each layout that copies in ``mask`` play."""
        for w in np.unique(self.which[mask]):
            yield w, mask & (self.which == w)

    def observations(self) -> np.ndarray:
        cells = (2 * self.view_radius + 1) ** 2
        out = np.empty((self.num_envs, self.state.shape[1] + cells), dtype=np.int64)
        for w, rows in self._by_layout(np.ones(self.num_envs, bool)):
            out[rows] = view_states(self.layouts[w], self.state[rows], self.view_radius)
        return out

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset every copy, or those in ``options["reset_mask"]``, each on a layout drawn from the pool."""
        if seed is not None:
            self.np_random, _ = seeding.np_random(seed)
        mask = (options or {}).get("reset_mask")
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        for i in np.flatnonzero(mask):
            self.which[i] = self.np_random.integers(len(self.layouts))
            self.state[i] = self.rules[self.which[i]].initial_states(1)[0]
        self._restart(mask)
        return self.observations(), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.int64).reshape(self.num_envs)
        u = self.np_random.random(self.num_envs)
        live = ~self.done
        success = np.zeros(self.num_envs, dtype=bool)
        for w, rows in self._by_layout(live):  # the rules act row by row: one call per layout in play
            s = self.state[rows]
            success[rows], _ = self.rules[w].step(s, actions[rows], u[rows], self.fail_prob[rows], live[rows])
            self.state[rows] = s
        reward = self._tick(live, success)
        return self.observations(), reward, self.terminated.copy(), self.truncated.copy(), {"success": success}
