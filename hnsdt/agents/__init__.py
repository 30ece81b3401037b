"""Stage 5 of Figure 1: agents that act in batches of environments (the baselines' own: :mod:`hnsdt.baselines`)."""

from hnsdt.agents.executor import ExecutorConfig, PlanExecutor
from hnsdt.agents.hierarchical import HierarchicalAgent
from hnsdt.agents.navigation import Navigator
from hnsdt.agents.rollout import Episode, rollout
from hnsdt.agents.symbolic import SymbolicAgent

__all__ = ["Episode", "ExecutorConfig", "HierarchicalAgent", "Navigator", "PlanExecutor", "SymbolicAgent",
           "rollout"]
