"""Plan-following agents over a batch of environments: one :class:`PlanExecutor` per copy, and a low-level
controller (hand-written for the symbolic baseline, the decision transformer for HNSDT) chosen by subclasses."""

from __future__ import annotations

import numpy as np

from hnsdt.agents.executor import ExecutorConfig, PlanExecutor
from hnsdt.envs.layout import Layout, layout_runs


class HierarchicalAgent:
    name = "hierarchical"

    def __init__(self, layout: Layout | tuple[Layout, ...], config: ExecutorConfig | None = None):
        self.layout = layout
        self.config = config or ExecutorConfig()
        self.executors: list[PlanExecutor] = []

    def reset(self, obs: np.ndarray) -> None:
        """One executor per copy, on its map (``layout``: one, or one per equal run of copies)."""
        self.executors = [PlanExecutor(layout, self.config).start(o)
                          for layout, rows in layout_runs(self.layout, len(obs)) for o in obs[rows]]

    def observe(self, obs: np.ndarray, active: np.ndarray, actions=None, rewards=None) -> None:
        """Update the executors of the copies that were live for the step that produced ``obs``."""
        for i in np.flatnonzero(active):
            self.executors[i].observe(obs[i])

    def finish(self) -> None:
        for ex in self.executors:
            ex.finish()

    def subgoals(self) -> tuple[np.ndarray, np.ndarray]:
        """Current sub-goal ids (N,) and target cells (N, 2); id 0 / (-1, -1) where no operator is active."""
        goals = [ex.subgoal for ex in self.executors]
        return (np.array([g.id for g in goals], dtype=np.int64),
                np.array([g.target for g in goals], dtype=np.int64).reshape(-1, 2))

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions for the current operators; their sub-goals stay in ``last_subgoals`` for the caller."""
        self.last_subgoals = ids, targets = self.subgoals()
        return self.low_level(obs, ids, targets)

    def low_level(self, obs: np.ndarray, subgoal_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
        raise NotImplementedError
