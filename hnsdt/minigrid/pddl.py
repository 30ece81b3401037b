"""Export one MiniGrid world's symbolic domain and planning problem as STRIPS PDDL (with typing), for any STRIPS
planner (the tests solve it with pyperplan and compare the plan length with :func:`hnsdt.minigrid.planner.plan`'s).

Places are the start cell, the goal cells and every cell beside an object or a door that is no wall — a door's or
an object's own cell too: in a one-cell room the key is picked up from the doorway, and a door whose key lay
beside it is opened from where the key was. Walking is grounded
per world, as in :mod:`hnsdt.symbolic.pddl`: reachability through closed doors and objects is not expressible in
STRIPS, so every ordered pair of places gets one ``goto`` action per minimal set of *blockers* that must be out of
the way — each closed or locked door on the route open (``door-open``), each object on it moved
(``moved``: picked up once; a put-down object is out of the way, as the planner's ``ASIDE``). A route never
passes a goal cell or a wall. Picking up, opening and dropping are lifted:

* ``pickup ?o ?p ?q``: at ``?p`` beside ``?q`` where ``?o`` lies, hands free → carrying ``?o``, moved;
* ``open-locked ?d ?k ?p`` / ``open-closed ?d ?p``: at ``?p`` beside the door; a locked one needs its key;
* ``drop ?o ?p``: carrying ``?o`` at a place with an empty cell beside it (``room``, as the world was made).

The goal is the mission: ``(at p-goal-…)`` (DoorKey), ``(carrying …)`` (the pickup worlds), ``(door-open …)``
(Unlock). PDDL is case-insensitive; names are ``obj-<i>-<color>-<kind>``, ``door-<i>-<color>``, ``c-<row>-<col>``.
"""

from __future__ import annotations

from pathlib import Path

from hnsdt.core.fileio import atomic_file
from hnsdt.minigrid.operators import STEPS, beside, empty_beside
from hnsdt.minigrid.world import GOAL, LOCKED, OPEN, OPEN_DOOR, Cell, World, WorldState


def _place(cell: Cell) -> str:
    return f"c-{cell[0]}-{cell[1]}"


def _object(world: World, i: int) -> str:
    t = world.objects[i]
    return f"obj-{i}-{t.color}-{t.kind}"


def _door(world: World, d: int) -> str:
    return f"door-{d}-{world.doors[d].color}"


def places(world: World, state: WorldState) -> list[Cell]:
    """The start, the goal cells and the cells beside an object or a door that are not walls (a door's or an
    object's own cell among them: the agent stands there once the door is open or the object moved), in a fixed
    order."""
    h, w = world.shape
    out = {state.cell, *world.goals}
    for target in [c for c in state.objects if c[0] >= 0] + [d.cell for d in world.doors]:
        for dr, dc in STEPS:
            c = (target[0] + dr, target[1] + dc)
            if 0 <= c[0] < h and 0 <= c[1] < w and c not in world.walls and c not in world.goals:
                out.add(c)
    return sorted(out)


def minimal_blockers(world: World, state: WorldState, origin: Cell) -> dict[Cell, list[frozenset[str]]]:
    """Per cell reachable from ``origin`` with some blockers out of the way: the minimal sets of blocker names
    (door and object names) a route there needs (label-setting search; a goal cell ends a route)."""
    blocker_at = {d.cell: _door(world, i) for i, (d, s) in enumerate(zip(world.doors, state.doors)) if s != OPEN}
    blocker_at |= {c: _object(world, i) for i, c in enumerate(state.objects) if c[0] >= 0}
    h, w = world.shape
    labels: dict[Cell, list[frozenset[str]]] = {origin: [frozenset()]}
    frontier = [(origin, frozenset())]
    while frontier:
        cell, need = frontier.pop()
        if need not in labels.get(cell, ()):
            continue  # superseded by a smaller set
        if cell in world.goals and cell != origin:
            continue
        for dr, dc in STEPS:
            nxt = (cell[0] + dr, cell[1] + dc)
            if not (0 <= nxt[0] < h and 0 <= nxt[1] < w) or nxt in world.walls:
                continue
            more = need | ({blocker_at[nxt]} if nxt in blocker_at else set())
            have = labels.setdefault(nxt, [])
            if any(old <= more for old in have):
                continue
            have[:] = [old for old in have if not more <= old] + [more]
            frontier.append((nxt, more))
    return labels


