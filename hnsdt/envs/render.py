"""Text and image renderings of a key–door state, shared by the environments, the dataset tools and the logs."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hnsdt.envs.layout import Layout

CELL_PX = 16
COLOURS = {
    "floor": (235, 235, 235),
    "wall": (60, 60, 60),
    "goal": (80, 190, 80),
    "key": (240, 200, 40),
    "door_closed": (150, 90, 40),
    "door_open": (215, 185, 150),
    "item": (70, 130, 230),
    "agent": (220, 40, 40),
}


def split_state(layout: Layout, state: np.ndarray) -> tuple[tuple[int, int], set[str], set[str], set[str]]:
    """Observation vector -> (cell, keys held, doors open, items held)."""
    state = np.asarray(state)
    keys = {k for k, f in zip(layout.keys, state[layout.key_flags]) if f}
    doors = {d for d, f in zip(layout.doors, state[layout.door_flags]) if f}
    items = {i for i, f in zip(layout.items, state[layout.item_flags]) if f}
    return (int(state[0]), int(state[1])), keys, doors, items


def symbol_grid(layout: Layout, state: np.ndarray) -> list[list[str]]:
    """Characters of the current grid: picked keys/items vanish, open doors show lower-case, agent is '@'."""
    cell, keys, doors, items = split_state(layout, state)
    grid = [["#" if w else "." for w in row] for row in layout.walls]
    grid[layout.goal[0]][layout.goal[1]] = "G"
    for k, (r, c) in layout.keys.items():
        if k not in keys:
            grid[r][c] = k
    for d, (r, c) in layout.doors.items():
        grid[r][c] = "/" if d in doors else d
    for i, (r, c) in layout.items.items():
        if i not in items:
            grid[r][c] = i
    grid[cell[0]][cell[1]] = "@"
    return grid


def render_ansi(layout: Layout, state: np.ndarray) -> str:
    return "\n".join("".join(row) for row in symbol_grid(layout, state)) + "\n"


# class id (0 = nothing, as rerun's segmentation images expect) -> what a cell shows; the agent is drawn on top
CLASSES = {i: name for i, name in enumerate(COLOURS, start=1)}
CLASS_ID = {name: i for i, name in CLASSES.items()}
_PALETTE = np.array([(0, 0, 0), *COLOURS.values()], dtype=np.uint8)  # class id -> colour


def cell_classes(layout: Layout, state: np.ndarray, cell_px: int = 1) -> np.ndarray:
    """(H*px, W*px) class ids of the world's cells in ``state``: walls, keys and items not yet picked up, doors
    (closed or open), the goal; the agent is not among them (it stands on one of these cells)."""
    _, keys, doors, items = split_state(layout, state)
    ids = np.where(layout.walls, CLASS_ID["wall"], CLASS_ID["floor"]).astype(np.uint8)
    objects = [(layout.goal, "goal")]
    objects += [(rc, "key") for k, rc in layout.keys.items() if k not in keys]
    objects += [(rc, "door_open" if d in doors else "door_closed") for d, rc in layout.doors.items()]
    objects += [(rc, "item") for i, rc in layout.items.items() if i not in items]
    for rc, name in objects:
        ids[rc] = CLASS_ID[name]
    return np.repeat(np.repeat(ids, cell_px, axis=0), cell_px, axis=1)


def render_rgb(layout: Layout, state: np.ndarray, cell_px: int = CELL_PX) -> np.ndarray:
    """An (H*px, W*px, 3) uint8 image: the cells in their colours and the agent as a disc."""
    # colours looked up per cell, then blown up (per pixel, the lookup was most of a recording's time)
    big = np.repeat(np.repeat(_PALETTE[cell_classes(layout, state)], cell_px, axis=0), cell_px, axis=1)
    # The agent is a filled disc so the cell underneath (key, door, goal) stays visible at its corners.
    r0, c0 = int(state[0]) * cell_px, int(state[1]) * cell_px
    big[r0 : r0 + cell_px, c0 : c0 + cell_px][_disc(cell_px)] = COLOURS["agent"]
    return big


@lru_cache(maxsize=8)
def _disc(cell_px: int) -> np.ndarray:
    """The agent's pixels in its (px, px) cell."""
    yy, xx = np.mgrid[0:cell_px, 0:cell_px]
    disc = (yy - cell_px / 2 + 0.5) ** 2 + (xx - cell_px / 2 + 0.5) ** 2 <= (cell_px * 0.35) ** 2
    disc.flags.writeable = False
    return disc
