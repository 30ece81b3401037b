"""The hybrid executor's bookkeeping, shared by every plan-following agent (symbolic baseline, HNSDT).

Plan from φ(s₀); execute one operator at a time; when φ(s) ⊇ eff(o) move to the next; when the operator
overruns its step allowance, the plan runs out, or the rest of the plan's preconditions no longer hold, replan
from φ(s). The low-level controller that turns the current operator into actions is the agent's business.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from hnsdt.envs.layout import Layout
from hnsdt.symbolic.abstraction import SymbolicState
from hnsdt.symbolic.operators import Operator
from hnsdt.symbolic.planner import NoPlanError, is_valid_plan, plan
from hnsdt.symbolic.subgoals import NO_SUBGOAL, SubGoal, psi


@dataclass
class Segment:
    """One operator's execution: steps [start, end) of the episode."""

    operator: str
    subgoal_id: int
    start: int
    end: int | None = None
    achieved: bool = False
    outcome: str = ""  # "achieved", a replan's reason ("overran", "broken"), or "ended" (the episode ended first)


# Why the executor replans: the operator took more than its allowance; the rest of the plan's preconditions no
# longer hold (a failed or wrong step broke them); the plan ran out before the goal.
REPLAN_REASONS = {"overran": "overran {op}", "broken": "preconditions broken at {op}", "exhausted": "plan exhausted"}


@dataclass
class ExecutorConfig:
    plan_mode: str = "cost"  # "bfs" = fewest operators (the paper's BFS), "cost" = fewest expected steps
    operators: str = "goto"  # "goto" = GoTo macro-operators (ours), "move" = the paper's one-cell Move operators
    allowance_factor: float = 3.0  # an operator may take this many times its nominal cost ...
    allowance_min: int = 6  # ... but never fewer steps than this before a replan


@lru_cache(maxsize=65536)
def _still_valid(layout: Layout, state: SymbolicState, ops: tuple[Operator, ...], operators: str) -> bool:
    return is_valid_plan(layout, state, list(ops), operators)


@dataclass
class PlanExecutor:
    layout: Layout
    config: ExecutorConfig = field(default_factory=ExecutorConfig)
    plan: list[Operator] = field(default_factory=list)
    index: int = 0
    t: int = 0
    op_start: int = 0
    replans: int = 0
    stuck: bool = False  # no plan exists any more (e.g. trapped in a closed door without its key)
    initial_plan: list[str] = field(default_factory=list)
    segments: list[Segment] = field(default_factory=list)
    replan_reasons: list[str] = field(default_factory=list)  # "t:reason", in the words of REPLAN_REASONS
    replan_counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(REPLAN_REASONS, 0))

    @property
    def operator(self) -> Operator | None:
        return self.plan[self.index] if self.index < len(self.plan) else None

    @property
    def subgoal(self) -> SubGoal:
        op = self.operator
        return psi(op) if op is not None else NO_SUBGOAL

    def allowance(self, op: Operator) -> int:
        return max(self.config.allowance_min, math.ceil(self.config.allowance_factor * op.cost))

    def start(self, obs: np.ndarray) -> "PlanExecutor":
        self.t = 0
        self._replan(SymbolicState.from_observation(self.layout, obs), reason=None)
        self.initial_plan = [op.name for op in self.plan]
        return self

    def _open_segment(self) -> None:
        self.op_start = self.t
        op = self.operator
        if op is not None:
            self.segments.append(Segment(op.name, psi(op).id, self.t))

    def _close_segment(self, outcome: str) -> None:
        if self.segments and self.segments[-1].end is None:
            self.segments[-1].end = self.t
            self.segments[-1].achieved = outcome == "achieved"
            self.segments[-1].outcome = outcome

    def _replan(self, state: SymbolicState, reason: str | None) -> None:
        if reason is not None:
            self._close_segment(reason)
            self.replans += 1
            self.replan_counts[reason] += 1
            op = self.operator
            self.replan_reasons.append(f"{self.t}:" + REPLAN_REASONS[reason].format(op=op.name if op else ""))
        try:
            self.plan = plan(self.layout, state, self.config.plan_mode, self.config.operators)
            self.stuck = False
        except NoPlanError:
            self.plan, self.stuck = [], True
        self.index = 0
        self._open_segment()

    def observe(self, obs: np.ndarray) -> Operator | None:
        """Account for one environment step that led to ``obs``; returns the operator to pursue next."""
        self.t += 1
        state = SymbolicState.from_observation(self.layout, obs)
        if self.stuck:
            return None
        preds = state.predicates(self.layout)
        advanced = False
        while self.operator is not None and self.operator.achieved(preds):
            self._close_segment("achieved")
            self.index += 1
            advanced = True
            self._open_segment()
        if state.done(self.layout):
            return None
        op = self.operator
        if op is None:
            self._replan(state, "exhausted")
        elif not advanced and self.t - self.op_start > self.allowance(op):
            self._replan(state, "overran")
        elif not _still_valid(self.layout, state, tuple(self.plan[self.index:]), self.config.operators):
            self._replan(state, "broken")
        return self.operator

    def finish(self) -> None:
        self._close_segment("ended")
