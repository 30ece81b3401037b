"""The rules of every key–door world, written once.

:class:`KeyDoorEnv` (one copy, gymnasium's ``Env``), :class:`KeyDoorVectorEnv` (N copies at once) and, through
the vector env, the exact optimum (:mod:`hnsdt.envs.oracle`) all step through :meth:`Rules.step`, so a change to the
rules cannot make them disagree.

One step of a copy, given one uniform draw ``u`` (drawn every step, move or not):

* a move (up, right, down, left) fails when ``u < fail_prob`` and the agent stays; walls and grid edges block
  it; a closed door cell can be entered but not left (the paper's stochastic blocking);
* pick/open never fails: it takes the key or item on the agent's cell, or opens the door on it when the agent
  holds that door's key; otherwise it does nothing;
* the episode succeeds on reaching the exit holding every item: −0.1 every step, +1 on success.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from hnsdt.envs.layout import MOVES, Layout


class Actions(IntEnum):
    up = 0
    right = 1
    down = 2
    left = 3
    pick = 4  # pick up the key or item here, or open the door here with its key


N_ACTIONS = len(Actions)
PICK = int(Actions.pick)
ACTION_NAMES = ("up", "right", "down", "left", "pick/open")
STEP_REWARD = -0.1
GOAL_REWARD = 1.0

_DELTAS = np.array(MOVES + ((0, 0),), dtype=np.int64)  # pick/open does not move


class Rules:
    """The transition of a layout, on a batch of states ``(row, col, key flags, door flags, item flags)``."""

    def __init__(self, layout: Layout):
        self.layout = lay = layout
        self.nd = len(lay.doors)
        h, w = lay.shape
        # Lookup grids: index of the key/door/item on each cell, -1 where none.
        self.key_at = np.full((h, w), -1, np.int64)
        self.door_at = np.full((h, w), -1, np.int64)
        self.item_at = np.full((h, w), -1, np.int64)
        for table, grid in ((lay.keys, self.key_at), (lay.doors, self.door_at), (lay.items, self.item_at)):
            for i, (r, c) in enumerate(table.values()):
                grid[r, c] = i
        self.door_key = np.array([lay.door_key_index(d) for d in lay.doors], dtype=np.int64)
        self.walls = lay.walls
        self.goal = np.array(lay.goal, dtype=np.int64)

    def initial_states(self, n: int) -> np.ndarray:
        states = np.zeros((n, self.layout.state_size), dtype=np.int64)
        states[:, :2] = self.layout.start
        return states

    def step(self, s: np.ndarray, actions: np.ndarray, u: np.ndarray, fail_prob, live: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
        """Apply ``actions`` to the ``live`` rows of ``s`` in place, with uniform draws ``u`` and failure
        probability ``fail_prob`` (one, or one per row); returns ``(success, move_failed)`` per row."""
        rows, cols = s[:, 0].copy(), s[:, 1].copy()  # positions before this step's moves
        lay = self.layout
        keys, doors, items = s[:, lay.key_flags], s[:, lay.door_flags], s[:, lay.item_flags]
        idx = np.arange(len(s))

        # Moves: fail with fail_prob, blocked by walls/edges, and impossible out of a closed door cell.
        door_here = self.door_at[rows, cols]
        trapped = (door_here >= 0) & (doors[idx, np.maximum(door_here, 0)] == 0) if self.nd else np.zeros_like(live)
        move_failed = (actions < PICK) & (u < fail_prob)
        target = s[:, :2] + _DELTAS[actions]
        h, w = self.walls.shape
        inside = (target[:, 0] >= 0) & (target[:, 0] < h) & (target[:, 1] >= 0) & (target[:, 1] < w)
        tr, tc = np.clip(target[:, 0], 0, h - 1), np.clip(target[:, 1], 0, w - 1)
        moves = live & (actions < PICK) & ~move_failed & ~trapped & inside & ~self.walls[tr, tc]
        s[moves, 0], s[moves, 1] = tr[moves], tc[moves]

        # Pick/open on the current cell (keys, items and doors never share a cell).
        pick = live & (actions == PICK)
        k = self.key_at[rows, cols]
        sel = pick & (k >= 0)
        keys[idx[sel], k[sel]] = 1
        i = self.item_at[rows, cols]
        sel = pick & (i >= 0)
        items[idx[sel], i[sel]] = 1
        if self.nd:
            sel = pick & (door_here >= 0)
            sel &= keys[idx, self.door_key[np.maximum(door_here, 0)]] == 1
            doors[idx[sel], door_here[sel]] = 1

        at_goal = (s[:, 0] == self.goal[0]) & (s[:, 1] == self.goal[1])
        return live & at_goal & items.all(axis=1), live & move_failed
