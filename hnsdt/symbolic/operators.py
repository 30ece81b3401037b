"""Symbolic operators with preconditions, effects and costs, grounded on a layout.

=================  ===========================================================  ===================  ==============
operator           preconditions                                                effects              cost
=================  ===========================================================  ===================  ==============
GoTo(key k)        ¬HasKey(k), key cell reachable through walls and open doors  At(key cell)         path length
PickKey(k)         At(key cell), ¬HasKey(k)                                     HasKey(k)            1
GoTo(door D)       ¬DoorOpen(D), door cell reachable                            At(door cell)        path length
OpenDoor(D)        At(door cell), HasKey(d), ¬DoorOpen(D)                       DoorOpen(D)          1
GoTo(item i)       ¬HasItem(i), item cell reachable                             At(item cell)        path length
PickItem(i)        At(item cell), ¬HasItem(i)                                   HasItem(i)           1
GoTo(exit)         HasItem(every item), exit reachable                          At(exit), Done       path length
Move(c → c')       At(c), c' a 4-neighbour of c, not a wall, c not a closed door  At(c')               1
=================  ===========================================================  ===================  ==============

Two operator sets (``OPERATOR_SETS``): ``goto`` (ours: GoTo macro-operators to objects, then the interactions)
and ``move`` (the paper's Appendix B: one-cell ``Move`` operators plus PickKey / OpenDoor / PickItem; the goal
Done is reached by the Move onto the exit holding every item).

"Reachable" follows the environment: a closed door cell may be the end of a path but never a step along it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

from hnsdt.envs.layout import MOVES, Cell, Layout, reachable_cells
from hnsdt.symbolic.abstraction import DONE, SymbolicState, at, door_open, has_item, has_key

GOTO_KEY, PICK_KEY, GOTO_DOOR, OPEN_DOOR, GOTO_ITEM, PICK_ITEM, GOTO_EXIT, MOVE = (
    "goto_key", "pick_key", "goto_door", "open_door", "goto_item", "pick_item", "goto_exit", "move")
GOTO_KINDS = (GOTO_KEY, GOTO_DOOR, GOTO_ITEM, GOTO_EXIT, MOVE)  # operators that change the agent's cell
INTERACT_KINDS = (PICK_KEY, OPEN_DOOR, PICK_ITEM)


@dataclass(frozen=True)
class Operator:
    kind: str
    obj: str  # key letter, door letter, item digit, "exit", or the source cell "r,c" of a Move
    target: Cell
    pre: frozenset[str] = field(compare=False)
    eff: frozenset[str] = field(compare=False)
    cost: int = field(compare=False, default=1)

    @cached_property  # (computed once: the executors read it at every operator they start)
    def name(self) -> str:
        return _NAMES[self.kind].format(obj=self.obj, r=self.target[0], c=self.target[1])

    def __hash__(self) -> int:  # the generated one's value, computed once: the executor's plan check hashes
        h = self.__dict__.get("_hash")  # the rest of its plan at every step
        if h is None:
            h = self.__dict__["_hash"] = hash((self.kind, self.obj, self.target))
        return h

    def __reduce__(self):  # rebuilt from its fields: a cached hash would be the pickling process's
        return Operator, (self.kind, self.obj, self.target, self.pre, self.eff, self.cost)

    def __str__(self) -> str:
        return self.name

    def achieved(self, predicates: frozenset[str]) -> bool:
        """The paper's completion test: φ(s) ⊇ eff(o)."""
        return self.eff <= predicates


_NAMES = {GOTO_KEY: "GoTo(key {obj})", PICK_KEY: "PickKey({obj})", GOTO_DOOR: "GoTo(door {obj})",
          OPEN_DOOR: "OpenDoor({obj})", GOTO_ITEM: "GoTo(item {obj})", PICK_ITEM: "PickItem({obj})",
          GOTO_EXIT: "GoTo(exit)", MOVE: "Move({obj}->{r},{c})"}


