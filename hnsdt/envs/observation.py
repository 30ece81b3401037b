"""Observations that show the world: the grid around the agent as cell codes, the same on every layout.

The paper's state ``(row, col, flags)`` never shows a wall, a key or a door, so a learner trained on it can only
memorise one map. :func:`local_view` gives, for a batch of states, the ``(2r+1) x (2r+1)`` window of cell codes
centred on the agent (``radius`` r; cells beyond the grid read ``OUTSIDE``). Codes name objects by identity
(key ``a`` is the same code on every layout) and show the state: a held key or item reads as floor, an open
door as ``DOOR_OPEN + i``. :func:`full_view` is the whole grid with the agent's cell marked; :func:`whole_map`
the whole grid as a planner module reads it (:class:`hnsdt.models.plan.MapPlanner`), on a square of any side.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hnsdt.envs.layout import Layout, layout_runs

OUTSIDE, WALL, FLOOR, EXIT, AGENT = 0, 1, 2, 3, 4
MAX_OBJECTS = 10  # keys a..j, doors A..J, items 0..9
KEY = 5  # key a = 5, b = 6, ...
DOOR_CLOSED = KEY + MAX_OBJECTS
DOOR_OPEN = DOOR_CLOSED + MAX_OBJECTS
ITEM = DOOR_OPEN + MAX_OBJECTS
N_CODES = ITEM + MAX_OBJECTS


def _index(symbol: str) -> int:
    i = ord(symbol.lower()) - 97 if symbol.isalpha() else int(symbol)
    if not 0 <= i < MAX_OBJECTS:
        raise ValueError(f"object {symbol!r}: views name at most {MAX_OBJECTS} keys, doors and items")
    return i


@lru_cache(maxsize=256)
def static_codes(layout: Layout) -> np.ndarray:
    """(H, W) codes of the layout as it starts: walls, floor, exit, keys, closed doors, items. Computed once per
    layout (an agent asks every step) and read-only."""
    codes = np.where(layout.walls, WALL, FLOOR).astype(np.int64)
    codes[layout.goal] = EXIT
    for k, cell in layout.keys.items():
        codes[cell] = KEY + _index(k)
    for d, cell in layout.doors.items():
        codes[cell] = DOOR_CLOSED + _index(d)
    for i, cell in layout.items.items():
        codes[cell] = ITEM + _index(i)
    codes.setflags(write=False)
    return codes


def state_codes(layout: Layout, states: np.ndarray) -> np.ndarray:
    """(N, H, W) codes of the grid in each state: held keys and items gone, open doors open."""
    states = np.asarray(states, dtype=np.int64).reshape(-1, layout.state_size)
    grids = np.repeat(static_codes(layout)[None], len(states), axis=0)
    keys, doors, items = states[:, layout.key_flags], states[:, layout.door_flags], states[:, layout.item_flags]
    for j, cell in enumerate(layout.keys.values()):
        grids[keys[:, j] == 1, cell[0], cell[1]] = FLOOR
    for j, (d, cell) in enumerate(layout.doors.items()):
        grids[doors[:, j] == 1, cell[0], cell[1]] = DOOR_OPEN + _index(d)
    for j, cell in enumerate(layout.items.values()):
        grids[items[:, j] == 1, cell[0], cell[1]] = FLOOR
    return grids


def local_view(layout: Layout, states: np.ndarray, radius: int) -> np.ndarray:
    """(N, 2r+1, 2r+1) codes around the agent of each state (the agent's own cell at the centre shows what
    lies under it)."""
    if radius < 1:
        raise ValueError(f"view radius must be >= 1, got {radius}")
    states = np.asarray(states, dtype=np.int64).reshape(-1, layout.state_size)
    grids = state_codes(layout, states)
    n = len(grids)
    padded = np.full((n, grids.shape[1] + 2 * radius, grids.shape[2] + 2 * radius), OUTSIDE, dtype=np.int64)
    padded[:, radius:-radius, radius:-radius] = grids
    offsets = np.arange(2 * radius + 1)
    rows = states[:, 0, None] + offsets[None, :]  # padded coordinates: the window starts at (row, col)
    cols = states[:, 1, None] + offsets[None, :]
    return padded[np.arange(n)[:, None, None], rows[:, :, None], cols[:, None, :]]


def view_states(layout: Layout | tuple[Layout, ...], states: np.ndarray, radius: int, map_side: int = 0
                ) -> np.ndarray:
    """``row, col, view codes (row-major), flags`` per state: what a learner on unseen layouts reads
    (:mod:`hnsdt.models.view`), and what a dataset over many layouts stores beside ``observation.state``; with
    ``map_side`` > 0 the whole map's codes on a square of that side after them (:func:`whole_map`).
    ``layout``: a tuple gives each equal run of states its own (:func:`hnsdt.envs.layout.layout_runs`)."""
    if not isinstance(layout, Layout):
        states = np.asarray(states, dtype=np.int64)
        return np.concatenate([view_states(lay, states[rows], radius, map_side)
                               for lay, rows in layout_runs(layout, len(states))])
    states = np.asarray(states, dtype=np.int64).reshape(-1, layout.state_size)
    views = local_view(layout, states, radius).reshape(len(states), -1)
    grids = [whole_map(layout, states, map_side).reshape(len(states), -1)] if map_side else []
    return np.concatenate([states[:, :2], views, states[:, 2:], *grids], axis=1)


def full_view(layout: Layout, states: np.ndarray) -> np.ndarray:
    """(N, H, W) codes of the whole grid with the agent's cell marked ``AGENT``."""
    states = np.asarray(states, dtype=np.int64).reshape(-1, layout.state_size)
    grids = state_codes(layout, states)
    grids[np.arange(len(grids)), states[:, 0], states[:, 1]] = AGENT
    return grids


def whole_map(layout: Layout, states: np.ndarray, side: int | None = None) -> np.ndarray:
    """(N, side, side) codes of the whole grid in each state (:func:`state_codes`, no agent marked) at the top
    left of a square of ``side`` (default: the layout's larger dimension), the rest ``OUTSIDE``: one shape for
    every layout of a dataset, the agent's ``(row, col)`` its cell in it."""
    grids = state_codes(layout, states)
    side = max(layout.shape) if side is None else int(side)
    if side < max(grids.shape[1:]):
        raise ValueError(f"a map of side {side} cannot hold a {grids.shape[1]} x {grids.shape[2]} layout")
    out = np.full((len(grids), side, side), OUTSIDE, dtype=np.int64)
    out[:, :grids.shape[1], :grids.shape[2]] = grids
    return out
