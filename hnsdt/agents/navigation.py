"""Hand-written low-level controllers: shortest-path moves to a target cell, as lookup tables.

For every object cell (keys, doors, items, exit) and every combination of open doors we store the first move
of a shortest path from each cell, so a whole batch of agents picks its actions with one numpy index.
Ties go to the first of up, right, down, left. Paths respect the environment: a closed door cell can be the
target but never a step along the way.
"""

from __future__ import annotations

import numpy as np

from hnsdt.envs.keydoor import PICK
from hnsdt.envs.layout import MOVES, Cell, Layout

NO_MOVE = -1


class Navigator:
    def __init__(self, layout: Layout):
        self.layout = layout
        self.targets: list[Cell] = [*layout.keys.values(), *layout.doors.values(), *layout.items.values(),
                                    layout.goal]
        self.target_index = {cell: i for i, cell in enumerate(self.targets)}
        self.target_grid = np.zeros(layout.shape, dtype=np.int64)  # cell -> target index, for batches
        for cell, i in self.target_index.items():
            self.target_grid[cell] = i
        n_masks = 1 << len(layout.doors)
        h, w = layout.shape
        self.first_move = np.full((len(self.targets), n_masks, h, w), NO_MOVE, dtype=np.int64)
        self.distance = np.full((len(self.targets), n_masks, h, w), -1, dtype=np.int64)
        for t, target in enumerate(self.targets):
            for mask in range(n_masks):
                self._fill(t, target, mask)

    def door_mask(self, open_doors) -> int:
        return sum(1 << j for j, d in enumerate(self.layout.doors) if d in open_doors)

    def _fill(self, t: int, target: Cell, mask: int) -> None:
        lay = self.layout
        h, w = lay.shape
        closed = {cell for j, cell in enumerate(lay.doors.values()) if not mask >> j & 1}
        dist = self.distance[t, mask]
        dist[target] = 0
        frontier = [target]
        # Backwards breadth-first search: v -> u is a legal move unless v is a closed door (cannot be left).
        while frontier:
            nxt = []
            for u in frontier:
                for a, (dr, dc) in enumerate(MOVES):
                    v = (u[0] - dr, u[1] - dc)
                    if not (0 <= v[0] < h and 0 <= v[1] < w) or lay.walls[v] or v in closed or dist[v] >= 0:
                        continue
                    dist[v] = dist[u] + 1
                    nxt.append(v)
            frontier = nxt
        # First move: the first action (in MOVES order) that steps to a cell one closer.
        for r in range(h):
            for c in range(w):
                if dist[r, c] <= 0:
                    continue
                for a, (dr, dc) in enumerate(MOVES):
                    rr, cc = r + dr, c + dc
                    if 0 <= rr < h and 0 <= cc < w and dist[rr, cc] == dist[r, c] - 1 and not lay.walls[rr, cc]:
                        self.first_move[t, mask, r, c] = a
                        break

    def moves(self, target_idx: np.ndarray, masks: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """First moves for a batch; NO_MOVE where the agent is on the target or cannot reach it."""
        return self.first_move[target_idx, masks, cells[:, 0], cells[:, 1]]

    def on_shortest_path(self, target_idx: np.ndarray, masks: np.ndarray, cells: np.ndarray,
                         actions: np.ndarray) -> np.ndarray:
        """Whether each move brings its agent one step closer to the target (any shortest path's first move,
        not only the controller's tie-break); pick/open is never a move closer."""
        h, w = self.layout.shape
        step = np.array(MOVES + ((0, 0),))[actions]  # pick: (0, 0), never closer
        nxt = np.clip(cells + step, 0, [h - 1, w - 1])
        here = self.distance[target_idx, masks, cells[:, 0], cells[:, 1]]
        there = self.distance[target_idx, masks, nxt[:, 0], nxt[:, 1]]
        return (actions != PICK) & (here > 0) & (there == here - 1)

    def controller_actions(self, target_idx: np.ndarray, masks: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """The hand-written controller: walk the shortest path to the target, then pick/open on it.
        Recomputed from the current cell every step, so a failed move is simply retried."""
        moves = self.moves(target_idx, masks, cells)
        return np.where(moves >= 0, moves, PICK)


def step_towards(cells: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The one-cell controller of the paper's ``Move`` operators: the move onto a neighbouring target cell, and
    pick/open when the target is the agent's own cell."""
    delta = targets - cells
    actions = np.full(len(cells), PICK, dtype=np.int64)
    for a, (dr, dc) in enumerate(MOVES):
        actions[(delta[:, 0] == dr) & (delta[:, 1] == dc)] = a
    return actions