def apply(op: Operator, s: SymbolicState) -> SymbolicState:
    if op.kind in GOTO_KINDS:
        return SymbolicState(op.target, s.keys, s.doors, s.items)
    if op.kind == PICK_KEY:
        return SymbolicState(s.cell, s.keys | {op.obj}, s.doors, s.items)
    if op.kind == OPEN_DOOR:
        return SymbolicState(s.cell, s.keys, s.doors | {op.obj}, s.items)
    return SymbolicState(s.cell, s.keys, s.doors, s.items | {op.obj})


def goto(kind: str, obj: str, target: Cell, dist: int, extra_pre: frozenset[str] = frozenset()) -> Operator:
    eff = {at(target)} | ({DONE} if kind == GOTO_EXIT else set())
    return Operator(kind, obj, target, extra_pre, frozenset(eff), dist)


def move(source: Cell, target: Cell) -> Operator:
    """Move(source → target) between 4-neighbours. Done is no effect of it: the planner's goal test reads it
    from the state the move reaches (the exit, holding every item)."""
    return Operator(MOVE, f"{source[0]},{source[1]}", target, frozenset({at(source)}), frozenset({at(target)}))


def interaction(layout: Layout, kind: str, obj: str) -> Operator:
    if kind == PICK_KEY:
        cell = layout.keys[obj]
        return Operator(kind, obj, cell, frozenset({at(cell)}), frozenset({has_key(obj)}))
    if kind == OPEN_DOOR:
        cell = layout.doors[obj]
        return Operator(kind, obj, cell, frozenset({at(cell), has_key(obj.lower())}), frozenset({door_open(obj)}))
    cell = layout.items[obj]
    return Operator(kind, obj, cell, frozenset({at(cell)}), frozenset({has_item(obj)}))


OPERATOR_SETS = ("goto", "move")


def applicable(layout: Layout, s: SymbolicState, operators: str = "goto") -> list[Operator]:
    """Every operator of the set ``operators`` whose preconditions hold in ``s``, in a fixed order (keys,
    doors, items, then the moves: GoTo to keys, doors, items, exit, or Move up, right, down, left)."""
    ops: list[Operator] = []
    for k, cell in layout.keys.items():
        if k not in s.keys and s.cell == cell:
            ops.append(interaction(layout, PICK_KEY, k))
    for d, cell in layout.doors.items():
        if d not in s.doors and s.cell == cell and d.lower() in s.keys:
            ops.append(interaction(layout, OPEN_DOOR, d))
    for i, cell in layout.items.items():
        if i not in s.items and s.cell == cell:
            ops.append(interaction(layout, PICK_ITEM, i))
    if operators == "move":
        return ops + _moves(layout, s)
    dist = reachable_cells(layout, s.cell, set(s.doors))
    candidates = (
        [(GOTO_KEY, k, c) for k, c in layout.keys.items() if k not in s.keys]
        + [(GOTO_DOOR, d, c) for d, c in layout.doors.items() if d not in s.doors]
        + [(GOTO_ITEM, i, c) for i, c in layout.items.items() if i not in s.items]
    )
    for kind, obj, cell in candidates:
        if cell != s.cell and cell in dist:
            ops.append(goto(kind, obj, cell, dist[cell]))
    if s.items >= set(layout.items) and layout.goal in dist and s.cell != layout.goal:
        pre = frozenset(has_item(i) for i in layout.items)
        ops.append(goto(GOTO_EXIT, "exit", layout.goal, dist[layout.goal], pre))
    return ops


def _moves(layout: Layout, s: SymbolicState) -> list[Operator]:
    """The legal one-cell moves from ``s``: onto any non-wall neighbour, never out of a closed door."""
    if s.cell in {c for d, c in layout.doors.items() if d not in s.doors}:
        return []
    h, w = layout.shape
    ops = []
    for dr, dc in MOVES:
        r, c = s.cell[0] + dr, s.cell[1] + dc
        if 0 <= r < h and 0 <= c < w and not layout.walls[r, c]:
            ops.append(move(s.cell, (r, c)))
    return ops
