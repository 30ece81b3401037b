"""The exact optimum of a layout's MDP, by finite-horizon value iteration.

States are every (free cell, key/door/item flags) combination — Case 1 has 21 free cells × 4 = 84 states,
Case 2 65 × 64 = 4,160. Transitions follow the environment exactly: a move succeeds with probability
1 − fail_prob (walls, edges and closed doors that trap block it), pick/open is deterministic, and reaching the
exit with every item ends the episode. With the horizon ``max_steps`` we compute, from the start state:

* ``success``: the best achievable probability of succeeding within the horizon;
* ``return``: the best expected undiscounted return (−0.1 a step, +1 on success), and
* ``steps``: the expected steps to success of that return-optimal policy, among its successful episodes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hnsdt.envs.keydoor import GOAL_REWARD, N_ACTIONS, PICK, STEP_REWARD
from hnsdt.envs.layout import Layout
from hnsdt.envs.vector import KeyDoorVectorEnv


@dataclass(frozen=True)
class Optimum:
    success: float
    ret: float
    steps: float  # expected steps of the successful episodes under the return-optimal policy


class MDP:
    """All states of a layout, with ``succ[s, a]`` (next state when the move works), ``stay[s, a]`` (the
    probability-``fail_prob`` outcome: same state) and ``done[s]`` (the success states, absorbing)."""

    def __init__(self, layout: Layout):
        self.layout = layout
        n_flags = layout.n_flags
        flags = (np.arange(1 << n_flags)[:, None] >> np.arange(n_flags)[None, :]) & 1
        cells = np.array(layout.free_cells(), dtype=np.int64)
        self.states = np.concatenate([np.repeat(cells, len(flags), axis=0), np.tile(flags, (len(cells), 1))], axis=1)
        n = len(self.states)
        # Every (state, action) stepped once, with no failure, by the batched environment itself.
        env = KeyDoorVectorEnv(n * N_ACTIONS, layout, 0.0, 1)
        env.reset(options={"states": np.repeat(self.states, N_ACTIONS, axis=0)})
        nxt, *_ = env.step(np.tile(np.arange(N_ACTIONS), n))
        codes = self._codes(self.states)
        self._order = np.argsort(codes)
        self._sorted_codes = codes[self._order]
        self.succ = self.index(nxt).reshape(n, N_ACTIONS)
        items = self.states[:, layout.item_flags]
        at_goal = (self.states[:, 0] == layout.goal[0]) & (self.states[:, 1] == layout.goal[1])
        self.done = at_goal & items.all(axis=1)
        self.is_move = np.arange(N_ACTIONS) < PICK
        self.start = int(self.index(np.array([[*layout.start, *[0] * n_flags]]))[0])
        # The states from which working moves can reach success (a shortest path visits each state at most once).
        # The others' values never settle (each step costs the same forever), and every layout has some (flag
        # combinations no episode makes).
        self.alive = self._fewest_steps(len(self)) < len(self)

    def _codes(self, states: np.ndarray) -> np.ndarray:
        """A unique integer per state (row, col, flags) for fast lookup."""
        h, w = self.layout.shape
        flag_code = (states[:, 2:] << np.arange(states.shape[1] - 2)).sum(axis=1) if states.shape[1] > 2 else 0
        return (flag_code * h + states[:, 0]) * w + states[:, 1]

    def index(self, states: np.ndarray) -> np.ndarray:
        """Each of ``states``' row in :attr:`states`; a state the layout does not have is an error."""
        codes = self._codes(np.asarray(states, dtype=np.int64))
        at = np.minimum(np.searchsorted(self._sorted_codes, codes), len(self._sorted_codes) - 1)
        if not np.array_equal(self._sorted_codes[at], codes):
            raise ValueError("a state that is not one of the layout's (a wall cell, or flags it has not)")
        return self._order[at]

    def __len__(self) -> int:
        return len(self.states)

    def solve(self, fail_prob: float, horizon: int, gamma: float = 1.0) -> Optimum:
        """Backward induction over ``horizon`` steps from the start state; ``gamma`` < 1 discounts the return
        (``ret`` is then the optimal discounted value V*_γ; ``success`` and ``steps`` follow that policy)."""
        p = float(fail_prob)
        n = len(self)
        # Outcome probabilities per action: moves fail (stay) with p, pick/open never fails.
        p_stay = np.where(self.is_move, p, 0.0)[None, :]
        reached = self.done[self.succ]  # (n, A): the working outcome ends the episode successfully
        v_ret = np.zeros(n)  # value-to-go with k steps left; success states are absorbing with 0
        v_succ = np.zeros(n)
        # For the steps statistic: under the return-optimal policy, E[steps * 1{success}] and P(success).
        w_steps = np.zeros(n)
        w_succ = np.zeros(n)
        for _ in range(horizon):
            q_ret = STEP_REWARD + (1 - p_stay) * (GOAL_REWARD * reached
                                                  + np.where(reached, 0.0, gamma * v_ret[self.succ]))
            q_ret += p_stay * gamma * v_ret[:, None]
            q_succ = (1 - p_stay) * np.where(reached, 1.0, v_succ[self.succ]) + p_stay * v_succ[:, None]
            best = q_ret.argmax(axis=1)
            rows = np.arange(n)
            nxt, stay = self.succ[rows, best], p_stay[0, best]
            hit = reached[rows, best]
            # P(success) and E[steps·1{success}] of the return-optimal policy with k steps left.
            new_w_succ = (1 - stay) * np.where(hit, 1.0, w_succ[nxt]) + stay * w_succ
            new_w_steps = new_w_succ + (1 - stay) * np.where(hit, 0.0, w_steps[nxt]) + stay * w_steps
            new = [np.where(self.done, 0.0, x) for x in (q_ret.max(axis=1), q_succ.max(axis=1), new_w_succ,
                                                        new_w_steps)]
            # A longer horizon changes nothing once every value is stable to rounding: stop early. Nor once every
            # value of the states that can still succeed repeats to the bit: theirs depend on each other's and on
            # the dead states' returns, which only fall (an action into a dead state that is not a state's best
            # never becomes it; one that is would have moved that state's value). So the remaining steps would
            # repeat them exactly. The start must be one of them (a dead start's return falls step by step).
            old = (v_ret, v_succ, w_succ, w_steps)
            stable = (all(np.abs(a - b).max() < 1e-13 for a, b in zip(new, old))
                      or (self.alive[self.start] and all(np.array_equal(a[self.alive], b[self.alive])
                                                         for a, b in zip(new, old))))
            v_ret, v_succ, w_succ, w_steps = new
            if stable:
                break
        s = self.start
        steps = w_steps[s] / w_succ[s] if w_succ[s] > 0 else float("nan")
        return Optimum(success=float(v_succ[s]), ret=float(v_ret[s]), steps=float(steps))

    def fewest_steps(self, states: np.ndarray, horizon: int) -> np.ndarray:
        """Per state of ``states``: the fewest steps to success with no failures (``horizon`` where success takes
        longer or is impossible), the least episode length any policy can have from it at fail_prob 0."""
        return self._fewest_steps(horizon)[self.index(states)]

    def _fewest_steps(self, horizon: int) -> np.ndarray:
        """:meth:`fewest_steps` of every state."""
        dist = np.where(self.done, 0, horizon).astype(np.int64)
        for _ in range(horizon):  # Bellman-Ford on unit steps: stable after the longest shortest path
            new = np.where(self.done, 0, np.minimum(dist, 1 + dist[self.succ].min(axis=1)))
            if np.array_equal(new, dist):
                break
            dist = new
        return dist


@lru_cache(maxsize=16)
def mdp_for(layout: Layout) -> MDP:
    return MDP(layout)


def optimum(layout: Layout, fail_prob: float, horizon: int, gamma: float = 1.0) -> Optimum:
    return mdp_for(layout).solve(fail_prob, horizon, gamma)
