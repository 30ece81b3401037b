"""The symbolic planner: breadth-first search over symbolic states for the goal {Done}.

``mode="bfs"`` (the paper's planner) returns a plan with the fewest operators; ``mode="cost"`` runs uniform-cost
search and returns the cheapest plan (the sum of operator costs, i.e. the number of low-level steps when no
move fails). ``operators`` picks the operator set (:data:`hnsdt.symbolic.operators.OPERATOR_SETS`): with the
paper's one-cell ``move`` operators every operator costs one step, so both modes find a shortest plan. Ties are broken by the fixed operator order of :func:`applicable`, so plans are deterministic.
"""

from __future__ import annotations

import heapq
from collections import deque
from functools import lru_cache

from hnsdt.envs.layout import Layout
from hnsdt.symbolic.abstraction import SymbolicState
from hnsdt.symbolic.operators import OPERATOR_SETS, Operator, applicable, apply

PLAN_MODES = ("bfs", "cost")


class NoPlanError(RuntimeError):
    """No operator sequence reaches the goal from this symbolic state (e.g. trapped in a closed door)."""


def plan(layout: Layout, start: SymbolicState, mode: str = "bfs", operators: str = "goto") -> list[Operator]:
    if mode not in PLAN_MODES:
        raise ValueError(f"unknown plan mode {mode!r}; expected one of {PLAN_MODES}")
    if operators not in OPERATOR_SETS:
        raise ValueError(f"unknown operator set {operators!r}; expected one of {OPERATOR_SETS}")
    return list(_plan_cached(layout, start, mode, operators))


@lru_cache(maxsize=4096)
def _plan_cached(layout: Layout, start: SymbolicState, mode: str, operators: str) -> tuple[Operator, ...]:
    if start.done(layout):
        return ()
    parents: dict[SymbolicState, tuple[SymbolicState, Operator] | None] = {start: None}
    found = None
    if mode == "bfs":
        queue = deque([start])
        while queue and found is None:
            s = queue.popleft()
            for op in applicable(layout, s, operators):
                nxt = apply(op, s)
                if nxt not in parents:
                    parents[nxt] = (s, op)
                    if nxt.done(layout):
                        found = nxt
                        break
                    queue.append(nxt)
    else:
        best = {start: 0}
        heap = [(0, 0, start)]
        counter = 0
        settled = set()
        while heap:
            cost, _, s = heapq.heappop(heap)
            if s in settled:
                continue
            settled.add(s)
            if s.done(layout):
                found = s
                break
            for op in applicable(layout, s, operators):
                nxt = apply(op, s)
                if nxt not in settled and cost + op.cost < best.get(nxt, float("inf")):
                    best[nxt] = cost + op.cost
                    parents[nxt] = (s, op)
                    counter += 1
                    heapq.heappush(heap, (cost + op.cost, counter, nxt))
    if found is None:
        raise NoPlanError(f"no plan reaches the goal from {start}")
    ops = []
    s = found
    while parents[s] is not None:
        s, op = parents[s]
        ops.append(op)
    return tuple(reversed(ops))


def plan_cost(ops: list[Operator]) -> int:
    return sum(op.cost for op in ops)


def is_valid_plan(layout: Layout, start: SymbolicState, ops: list[Operator], operators: str = "goto") -> bool:
    """Each operator applicable in turn, ending in a Done state."""
    s = start
    for op in ops:
        if op not in applicable(layout, s, operators):
            return False
        s = apply(op, s)
    return s.done(layout)
