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
from hnsdt.envs.layout import Layout, layout_runs


class SymbolicAgent(HierarchicalAgent):
    def __init__(self, layout: Layout | tuple[Layout, ...], config: ExecutorConfig | None = None):
        super().__init__(layout, config)
        first = layout if isinstance(layout, Layout) else layout[0]  # (several maps: the same keys and doors)
        self.navigators = {lay: Navigator(lay) for lay in ([layout] if isinstance(layout, Layout) else layout)}
        self._door_cols = first.door_flags
        self._door_bits = 1 << np.arange(len(first.doors), dtype=np.int64)

    def low_level(self, obs: np.ndarray, subgoal_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
        masks = obs[:, self._door_cols] @ self._door_bits
        has_goal = subgoal_ids > 0
        if self.config.operators == "move":  # the target is a neighbour (Move) or the agent's own cell
            actions = step_towards(obs[:, :2], targets)
        else:
            actions = np.empty(len(obs), dtype=np.int64)
            for layout, rows in layout_runs(self.layout, len(obs)):  # each map's copies on its navigator
                navigator = self.navigators[layout]
                target_idx = navigator.target_grid[targets[rows, 0], targets[rows, 1]]  # (-1, -1) rows masked below
                actions[rows] = navigator.controller_actions(target_idx, masks[rows], obs[rows, :2])
        return np.where(has_goal, actions, PICK)  # nothing to pursue (done or trapped): a harmless no-op


def make_agent(model, meta: dict, layout: Layout, executor: ExecutorConfig, epsilon: float = 0.0,
               seed: int = 0) -> SymbolicAgent:
    """The registry's agent factory (:mod:`hnsdt.core.methods`): no model, the plan and the controllers."""
    return SymbolicAgent(layout, executor)
