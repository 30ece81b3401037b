"""Procedurally generated key–door worlds: seeded families of layouts, for training and held-out evaluation.

Families (sizes drawn per seed inside the family's ranges; every placement uniform over the free cells that
keep the family's structure):

* ``keydoor`` — Case 1's structure: a wall splits the grid into two rooms, one locked door ``A`` in it; the
  start and the key ``a`` lie in the first room, the exit ``G`` in the second. The wall runs vertically or,
  for half the seeds, horizontally.
* ``keydoor_obstacles`` — ``keydoor`` on larger grids with 2–4 straight wall segments (2–5 cells) inside the
  rooms, so that reaching the key, the door or the exit often means walking round a wall (a training family
  for maps of other shapes; the hand-drawn maps were drawn before it was made).
* ``keydoor_maze`` — ``keydoor`` whose two rooms are braided mazes (a random depth-first maze on every other
  cell, then a third of its inner walls removed so that there are loops), the door between two corridors: the
  random-maze training maps of value-iteration and gated path-planning networks, with Case 1's key and door.
* ``keydoor_perfect`` — ``keydoor_maze`` without the braiding: each room a perfect maze (one way between any
  two cells, as the depth-first mazes VIN's and GPPN's planners train on), so that a way often starts by walking
  away from its target, for long.
* ``keydoor_mixed`` — both single-door shapes in every split: ``keydoor`` at even seeds, ``keydoor_maze`` at
  odd ones (each layout is that family's layout of the same seed, and keeps its name).
* ``keydoor_mazes`` — both maze shapes in every split: ``keydoor_maze`` at even seeds, ``keydoor_perfect`` at
  odd ones.
* ``multikeydoor`` — Case 2's structure: two parallel walls make three rooms in a chain, doors ``A`` and ``B``
  in them; the start and key ``a`` in the first room, key ``b`` and item ``1`` behind door ``A``, item ``2``
  and the exit behind door ``B`` (the keys of later doors sit behind earlier doors).

The same ``(family, seed, sizes)`` always gives the same layout (:func:`generate`). Every generated layout goes
through :func:`hnsdt.envs.layout.parse_layout` (the same validation and solvability check as a layout file),
and :func:`check_usable` asks more before one is used: the planner finds a plan and the exact optimum succeeds
within the step limit. :func:`write_layout` writes any layout as a layout file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hnsdt.envs.layout import Layout, LayoutError, parse_layout

FAMILIES = ("keydoor", "multikeydoor", "keydoor_obstacles", "keydoor_maze", "keydoor_mixed", "keydoor_perfect",
            "keydoor_mazes")  # (append only: a family's index seeds its layouts)
MIXED = {"keydoor_mixed": ("keydoor", "keydoor_maze"),  # a family drawn from others, by seed (seed % len)
         "keydoor_mazes": ("keydoor_maze", "keydoor_perfect")}


@dataclass(frozen=True)
class FamilySizes:
    """Grid size ranges of a family (inclusive), rows x columns before the optional transpose."""

    rows: tuple[int, int]
    cols: tuple[int, int]


DEFAULT_SIZES = {"keydoor": FamilySizes(rows=(5, 7), cols=(5, 8)),
                 "multikeydoor": FamilySizes(rows=(6, 9), cols=(9, 12)),
                 "keydoor_obstacles": FamilySizes(rows=(7, 11), cols=(7, 12)),
                 "keydoor_maze": FamilySizes(rows=(7, 11), cols=(7, 13)),
                 "keydoor_perfect": FamilySizes(rows=(7, 11), cols=(7, 13))}
_MIN = {"keydoor": (3, 5), "multikeydoor": (4, 8), "keydoor_obstacles": (6, 7),  # the smallest grid that can
        "keydoor_maze": (5, 7), "keydoor_perfect": (5, 7)}                       # hold the family's structure


def check_sizes(family: str, sizes: FamilySizes) -> None:
    """One clear line when a family's size ranges cannot yield a layout."""
    if family not in FAMILIES:
        raise LayoutError(f"unknown layout family {family!r}; expected one of {', '.join(FAMILIES)}")
    min_rows, min_cols = _MIN[family]
    for name, (lo, hi), least in (("rows", sizes.rows, min_rows), ("cols", sizes.cols, min_cols)):
        if lo > hi:
            raise LayoutError(f"family {family}: {name} range {lo}..{hi} is empty")
        if lo < least:
            raise LayoutError(f"family {family}: {name} must be at least {least} to hold a {family} world "
                              f"(walls, doors, rooms); got {lo}..{hi}")
        if hi > 26:
            raise LayoutError(f"family {family}: {name} above 26 is not supported; got {lo}..{hi}")


