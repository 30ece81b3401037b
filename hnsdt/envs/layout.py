"""Grid layouts as data: parse, validate and describe an ASCII key–door world.

Legend (one character per cell, rows of equal length)::

    #  wall              .  floor
    @  start (once)      G  goal / exit (once)
    a-z  key             A-Z  door, opened by the key of the same letter
    0-9  collectible item (all must be held before the exit counts)

A layout is accepted only if it can be solved: starting from ``@``, picking every reachable key and opening
every reachable door whose key is held eventually reaches every item and then the goal. Because keys, open
doors and items are never lost, that greedy closure decides solvability exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

WALL, FLOOR, START, GOAL = "#", ".", "@", "G"
MOVES = ((-1, 0), (0, 1), (1, 0), (0, -1))  # action 0 up, 1 right, 2 down, 3 left
BUILTIN_LAYOUTS = ("keydoor_5x5", "multikeydoor_9x9")
_LEGEND = {WALL, FLOOR, START, GOAL}


class LayoutError(ValueError):
    """A layout that cannot be used; the message names the problem in one line."""


Cell = tuple[int, int]


@dataclass(frozen=True, eq=False)
class Layout:
    """A validated grid. Keys, doors and items are ordered by symbol, which fixes the observation layout.

    Two layouts are equal when their grid text is, so a layout can key a cache (the planner's)."""

    text: str
    name: str
    walls: np.ndarray = field(repr=False)  # (H, W) bool
    start: Cell
    goal: Cell
    keys: dict[str, Cell]
    doors: dict[str, Cell]
    items: dict[str, Cell]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Layout) and other.text == self.text

    def __hash__(self) -> int:
        return hash(self.text)

    @property
    def shape(self) -> tuple[int, int]:
        return self.walls.shape

    @property
    def key_names(self) -> list[str]:
        return list(self.keys)

    @property
    def door_names(self) -> list[str]:
        return list(self.doors)

    @property
    def item_names(self) -> list[str]:
        return list(self.items)

    @property
    def n_flags(self) -> int:
        return len(self.keys) + len(self.doors) + len(self.items)

    # The observation vector: row, col, then one flag per key, door and item, in symbol order. These slices name
    # its parts once; every module indexes states through them.
    @property
    def state_size(self) -> int:
        return 2 + self.n_flags

    @property
    def key_flags(self) -> slice:
        return slice(2, 2 + len(self.keys))

    @property
    def door_flags(self) -> slice:
        return slice(2 + len(self.keys), 2 + len(self.keys) + len(self.doors))

    @property
    def item_flags(self) -> slice:
        return slice(2 + len(self.keys) + len(self.doors), self.state_size)

    @property
    def state_names(self) -> list[str]:
        """Names of the observation vector's entries: row, col, then one flag per key, door, item."""
        return (
            ["row", "col"]
            + [f"has_key_{k}" for k in self.keys]
            + [f"door_open_{d}" for d in self.doors]
            + [f"has_item_{i}" for i in self.items]
        )

    def door_key_index(self, door: str) -> int:
        return self.key_names.index(door.lower())

    def free_cells(self) -> list[Cell]:
        h, w = self.shape
        return [(r, c) for r in range(h) for c in range(w) if not self.walls[r, c]]


def parse_layout(text: str, name: str = "<text>") -> Layout:
    """Parse and validate ASCII grid text; raise :class:`LayoutError` with one clear line on any problem."""
    rows = [line.rstrip("\r") for line in text.strip("\n").split("\n")]
    rows = [r for r in (line.strip() for line in rows) if r]
    if not rows:
        raise LayoutError(f"layout {name}: empty")
    width = len(rows[0])
    for i, row in enumerate(rows):
        if len(row) != width:
            raise LayoutError(f"layout {name}: not rectangular (row {i} has {len(row)} cells, row 0 has {width})")
    walls = np.zeros((len(rows), width), dtype=bool)
    start = goal = None
    keys: dict[str, Cell] = {}
    doors: dict[str, Cell] = {}
    items: dict[str, Cell] = {}
    for r, row in enumerate(rows):
        for c, ch in enumerate(row):
            if ch == WALL:
                walls[r, c] = True
            elif ch == FLOOR:
                pass
            elif ch == START:
                if start is not None:
                    raise LayoutError(f"layout {name}: more than one start '@'")
                start = (r, c)
            elif ch == GOAL:
                if goal is not None:
                    raise LayoutError(f"layout {name}: more than one goal 'G'")
                goal = (r, c)
            elif ch.isascii() and (ch.isalpha() or ch.isdigit()):
                table = keys if ch.islower() else doors if ch.isupper() else items
                if ch in table:
                    raise LayoutError(f"layout {name}: symbol '{ch}' appears more than once")
                table[ch] = (r, c)
            else:
                raise LayoutError(f"layout {name}: unknown character {ch!r} at row {r}, col {c}")
    if start is None:
        raise LayoutError(f"layout {name}: no start '@'")
    if goal is None:
        raise LayoutError(f"layout {name}: no goal 'G'")
    for d in doors:
        if d.lower() not in keys:
            raise LayoutError(f"layout {name}: door '{d}' has no key '{d.lower()}'")
    layout = Layout(
        text="\n".join(rows) + "\n",
        name=name,
        walls=walls,
        start=start,
        goal=goal,
        keys=dict(sorted(keys.items())),
        doors=dict(sorted(doors.items())),
        items=dict(sorted(items.items())),
    )
    _check_solvable(layout)
    return layout


