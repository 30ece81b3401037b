"""The symbolic planner over MiniGrid's worlds: search over :class:`PlanState` for a state where the mission is
done — ``mode="bfs"`` the fewest operators, ``mode="cost"`` (uniform-cost search) the fewest steps walked, turns
not counted. Ties go to the fixed order of :func:`applicable`, so plans are deterministic."""

from __future__ import annotations

import heapq
from collections import deque

from hnsdt.minigrid.operators import Operator, PlanState, applicable, apply, done
from hnsdt.minigrid.world import World

PLAN_MODES = ("bfs", "cost")


class NoPlanError(RuntimeError):
    """No operator sequence achieves the mission from this state (e.g. the box to pick up was toggled away)."""


def plan(world: World, start: PlanState, mode: str = "cost") -> list[Operator]:
    if mode not in PLAN_MODES:
        raise ValueError(f"unknown plan mode {mode!r}; expected one of {PLAN_MODES}")
    if done(world, start):
        return []
    parents: dict[PlanState, tuple[PlanState, Operator] | None] = {start: None}
    found = None
    if mode == "bfs":
        queue = deque([start])
        while queue and found is None:
            s = queue.popleft()
            for op in applicable(world, s):
                nxt = apply(op, s)
                if nxt not in parents:
                    parents[nxt] = (s, op)
                    if done(world, nxt):
                        found = nxt
                        break
                    queue.append(nxt)
    else:
        best, heap, counter, settled = {start: 0}, [(0, 0, start)], 0, set()
        while heap:
            cost, _, s = heapq.heappop(heap)
            if s in settled:
                continue
            settled.add(s)
            if done(world, s):
                found = s
                break
            for op in applicable(world, s):
                nxt = apply(op, s)
                if nxt not in settled and cost + op.cost < best.get(nxt, float("inf")):
                    best[nxt], parents[nxt] = cost + op.cost, (s, op)
                    counter += 1
                    heapq.heappush(heap, (cost + op.cost, counter, nxt))
    if found is None:
        raise NoPlanError(f"{world.name}: no plan achieves the mission from {start}")
    ops, s = [], found
    while parents[s] is not None:
        s, op = parents[s]
        ops.append(op)
    return ops[::-1]