def generate(family: str, seed: int, sizes: FamilySizes | None = None) -> Layout:
    """The layout of ``family`` for ``seed``; named ``<family>-<seed>`` (a mixed family's: its part's name)."""
    if family in MIXED:
        if sizes is not None:
            raise LayoutError(f"family {family} takes its parts' sizes; got {sizes}")
        parts = MIXED[family]
        return generate(parts[int(seed) % len(parts)], seed)
    sizes = sizes or DEFAULT_SIZES.get(family)
    check_sizes(family, sizes)  # (an unknown family stops here first)
    rng = np.random.default_rng([FAMILIES.index(family), int(seed), 7919])
    while True:
        try:
            return parse_layout(_draw(family, rng, sizes), name=f"{family}-{seed}")
        except LayoutError:  # obstacles that cut a room apart: draw again (only keydoor_obstacles gets here)
            if family != "keydoor_obstacles":
                raise


def _draw(family: str, rng: np.random.Generator, sizes: FamilySizes) -> str:
    if family in ("keydoor_maze", "keydoor_perfect"):
        return _draw_maze(rng, sizes, braid=family == "keydoor_maze")
    h = int(rng.integers(sizes.rows[0], sizes.rows[1] + 1))
    w = int(rng.integers(sizes.cols[0], sizes.cols[1] + 1))
    grid = np.full((h, w), ".", dtype="<U1")
    walls = 2 if family == "multikeydoor" else 1
    # wall columns: each room at least one column wide (two for the first room of a chain, which holds two
    # objects besides the start); drawn in order left to right
    cols = _wall_columns(rng, w, walls)
    rooms = [range(0, cols[0])] + [range(a + 1, b) for a, b in zip(cols, cols[1:])] + [range(cols[-1] + 1, w)]
    for j, c in enumerate(cols):
        grid[:, c] = "#"
        grid[int(rng.integers(0, h)), c] = "AB"[j]
    if family == "keydoor_obstacles":
        _add_obstacles(rng, grid, cols)
    cells = [[(r, c) for r in range(h) for c in room if grid[r, c] == "."] for room in rooms]
    if family != "multikeydoor":
        placements = [("@", 0), ("a", 0), ("G", 1)]
    else:
        placements = [("@", 0), ("a", 0), ("b", 1), ("1", 1), ("2", 2), ("G", 2)]
    used: set[tuple[int, int]] = set()
    for symbol, room in placements:
        free = [cell for cell in cells[room] if cell not in used]
        r, c = free[int(rng.integers(0, len(free)))]
        grid[r, c] = symbol
        used.add((r, c))
    if rng.random() < 0.5:  # walls horizontal instead
        grid = grid.T
    return "\n".join("".join(row) for row in grid) + "\n"


