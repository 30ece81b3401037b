"""The symbolic baseline of the paper: the BFS plan executed by hand-written controllers.

Each operator's target cell is reached along a shortest path (through walls and open doors), recomputed from the
current cell after every step so failed moves are retried; interaction operators then pick or open. With the
paper's one-cell ``Move`` operators (``operators: move``) the controller steps towards the operator's target.
"""

from __future__ import annotations

import numpy as np

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.hierarchical import HierarchicalAgent
from hnsdt.agents.navigation import Navigator, step_towards
from hnsdt.envs.keydoor import PICK
from hnsdt.envs.layout import Layout


class SymbolicAgent(HierarchicalAgent):
    def __init__(self, layout: Layout, config: ExecutorConfig | None = None):
        super().__init__(layout, config)
        self.navigator = Navigator(layout)
        self._door_cols = layout.door_flags
        self._door_bits = 1 << np.arange(len(layout.doors), dtype=np.int64)

    def low_level(self, obs: np.ndarray, subgoal_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
        masks = obs[:, self._door_cols] @ self._door_bits
        has_goal = subgoal_ids > 0
        if self.config.operators == "move":  # the target is a neighbour (Move) or the agent's own cell
            actions = step_towards(obs[:, :2], targets)
        else:
            target_idx = self.navigator.target_grid[targets[:, 0], targets[:, 1]]  # (-1, -1) rows masked below
            actions = self.navigator.controller_actions(target_idx, masks, obs[:, :2])
        return np.where(has_goal, actions, PICK)  # nothing to pursue (done or trapped): a harmless no-op


def make_agent(model, meta: dict, layout: Layout, executor: ExecutorConfig, epsilon: float = 0.0,
               seed: int = 0) -> SymbolicAgent:
    """The registry's agent factory (:mod:`hnsdt.core.methods`): no model, the plan and the controllers."""
    return SymbolicAgent(layout, executor)
