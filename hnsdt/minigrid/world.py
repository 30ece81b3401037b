"""One generated MiniGrid world as data, and MiniGrid's rules written out over its state.

:class:`World` holds what never changes in an episode of a MiniGrid env reset with a seed: walls, goal cells,
the doors' cells and colours, the objects that can be carried (keys, balls, boxes), what ends the episode with
success, and ``max_steps``. :class:`WorldState` is everything that can change: the agent's cell and facing
direction, what it carries, each door's state and each object's cell. :meth:`World.step` is MiniGrid's
``MiniGridEnv.step`` (and the env's own success test) on that state, so that the exact optimum
(:mod:`hnsdt.minigrid.optimum`) can enumerate it; :func:`snapshot` reads the same state off a live
env, and ``tests/test_minigrid.py`` steps both side by side on random actions.

Cells are ``(row, col)``, MiniGrid's ``(x, y)`` turned round, as in our layouts. Directions are MiniGrid's:
0 east (+col), 1 south (+row), 2 west, 3 north. The rules, read from ``minigrid`` 3.2.0:

* left / right turn; forward enters the cell in front when it is empty, an open door or a goal (a goal
  ends the episode with success); walls, closed doors and objects block;
* pickup takes the object in front when the agent carries nothing; drop puts the carried object in front
  when that cell is empty (no wall, door, goal or object);
* toggle on a locked door opens it when the agent carries the key of its colour; on an unlocked door it
  opens or closes it; on a box it replaces the box by its contents (here: nothing — the box is gone);
* done does nothing; every action counts a step; the reward of a success at step t is ``1 − 0.9 t / max_steps``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

Cell = tuple[int, int]

CARRIED: Cell = (-1, -1)  # an object's cell while the agent carries it
GONE: Cell = (-2, -2)  # a box toggled open (its contents, none in these worlds, take its place)
DIRECTIONS = ((0, 1), (1, 0), (0, -1), (-1, 0))  # MiniGrid's agent_dir 0..3 as (drow, dcol)
DIRECTION_NAMES = ("east", "south", "west", "north")
OPEN, CLOSED, LOCKED = 0, 1, 2  # a door's state, MiniGrid's own encoding
CARRIABLE = ("key", "ball", "box")
GOAL, OPEN_DOOR, PICKUP = "goal", "open", "pickup"  # what ends an episode with success
TASKS = (GOAL, OPEN_DOOR, PICKUP)


class MiniGridError(ValueError):
    """A MiniGrid id or world this module cannot use; the message names the problem in one line."""


class Actions(IntEnum):
    """MiniGrid's action space (``minigrid.core.actions.Actions``)."""

    left = 0
    right = 1
    forward = 2
    pickup = 3
    drop = 4
    toggle = 5
    done = 6


N_ACTIONS = len(Actions)
MOVEMENT = (Actions.left, Actions.right, Actions.forward)  # the actions that can fail (pickup, drop, toggle never)


class WorldState(NamedTuple):
    cell: Cell
    direction: int
    carrying: int  # index into World.objects, -1 for nothing
    doors: tuple[int, ...]  # per World.doors: OPEN, CLOSED or LOCKED
    objects: tuple[Cell, ...]  # per World.objects: its cell, CARRIED or GONE


@dataclass(frozen=True)
class Door:
    cell: Cell
    color: str


@dataclass(frozen=True)
class Thing:
    """An object the agent can carry."""

    kind: str  # key, ball or box
    color: str

    @property
    def name(self) -> str:
        return f"{self.color} {self.kind}"


@dataclass(frozen=True, eq=False)
class World:
    env_id: str
    seed: int
    shape: tuple[int, int]
    walls: frozenset[Cell]
    goals: frozenset[Cell]
    doors: tuple[Door, ...]
    objects: tuple[Thing, ...]
    task: str  # GOAL, OPEN_DOOR or PICKUP
    target: int  # OPEN_DOOR: index into doors; PICKUP: index into objects; GOAL: -1
    max_steps: int
    start: WorldState

    def __post_init__(self):
        object.__setattr__(self, "_door_at", {d.cell: i for i, d in enumerate(self.doors)})

    @property
    def name(self) -> str:
        return f"{self.env_id}@{self.seed}"

    def door_at(self, cell: Cell) -> int:
        return self._door_at.get(cell, -1)

    def done(self, s: WorldState) -> bool:
        """The success condition as a property of the state (MiniGrid tests it on the step that makes it true)."""
        if self.task == GOAL:
            return s.cell in self.goals
        if self.task == OPEN_DOOR:
            return s.doors[self.target] == OPEN
        return s.carrying == self.target

    def reward(self, steps: int) -> float:
        """MiniGrid's reward of a success on step ``steps``."""
        return 1 - 0.9 * (steps / self.max_steps)

    def step(self, s: WorldState, action: int) -> tuple[WorldState, bool]:
        """MiniGrid's step of ``action`` from ``s`` (the action works): the next state, and whether this step
        ends the episode with success."""
        a = Actions(action)
        if a == Actions.left:
            return s._replace(direction=(s.direction - 1) % 4), False
        if a == Actions.right:
            return s._replace(direction=(s.direction + 1) % 4), False
        dr, dc = DIRECTIONS[s.direction]
        front = (s.cell[0] + dr, s.cell[1] + dc)
        door = self.door_at(front)
        thing = s.objects.index(front) if front in s.objects else -1
        if a == Actions.forward:
            blocked = front in self.walls or thing >= 0 or (door >= 0 and s.doors[door] != OPEN)
            if blocked:
                return s, False
            s = s._replace(cell=front)
            return s, self.task == GOAL and front in self.goals
        if a == Actions.pickup:
            if thing < 0 or s.carrying >= 0:
                return s, False
            objects = list(s.objects)
            objects[thing] = CARRIED
            s = s._replace(carrying=thing, objects=tuple(objects))
            return s, self.task == PICKUP and thing == self.target
        if a == Actions.drop:
            empty = not (front in self.walls or front in self.goals or door >= 0 or thing >= 0)
            if s.carrying < 0 or not empty:
                return s, False
            objects = list(s.objects)
            objects[s.carrying] = front
            return s._replace(carrying=-1, objects=tuple(objects)), False
        if a == Actions.toggle:
            if door >= 0:
                state = s.doors[door]
                if state == LOCKED:
                    held = self.objects[s.carrying] if s.carrying >= 0 else None
                    if held is not None and held.kind == "key" and held.color == self.doors[door].color:
                        state = OPEN
                else:
                    state = CLOSED if state == OPEN else OPEN
                doors = list(s.doors)
                doors[door] = state
                s = s._replace(doors=tuple(doors))
            elif thing >= 0 and self.objects[thing].kind == "box":
                objects = list(s.objects)
                objects[thing] = GONE
                s = s._replace(objects=tuple(objects))
            # MiniGrid's Unlock tests its door after every toggle
            return s, self.task == OPEN_DOOR and s.doors[self.target] == OPEN
        return s, False  # done: nothing happens
