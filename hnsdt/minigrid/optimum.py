"""The exact optimum of one MiniGrid world under the paper's action failures, by finite-horizon backward induction.

States are every :class:`WorldState` reachable from the world's start by :meth:`World.step` (agent cell and
direction, what it carries, each door's state, each object's cell: a dropped key can lie on any free cell);
success states end the episode. A movement action works with probability ``1 − fail_prob`` and otherwise
leaves the state unchanged; pickup, drop, toggle and done always work (:class:`ActionFailures`). The reward is
MiniGrid's own, ``1 − 0.9 t / max_steps`` for a success on step ``t``, 0 otherwise, so the value depends on the
step count and the induction runs over every one of the ``max_steps`` steps. From the start state it gives

* ``success``: the success probability of the return-optimal policy;
* ``ret``: the best expected MiniGrid reward;
* ``steps``: that policy's expected steps over its successful episodes.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from hnsdt.minigrid.world import MOVEMENT, N_ACTIONS, World, WorldState


@dataclass(frozen=True)
class Optimum:
    success: float
    ret: float
    steps: float


class WorldMDP:
    """Every reachable state of ``world`` (``states``, ``index``) with ``succ[s, a]`` (the state when action
    ``a`` works) and ``hit[s, a]`` (that step ends the episode with success). Success states are not expanded."""

    def __init__(self, world: World, limit: int = 5_000_000):
        self.world = world
        self.states: list[WorldState] = [world.start]
        self.index: dict[WorldState, int] = {world.start: 0}
        rows: dict[int, tuple[list[int], list[bool]]] = {}  # per expanded state: next states, successes
        queue = deque([0])
        while queue:
            i = queue.popleft()
            row = rows[i] = ([], [])
            for a in range(N_ACTIONS):
                nxt, success = world.step(self.states[i], a)
                j = self.index.get(nxt)
                if j is None:
                    j = self.index[nxt] = len(self.states)
                    self.states.append(nxt)
                    if len(self.states) > limit:
                        raise MemoryError(f"{world.name}: more than {limit:,} reachable states")
                    if not success:
                        queue.append(j)
                row[0].append(j)
                row[1].append(success)
        n = len(self.states)
        self.succ = np.zeros((n, N_ACTIONS), np.int64)
        self.hit = np.zeros((n, N_ACTIONS), bool)
        self.terminal = np.ones(n, bool)  # states never expanded: reached only by a successful step
        for i, (row_s, row_h) in rows.items():
            self.succ[i], self.hit[i], self.terminal[i] = row_s, row_h, False
        self.succ[self.terminal] = np.flatnonzero(self.terminal)[:, None]  # absorbing, never used

    def __len__(self) -> int:
        return len(self.states)

    def solve(self, fail_prob: float, keep_policy: bool = False, settle: bool = True
              ) -> tuple[Optimum, np.ndarray | None]:
        """Backward induction over the world's ``max_steps``; with ``keep_policy`` also the return-optimal action
        per (steps taken, state), a ``(max_steps, states)`` array (ties go to the lowest action). ``settle=False``
        runs every step instead of ending with the shift once the values settle (the tests compare the two)."""
        world, p = self.world, float(fail_prob)
        horizon = world.max_steps
        p_fail = np.where(np.isin(np.arange(N_ACTIONS), MOVEMENT), p, 0.0)[None, :]
        n = len(self)
        rows = np.arange(n)
        v = np.zeros(n)  # best expected reward from each state with t steps taken
        w = np.zeros(n)  # P(success) of that policy
        e = np.zeros(n)  # E[steps-to-come · 1{success}] of that policy
        policy = np.zeros((horizon, n), np.int8) if keep_policy else None
        slope = 0.9 / horizon  # what one more step costs a success
        prev_best = None
        for t in range(horizon - 1, -1, -1):
            r = world.reward(t + 1)  # a success on this step
            q = (1 - p_fail) * np.where(self.hit, r, v[self.succ]) + p_fail * v[:, None]
            best = q.argmax(axis=1)
            nxt, fail, hit = self.succ[rows, best], p_fail[0, best], self.hit[rows, best]
            new_w = (1 - fail) * np.where(hit, 1.0, w[nxt]) + fail * w
            new_e = new_w + (1 - fail) * np.where(hit, 0.0, e[nxt]) + fail * e
            new_v, new_w, new_e = (np.where(self.terminal, 0.0, x) for x in (q.max(axis=1), new_w, new_e))
            # Once the policy repeats and success and steps-to-come are stable to rounding, one step earlier
            # only adds what a step costs: V_t = w - slope (t w + e). The rest of the induction is that shift.
            settled = (settle and prev_best is not None and np.array_equal(best, prev_best)
                       and np.abs(new_w - w).max() < 1e-13 and np.abs(new_e - e).max() < 1e-11
                       and np.abs(new_v - v - slope * new_w).max() < 1e-13)
            v, w, e, prev_best = new_v, new_w, new_e, best
            if policy is not None:
                policy[t] = best
            if settled:
                v = v + slope * t * w
                if policy is not None:
                    policy[:t] = best
                break
        steps = e[0] / w[0] if w[0] > 0 else float("nan")
        return Optimum(success=float(w[0]), ret=float(v[0]), steps=float(steps)), policy
