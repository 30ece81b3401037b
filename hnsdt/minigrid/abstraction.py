"""φ over MiniGrid's own worlds: a state → the predicates that hold in it.

The planner is privileged here as on our maps: φ reads the env's true state, not the agent's 7 × 7 view.
Predicates are plain strings:

* ``At(r,c)`` the agent's cell and ``Facing(east|south|west|north)`` its direction;
* ``Carrying(<color> <kind>)`` what it holds (one object at a time), ``HandsFree`` when nothing;
* ``DoorOpen(r,c)`` / ``DoorLocked(r,c)`` per door (a door in neither is closed and unlocked);
* ``ObjectAt(<color> <kind>,r,c)`` per object lying on the grid;
* ``Done`` when the mission is achieved (on the goal cell; carrying the object to pick up; the door open).

:func:`phi` reads a :class:`WorldState` (what the optimum and the planner search over); :func:`phi_live` reads
MiniGrid's own objects off a live env, sharing nothing with :meth:`World.step`, so that a test stepping both on
the same actions checks the dynamics predicate by predicate.
"""

from __future__ import annotations

from hnsdt.minigrid.world import (
    DIRECTION_NAMES, GOAL, LOCKED, OPEN, OPEN_DOOR, World, WorldState,
)

DONE = "Done"
HANDS_FREE = "HandsFree"


def at(cell) -> str:
    return f"At({cell[0]},{cell[1]})"


def facing(direction: int) -> str:
    return f"Facing({DIRECTION_NAMES[direction]})"


def carrying(name: str) -> str:
    return f"Carrying({name})"


def door_open(cell) -> str:
    return f"DoorOpen({cell[0]},{cell[1]})"


def door_locked(cell) -> str:
    return f"DoorLocked({cell[0]},{cell[1]})"


def object_at(name: str, cell) -> str:
    return f"ObjectAt({name},{cell[0]},{cell[1]})"


def phi(world: World, s: WorldState) -> frozenset[str]:
    """φ(s) for a state of ``world``."""
    preds = {at(s.cell), facing(s.direction)}
    preds.add(carrying(world.objects[s.carrying].name) if s.carrying >= 0 else HANDS_FREE)
    for door, state in zip(world.doors, s.doors):
        if state == OPEN:
            preds.add(door_open(door.cell))
        elif state == LOCKED:
            preds.add(door_locked(door.cell))
    for thing, cell in zip(world.objects, s.objects):
        if cell[0] >= 0:
            preds.add(object_at(thing.name, cell))
    if world.done(s):
        preds.add(DONE)
    return frozenset(preds)


def phi_live(env, task: str, target_name: str = "") -> frozenset[str]:
    """φ read straight off MiniGrid's env (``env.unwrapped``'s agent, carried object and grid). ``task`` is the
    world's (:data:`hnsdt.minigrid.world.TASKS`); ``target_name`` names the object to pick up or,
    for OPEN_DOOR, the door's cell as ``"r,c"``."""
    u = env.unwrapped
    x, y = (int(v) for v in u.agent_pos)
    preds = {at((y, x)), facing(int(u.agent_dir))}
    preds.add(carrying(f"{u.carrying.color} {u.carrying.type}") if u.carrying is not None else HANDS_FREE)
    done = task == GOAL and u.grid.get(x, y) is not None and u.grid.get(x, y).type == "goal"
    for j in range(u.height):
        for i in range(u.width):
            obj = u.grid.get(i, j)
            if obj is None:
                continue
            if obj.type == "door":
                if obj.is_open:
                    preds.add(door_open((j, i)))
                    done |= task == OPEN_DOOR and target_name == f"{j},{i}"
                elif obj.is_locked:
                    preds.add(door_locked((j, i)))
            elif obj.type in ("key", "ball", "box"):
                preds.add(object_at(f"{obj.color} {obj.type}", (j, i)))
    if task not in (GOAL, OPEN_DOOR) and u.carrying is not None:
        done = f"{u.carrying.color} {u.carrying.type}" == target_name
    if done:
        preds.add(DONE)
    return frozenset(preds)
