"""Hand-written low-level controllers for the MiniGrid operators, and the symbolic agent that runs a plan with them
(the paper's symbolic baseline: planner + controllers, replanning when an operator can no longer be done).

* GoTo: the first action of a shortest turn / forward sequence onto the operator's cell (a breadth-first search
  over cell and direction, stepped by :meth:`World.step`);
* PickUp, Open: turn to face the object or door, then pickup / toggle;
* Drop: turn to face an empty cell beside the agent — one not beside a door when there is one, so the object does
  not block a doorway — then drop.

A controller that cannot act (no way, nowhere to put the object) makes the agent replan; a plan whose first
operator its controller still cannot act on means the agent gives up rather than replan for ever.

The controllers read the true state, as the planner does; with action failures they simply act again.
"""

from __future__ import annotations

from collections import deque

from hnsdt.minigrid.operators import (
    DROP, GOTO_DOOR, GOTO_GOAL, GOTO_OBJECT, OPEN_IT, PICKUP, Operator, PlanState, achieved, beside, distances,
    empty_beside,
)
from hnsdt.minigrid.live import Episode, GaveUp, run_episode
from hnsdt.minigrid.planner import NoPlanError, plan
from hnsdt.minigrid.world import DIRECTIONS, LOCKED, OPEN, Actions, Cell, World, WorldState

WALKS = (GOTO_OBJECT, GOTO_DOOR, GOTO_GOAL)


def walk(world: World, s: WorldState, target: Cell) -> int | None:
    """The first action of a shortest left / right / forward sequence from ``s`` onto ``target`` (ties: left,
    right, forward), or None when there is none."""
    start = (s.cell, s.direction)
    first: dict[tuple[Cell, int], int | None] = {start: None}
    queue = deque([s])
    while queue:
        cur = queue.popleft()
        for a in (Actions.left, Actions.right, Actions.forward):
            nxt, success = world.step(cur, a)
            key = (nxt.cell, nxt.direction)
            if key in first:
                continue
            first[key] = first[(cur.cell, cur.direction)] if cur is not s else int(a)
            if nxt.cell == target:
                return first[key]
            if not success:
                queue.append(nxt)
    return None


def face(s: WorldState, target: Cell) -> int | None:
    """Turn towards the neighbouring ``target`` (None once the agent faces it)."""
    want = DIRECTIONS.index((target[0] - s.cell[0], target[1] - s.cell[1]))
    turn = (want - s.direction) % 4
    return None if turn == 0 else int(Actions.left) if turn == 3 else int(Actions.right)


def drop_cell(world: World, s: WorldState) -> Cell | None:
    """Where Drop puts the object: an empty cell beside the agent, preferring one beside no door, then the one in
    front, then the order of STEPS."""
    front = (s.cell[0] + DIRECTIONS[s.direction][0], s.cell[1] + DIRECTIONS[s.direction][1])
    empty = empty_beside(world, s.cell, s.objects)
    if not empty:
        return None
    return min(empty, key=lambda c: (any(beside(c, d.cell) for d in world.doors), c != front))


def controller(world: World, s: WorldState, op: Operator) -> int | None:
    """The next low-level action for ``op`` in ``s`` (None: the controller cannot do it from here)."""
    if op.kind in WALKS:
        return walk(world, s, op.cell)
    if op.kind in (PICKUP, OPEN_IT):
        if not beside(s.cell, op.cell):
            return None
        turn = face(s, op.cell)
        return turn if turn is not None else int(Actions.pickup if op.kind == PICKUP else Actions.toggle)
    target = drop_cell(world, s)
    if target is None:
        return None
    turn = face(s, target)
    return turn if turn is not None else int(Actions.drop)


def possible(world: World, op: Operator, s: PlanState) -> bool:
    """Whether ``op`` can still be done from ``s`` (else the agent replans)."""
    if op.kind in WALKS:
        return op.cell in distances(world, s)
    if op.kind == PICKUP:
        return s.objects[op.index] == op.cell and s.carrying < 0 and beside(s.cell, op.cell)
    if op.kind == OPEN_IT:
        state, door = s.doors[op.index], world.doors[op.index]
        key = world.objects[s.carrying] if s.carrying >= 0 else None
        return (state != OPEN and beside(s.cell, op.cell)
                and (state != LOCKED or (key is not None and key.kind == "key" and key.color == door.color)))
    return op.kind == DROP and s.carrying >= 0 and bool(empty_beside(world, s.cell, s.objects))


class SymbolicAgent:
    """Plans from the true state, runs each operator with its controller, replans when the next operator can no
    longer be done (or its controller finds no way). ``plans`` counts the planner's calls."""

    def __init__(self, world: World, mode: str = "cost"):
        self.world, self.mode = world, mode
        self.plan: list[Operator] = []
        self.plans = 0

    def advance(self, ps: PlanState) -> bool:
        """Drop the operators ``ps`` has achieved from the plan's head; can the next one still be done?"""
        while self.plan and achieved(self.plan[0], ps):
            self.plan.pop(0)
        return bool(self.plan) and possible(self.world, self.plan[0], ps)

    def replan(self, ps: PlanState) -> None:
        try:
            self.plan = plan(self.world, ps, self.mode)
        except NoPlanError as exc:
            raise GaveUp(str(exc)) from exc
        self.plans += 1

    def act(self, s: WorldState) -> int:
        ps = PlanState.of(s)
        action = controller(self.world, s, self.plan[0]) if self.advance(ps) else None
        if action is None:
            self.replan(ps)
            action = controller(self.world, s, self.plan[0]) if self.plan else int(Actions.done)
            if action is None:
                raise GaveUp(f"{self.world.name}: the controller of {self.plan[0].name(self.world)} cannot act")
        return action


def symbolic_episode(env_id: str, seed: int, fail_prob: float = 0.0, failure_seed: int = 0,
                     mode: str = "cost") -> Episode:
    """One episode of :class:`SymbolicAgent` on ``env_id``'s world ``seed``."""
    return run_episode(env_id, seed, fail_prob, failure_seed, lambda world, env: SymbolicAgent(world, mode))
