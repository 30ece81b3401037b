"""Symbolic operators over MiniGrid's worlds, with what carrying one object at a time needs (a ``Drop``).

The planner's state (:class:`PlanState`) is a :class:`WorldState` without the facing direction — turning is
the controllers' business (:mod:`hnsdt.minigrid.controllers`) — and with one more place an object can be:
``ASIDE``, put down by a planned ``Drop`` somewhere beside the agent (where exactly, the controller decides; the
planner does not count it as an obstacle, and a replan reads where it really went).

==================  ===========================================================  =============================
operator            preconditions                                                effects
==================  ===========================================================  =============================
GoTo(object o)      o on the grid; a free cell beside it reachable               agent on the nearest such cell
GoTo(door d)        d not open; a free cell beside it reachable                  agent on the nearest such cell
GoTo(goal)          the goal reachable (GOAL worlds)                             agent on the goal: Done
PickUp(o)           agent beside o, hands free                                   Carrying(o) (Done: the target)
Open(d)             agent beside d, d not open; locked: carrying its colour's key DoorOpen(d) (Done: the target)
Drop                carrying something, an empty cell beside the agent           hands free, the object ASIDE
==================  ===========================================================  =============================

"Reachable" walks 4-neighbour steps over cells that are not walls, goal cells (stepping on one ends the
episode), objects lying on the grid or doors that are not open. A GoTo costs its path's length, the others 1.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

from hnsdt.minigrid.world import CARRIED, GOAL, LOCKED, OPEN, Cell, World, WorldState

ASIDE: Cell = (-3, -3)  # an object put down by a planned Drop
GOTO_OBJECT, GOTO_DOOR, GOTO_GOAL, PICKUP, OPEN_IT, DROP = "goto_object", "goto_door", "goto_goal", "pickup", \
    "open", "drop"
KINDS = (GOTO_OBJECT, GOTO_DOOR, GOTO_GOAL, PICKUP, OPEN_IT, DROP)
STEPS = ((-1, 0), (0, 1), (1, 0), (0, -1))  # 4-neighbours, in a fixed order (ties go to the first)


class PlanState(NamedTuple):
    cell: Cell
    carrying: int
    doors: tuple[int, ...]
    objects: tuple[Cell, ...]

    @classmethod
    def of(cls, s: WorldState) -> "PlanState":
        return cls(s.cell, s.carrying, s.doors, s.objects)


@dataclass(frozen=True)
class Operator:
    kind: str
    index: int  # into World.objects (GoTo object, PickUp) or World.doors (GoTo door, Open); -1 otherwise
    cell: Cell  # GoTo: where the agent ends; PickUp / Open: the object's or door's cell; Drop: (-1, -1)
    cost: int = 1

    def name(self, world: World) -> str:
        if self.kind == GOTO_OBJECT:
            return f"GoTo({world.objects[self.index].name})"
        if self.kind == GOTO_DOOR:
            return f"GoTo({world.doors[self.index].color} door)"
        if self.kind == GOTO_GOAL:
            return "GoTo(goal)"
        if self.kind == PICKUP:
            return f"PickUp({world.objects[self.index].name})"
        if self.kind == OPEN_IT:
            return f"Open({world.doors[self.index].color} door)"
        return "Drop"


def done(world: World, s: PlanState) -> bool:
    return world.done(s)  # (the world's test reads only what a PlanState keeps: cell, doors, carrying)


def distances(world: World, s: PlanState) -> dict[Cell, int]:
    """Steps from the agent's cell to every cell it can walk to (the goal cells as ends, never passed through)."""
    blocked = {c for c in s.objects if c[0] >= 0}
    blocked |= {d.cell for d, state in zip(world.doors, s.doors) if state != OPEN}
    h, w = world.shape
    dist = {s.cell: 0}
    queue = deque([s.cell])
    while queue:
        cell = queue.popleft()
        if cell in world.goals and cell != s.cell:
            continue  # the episode ends there
        for dr, dc in STEPS:
            nxt = (cell[0] + dr, cell[1] + dc)
            if (0 <= nxt[0] < h and 0 <= nxt[1] < w and nxt not in dist and nxt not in world.walls
                    and nxt not in blocked):
                dist[nxt] = dist[cell] + 1
                queue.append(nxt)
    return dist