def domain_pddl(world: World, state: WorldState | None = None) -> str:
    state = state or world.start
    spots = places(world, state)
    actions = [
        """  (:action pickup
    :parameters (?o - thing ?p - place ?q - place)
    :precondition (and (at ?p) (beside ?p ?q) (lies ?o ?q) (hands-free))
    :effect (and (carrying ?o) (moved ?o) (not (lies ?o ?q)) (not (hands-free))))""",
        """  (:action open-locked
    :parameters (?d - door ?k - thing ?p - place)
    :precondition (and (at ?p) (beside-door ?p ?d) (door-locked ?d) (carrying ?k) (key-of ?k ?d))
    :effect (and (door-open ?d) (not (door-locked ?d))))""",
        """  (:action open-closed
    :parameters (?d - door ?p - place)
    :precondition (and (at ?p) (beside-door ?p ?d) (door-closed ?d))
    :effect (and (door-open ?d) (not (door-closed ?d))))""",
        """  (:action drop
    :parameters (?o - thing ?p - place)
    :precondition (and (at ?p) (carrying ?o) (room ?p))
    :effect (and (hands-free) (not (carrying ?o))))""",
    ]
    for a in spots:
        reach = minimal_blockers(world, state, a)
        for b in spots:
            if a == b or b not in reach:
                continue
            for n, need in enumerate(sorted(reach[b], key=sorted)):
                pre = [f"(at {_place(a)})"] + [f"({'door-open' if x.startswith('door-') else 'moved'} {x})"
                                                for x in sorted(need)]
                actions.append(f"  (:action goto-{_place(a)}-to-{_place(b)}-r{n}\n    :parameters ()\n"
                               f"    :precondition (and {' '.join(pre)})\n"
                               f"    :effect (and (at {_place(b)}) (not (at {_place(a)}))))")
    return (f"; hnsdt MiniGrid domain grounded on {world.name}\n"
            "(define (domain hnsdt-minigrid)\n"
            "  (:requirements :strips :typing)\n"
            "  (:types place thing door)\n"
            "  (:predicates (at ?p - place) (beside ?p ?q - place) (beside-door ?p - place ?d - door)\n"
            "               (lies ?o - thing ?q - place) (carrying ?o - thing) (hands-free) (moved ?o - thing)\n"
            "               (door-open ?d - door) (door-closed ?d - door) (door-locked ?d - door)\n"
            "               (key-of ?k - thing ?d - door) (room ?p - place))\n"
            + "\n".join(actions) + ")\n")


def problem_pddl(world: World, state: WorldState | None = None) -> str:
    state = state or world.start
    spots = places(world, state)
    init = [f"(at {_place(state.cell)})"]
    init.append("(hands-free)" if state.carrying < 0 else f"(carrying {_object(world, state.carrying)})")
    lying = [c for c in state.objects if c[0] >= 0]  # the objects' cells: places for pickup's ?q
    for i, c in enumerate(state.objects):
        if c[0] >= 0:
            init.append(f"(lies {_object(world, i)} {_place(c)})")
        else:
            init.append(f"(moved {_object(world, i)})")
    for p in spots:
        for c in lying:
            if beside(p, c):
                init.append(f"(beside {_place(p)} {_place(c)})")
        for d, door in enumerate(world.doors):
            if beside(p, door.cell):
                init.append(f"(beside-door {_place(p)} {_door(world, d)})")
        if empty_beside(world, p, state.objects):
            init.append(f"(room {_place(p)})")
    for d, (door, s) in enumerate(zip(world.doors, state.doors)):
        init.append(f"({'door-open' if s == OPEN else 'door-locked' if s == LOCKED else 'door-closed'} "
                    f"{_door(world, d)})")
        for i, t in enumerate(world.objects):
            if t.kind == "key" and t.color == door.color:
                init.append(f"(key-of {_object(world, i)} {_door(world, d)})")
    if world.task == GOAL:
        if len(world.goals) != 1:  # (STRIPS has no "or")
            raise ValueError(f"{world.name}: the PDDL export needs one goal cell, the world has {len(world.goals)}")
        goal = f"(at {_place(next(iter(world.goals)))})"
    elif world.task == OPEN_DOOR:
        goal = f"(door-open {_door(world, world.target)})"
    else:
        goal = f"(carrying {_object(world, world.target)})"
    all_places = sorted(set(spots) | set(lying))
    objects = [" ".join(_place(p) for p in all_places) + " - place"]
    if world.objects:
        objects.append(" ".join(_object(world, i) for i in range(len(world.objects))) + " - thing")
    if world.doors:
        objects.append(" ".join(_door(world, d) for d in range(len(world.doors))) + " - door")
    name = world.env_id.lower().replace("minigrid-", "").replace("-v0", "")
    return (f"(define (problem hnsdt-{name}-{world.seed})\n"
            "  (:domain hnsdt-minigrid)\n"
            f"  (:objects {' '.join(objects)})\n"
            f"  (:init {' '.join(init)})\n"
            f"  (:goal {goal}))\n")


def write_pddl(world: World, out_dir: str | Path, state: WorldState | None = None) -> tuple[Path, Path]:
    """``domain.pddl`` and ``problem.pddl`` of ``world`` from ``state`` (default: its start)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    domain, problem = out / "domain.pddl", out / "problem.pddl"
    for path, text in ((domain, domain_pddl(world, state)), (problem, problem_pddl(world, state))):
        with atomic_file(path) as tmp:
            tmp.write_text(text)
    return domain, problem
