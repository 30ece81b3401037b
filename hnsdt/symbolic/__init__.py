"""Stages 2–4 of Figure 1: abstraction φ, operators and the BFS planner, and the sub-goal map ψ."""

from hnsdt.symbolic.abstraction import SymbolicState, phi
from hnsdt.symbolic.operators import Operator, applicable, apply
from hnsdt.symbolic.planner import NoPlanError, is_valid_plan, plan, plan_cost
from hnsdt.symbolic.subgoals import ID_TO_NAME, NAME_TO_ID, NO_SUBGOAL, VOCAB_SIZE, SubGoal, psi, subgoal_id

__all__ = [
    "ID_TO_NAME", "NAME_TO_ID", "NO_SUBGOAL", "NoPlanError", "Operator", "SubGoal", "SymbolicState", "VOCAB_SIZE",
    "applicable", "apply", "is_valid_plan", "phi", "plan", "plan_cost", "psi", "subgoal_id",
]