def beside(cell: Cell, other: Cell) -> bool:
    return abs(cell[0] - other[0]) + abs(cell[1] - other[1]) == 1


def empty_beside(world: World, cell: Cell, objects) -> list[Cell]:
    """The cells beside ``cell`` a carried object can be put on (no wall, door, goal or object), in STEPS order."""
    h, w = world.shape
    out = []
    for dr, dc in STEPS:
        c = (cell[0] + dr, cell[1] + dc)
        if (0 <= c[0] < h and 0 <= c[1] < w and c not in world.walls and c not in world.goals
                and world.door_at(c) < 0 and c not in objects):
            out.append(c)
    return out


def _nearest_beside(target: Cell, dist: dict[Cell, int], goals) -> tuple[Cell, int] | None:
    """The reachable cell beside ``target`` with the fewest steps (ties: the order of STEPS)."""
    best = None
    for dr, dc in STEPS:
        cell = (target[0] + dr, target[1] + dc)
        if cell in dist and cell not in goals and (best is None or dist[cell] < best[1]):
            best = (cell, dist[cell])
    return best


def applicable(world: World, s: PlanState) -> list[Operator]:
    """Every operator whose preconditions hold in ``s``, in a fixed order: the interactions (pick up, open,
    drop), then the GoTos to objects, doors and the goal."""
    ops: list[Operator] = []
    for i, cell in enumerate(s.objects):
        if cell[0] >= 0 and s.carrying < 0 and beside(s.cell, cell):
            ops.append(Operator(PICKUP, i, cell))
    for d, (door, state) in enumerate(zip(world.doors, s.doors)):
        if state != OPEN and beside(s.cell, door.cell):
            if state != LOCKED or (s.carrying >= 0 and world.objects[s.carrying].kind == "key"
                                   and world.objects[s.carrying].color == door.color):
                ops.append(Operator(OPEN_IT, d, door.cell))
    if s.carrying >= 0 and empty_beside(world, s.cell, s.objects):
        ops.append(Operator(DROP, -1, (-1, -1)))
    dist = distances(world, s)
    for i, cell in enumerate(s.objects):
        if cell[0] >= 0 and (near := _nearest_beside(cell, dist, world.goals)) and near[0] != s.cell:
            ops.append(Operator(GOTO_OBJECT, i, near[0], near[1]))
    for d, (door, state) in enumerate(zip(world.doors, s.doors)):
        if state != OPEN and (near := _nearest_beside(door.cell, dist, world.goals)) and near[0] != s.cell:
            ops.append(Operator(GOTO_DOOR, d, near[0], near[1]))
    if world.task == GOAL:
        for goal in sorted(world.goals):
            if goal in dist and goal != s.cell:
                ops.append(Operator(GOTO_GOAL, -1, goal, dist[goal]))
    return ops


def apply(op: Operator, s: PlanState) -> PlanState:
    if op.kind in (GOTO_OBJECT, GOTO_DOOR, GOTO_GOAL):
        return s._replace(cell=op.cell)
    if op.kind == PICKUP:
        objects = list(s.objects)
        objects[op.index] = CARRIED
        return s._replace(carrying=op.index, objects=tuple(objects))
    if op.kind == OPEN_IT:
        doors = list(s.doors)
        doors[op.index] = OPEN
        return s._replace(doors=tuple(doors))
    objects = list(s.objects)
    objects[s.carrying] = ASIDE
    return s._replace(carrying=-1, objects=tuple(objects))


def achieved(op: Operator, s: PlanState) -> bool:
    """The operator's effect holds in ``s`` (the executor's completion test)."""
    if op.kind in (GOTO_OBJECT, GOTO_DOOR, GOTO_GOAL):
        return s.cell == op.cell
    if op.kind == PICKUP:
        return s.carrying == op.index
    if op.kind == OPEN_IT:
        return s.doors[op.index] == OPEN
    return s.carrying < 0