def load_layout(spec: str | Path | Layout) -> Layout:
    """Accept a Layout, a built-in layout name, a path to a layout file, or the ASCII grid text itself."""
    if isinstance(spec, Layout):
        return spec
    spec_str = str(spec)
    if "\n" in spec_str or (START in spec_str and all(ch in _LEGEND or ch.isalnum() for ch in spec_str)):
        return parse_layout(spec_str)
    if spec_str in BUILTIN_LAYOUTS:
        text = resources.files("hnsdt.envs.layouts").joinpath(f"{spec_str}.txt").read_text()
        return parse_layout(text, name=spec_str)
    path = Path(spec_str)
    if path.is_file():
        return parse_layout(path.read_text(), name=str(path))
    raise LayoutError(
        f"layout {spec_str!r}: not a file, not a built-in layout ({', '.join(BUILTIN_LAYOUTS)}) and not grid text"
    )


def equal_runs(n: int, k: int, what: str) -> list[slice]:
    """The rows of ``k`` equal runs of ``n`` batched copies (each with its own ``what``: a map, a random stream, a
    cell), in order."""
    if not k or n % k:
        raise ValueError(f"{n} copies do not split evenly over {k} {what}")
    each = n // k
    return [slice(i * each, (i + 1) * each) for i in range(k)]


def layout_runs(layouts: Layout | tuple[Layout, ...], n: int) -> list[tuple[Layout, slice]]:
    """``(layout, rows)`` of each equal run of ``n`` batched copies: one layout for all of them, or one per equal
    run (a tuple: a batch over several maps, as the unseen-layout evaluation steps a split's maps together)."""
    if isinstance(layouts, Layout):
        return [(layouts, slice(0, n))]
    return list(zip(layouts, equal_runs(n, len(layouts), "layouts")))


def reachable_cells(layout: Layout, origin: Cell, open_doors: set[str]) -> dict[Cell, int]:
    """Shortest move counts from ``origin`` to every cell it can reach.

    Walls block; a closed door cell can be entered but not left, so it is a dead end of the search (and an
    origin on a closed door reaches nothing else)."""
    closed = {cell for d, cell in layout.doors.items() if d not in open_doors}
    h, w = layout.shape
    dist = {origin: 0}
    frontier = [origin]
    while frontier:
        nxt = []
        for r, c in frontier:
            if (r, c) in closed:
                continue
            for dr, dc in MOVES:
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and not layout.walls[rr, cc] and (rr, cc) not in dist:
                    dist[(rr, cc)] = dist[(r, c)] + 1
                    nxt.append((rr, cc))
        frontier = nxt
    return dist


def _check_solvable(layout: Layout) -> None:
    held: set[str] = set()
    opened: set[str] = set()
    while True:
        reach = reachable_cells(layout, layout.start, opened)
        new_keys = {k for k, cell in layout.keys.items() if cell in reach} - held
        new_doors = {d for d, cell in layout.doors.items() if cell in reach and d.lower() in held} - opened
        if not new_keys and not new_doors:
            break
        held |= new_keys
        opened |= new_doors
    missing = [f"item '{i}'" for i, cell in layout.items.items() if cell not in reach]
    if layout.goal not in reach:
        missing.append("the goal 'G'")
    if missing:
        raise LayoutError(f"layout {layout.name}: no path from the start reaches {', '.join(missing)}")
