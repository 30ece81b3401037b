"""Sub-goal segmentation of trajectories.

A segment ends where φ gains an operator's effects. For a plan-following behaviour the operator being executed
is known (the executor's). For random exploration it is not, so segments are labelled in hindsight: every
transition that gains a key, door or item ends a PickKey / OpenDoor / PickItem segment of one frame or more,
and every arrival on a relevant object cell (a key not held, a closed door, an item not held, the exit holding
all items) ends a GoTo segment. The frames since the previous event carry that operator's sub-goal; frames
after the last event serve no sub-goal (id 0).

With the paper's ``move`` operators (Appendix B) the events are finer: every change of cell ends a
``Move(c → c')`` segment, and the PickKey / OpenDoor / PickItem events stay as above.
"""

from __future__ import annotations

import numpy as np

from hnsdt.envs.layout import Layout
from hnsdt.symbolic.abstraction import SymbolicState
from hnsdt.symbolic.operators import (
    GOTO_DOOR, GOTO_EXIT, GOTO_ITEM, GOTO_KEY, OPEN_DOOR, OPERATOR_SETS, PICK_ITEM, PICK_KEY, Operator, goto,
    interaction, move,
)
from hnsdt.symbolic.subgoals import NONE_ID, psi


def achieved_operator(layout: Layout, before: SymbolicState, after: SymbolicState,
                      operators: str = "goto") -> Operator | None:
    """The operator of the set ``operators`` whose effects the transition before → after gained, if any."""
    for k in sorted(after.keys - before.keys):
        return interaction(layout, PICK_KEY, k)
    for d in sorted(after.doors - before.doors):
        return interaction(layout, OPEN_DOOR, d)
    for i in sorted(after.items - before.items):
        return interaction(layout, PICK_ITEM, i)
    if after.cell == before.cell:
        return None
    if operators == "move":
        return move(before.cell, after.cell)
    cell = after.cell
    for k, c in layout.keys.items():
        if c == cell and k not in before.keys:
            return goto(GOTO_KEY, k, c, 0)
    for d, c in layout.doors.items():
        if c == cell and d not in before.doors:
            return goto(GOTO_DOOR, d, c, 0)
    for i, c in layout.items.items():
        if c == cell and i not in before.items:
            return goto(GOTO_ITEM, i, c, 0)
    if cell == layout.goal and before.items >= set(layout.items):
        return goto(GOTO_EXIT, "exit", cell, 0)
    return None


def hindsight_labels(layout: Layout, states: np.ndarray, operators: str = "goto") -> tuple[np.ndarray, np.ndarray]:
    """Sub-goal ids (T,) and target cells (T, 2) for the T transitions of ``states`` (T+1 rows), segmented by
    the operator set ``operators``."""
    if operators not in OPERATOR_SETS:
        raise ValueError(f"unknown operator set {operators!r}; expected one of {OPERATOR_SETS}")
    T = len(states) - 1
    ids = np.full(T, NONE_ID, dtype=np.int64)
    targets = np.full((T, 2), -1, dtype=np.int64)
    syms = [SymbolicState.from_observation(layout, s) for s in states]
    start = 0
    for t in range(T):
        op = achieved_operator(layout, syms[t], syms[t + 1], operators)
        if op is not None:
            g = psi(op)
            ids[start : t + 1] = g.id
            targets[start : t + 1] = g.target
            start = t + 1
    return ids, targets


def segments_of(ids: np.ndarray) -> list[tuple[int, int, int]]:
    """Runs of equal sub-goal ids as (subgoal_id, start, end) with ``end`` exclusive."""
    runs = []
    start = 0
    for t in range(1, len(ids) + 1):
        if t == len(ids) or ids[t] != ids[start]:
            runs.append((int(ids[start]), start, t))
            start = t
    return runs