def _draw_maze(rng: np.random.Generator, sizes: FamilySizes, braid: bool = True) -> str:
    """Two maze rooms (odd sizes: corridors on even rows / columns of each room), braided or perfect, the wall
    between them with door ``A`` at a corridor row; start and key in the first room, the exit in the second."""
    h = int(rng.integers(sizes.rows[0], sizes.rows[1] + 1)) | 1
    w = int(rng.integers(sizes.cols[0], sizes.cols[1] + 1))
    w += (w % 2 == 0)  # two odd-width rooms and the wall: an odd width
    c = 2 * int(rng.integers(1, (w - 1) // 2)) - 1  # the wall's column: an odd one, rooms at least 1 wide
    grid = np.full((h, w), "#", dtype="<U1")
    rooms = [range(0, c), range(c + 1, w)]
    for room in rooms:
        nodes = [(r, col) for r in range(0, h, 2) for col in range(room.start, room.stop, 2)]
        seen, stack = {nodes[int(rng.integers(len(nodes)))]}, []
        stack.append(next(iter(seen)))
        while stack:  # depth-first: carve to an unvisited neighbour two cells away, or backtrack
            r, col = stack[-1]
            grid[r, col] = "."
            nxt = [(r + dr, col + dc) for dr, dc in ((-2, 0), (2, 0), (0, -2), (0, 2))
                   if 0 <= r + dr < h and room.start <= col + dc < room.stop and (r + dr, col + dc) not in seen]
            if not nxt:
                stack.pop()
                continue
            nr, nc = nxt[int(rng.integers(len(nxt)))]
            grid[(r + nr) // 2, (col + nc) // 2] = "."
            seen.add((nr, nc))
            stack.append((nr, nc))
        inner = [(r, col) for r in range(h) for col in room if (r + col - room.start) % 2 == 1]
        for r, col in inner if braid else ():  # braid: open a third of the walls between two corridor cells
            if grid[r, col] == "#" and rng.random() < 1 / 3:
                grid[r, col] = "."
    grid[2 * int(rng.integers(0, (h + 1) // 2)), c] = "A"
    used: set[tuple[int, int]] = set()
    for symbol, room in (("@", 0), ("a", 0), ("G", 1)):
        free = [(r, col) for r in range(h) for col in rooms[room] if grid[r, col] == "." and (r, col) not in used]
        r, col = free[int(rng.integers(0, len(free)))]
        grid[r, col] = symbol
        used.add((r, col))
    if rng.random() < 0.5:
        grid = grid.T
    return "\n".join("".join(row) for row in grid) + "\n"


def _add_obstacles(rng: np.random.Generator, grid: np.ndarray, cols: list[int]) -> None:
    """2–4 straight wall segments of 2–5 cells inside the rooms, never on a dividing wall or in front of a door."""
    h, w = grid.shape
    doors = [(r, c) for c in cols for r in range(h) if grid[r, c] != "#"]
    keep_free = {(r, c + d) for r, c in doors for d in (-1, 1)}
    for _ in range(int(rng.integers(2, 5))):
        length, vertical = int(rng.integers(2, 6)), bool(rng.random() < 0.5)
        r0, c0 = int(rng.integers(0, h)), int(rng.integers(0, w))
        cells = [(r0 + i, c0) if vertical else (r0, c0 + i) for i in range(length)]
        for r, c in cells:
            if r < h and c < w and c not in cols and (r, c) not in keep_free:
                grid[r, c] = "#"


def _wall_columns(rng: np.random.Generator, w: int, walls: int) -> list[int]:
    first_room = 1 if walls == 1 else 2
    while True:
        cols = sorted(int(c) for c in rng.choice(np.arange(first_room, w - 1), size=walls, replace=False))
        if all(b - a >= 2 for a, b in zip(cols, cols[1:])):
            return cols


def check_usable(layout: Layout, max_steps: int, fail_prob: float, min_success: float = 0.99) -> None:
    """Raise :class:`LayoutError` unless the planner finds a plan from the start and the exact optimum
    succeeds within ``max_steps`` with probability at least ``min_success`` at ``fail_prob`` (0: the plan alone,
    the optimum not computed)."""
    from hnsdt.envs.dynamics import Rules
    from hnsdt.envs.oracle import optimum
    from hnsdt.symbolic import SymbolicState, plan

    start = SymbolicState.from_observation(layout, Rules(layout).initial_states(1)[0])
    if not plan(layout, start, "cost"):
        raise LayoutError(f"layout {layout.name}: the planner finds no plan")
    if min_success <= 0:
        return
    best = optimum(layout, fail_prob, max_steps)
    if best.success < min_success:
        raise LayoutError(f"layout {layout.name}: even the optimal policy succeeds only {best.success:.3f} of the "
                          f"time within {max_steps} steps at fail_prob {fail_prob:g} (need {min_success:g})")


def write_layout(layout: Layout, path: str | Path) -> Path:
    """Write ``layout`` as a layout file (loadable by ``envs.<name>.layout`` and :func:`load_layout`)."""
    from hnsdt.core.fileio import atomic_file

    path = Path(path)
    with atomic_file(path) as tmp:
        Path(tmp).write_text(layout.text)
    return path
