"""Agents driven by a decision transformer: HNSDT (planner + executor + DT controller) and the pure DT.

Both keep, per environment copy, the last ``h`` steps of (state, action, timestep) as the model's window; the
model sees it left-padded exactly as in training. Only copies that need a decision are run through the model.
Actions are the argmax of the action distribution.
"""

from __future__ import annotations

import numpy as np
import torch

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.hierarchical import HierarchicalAgent
from hnsdt.envs.keydoor import PICK
from hnsdt.envs.layout import Layout
from hnsdt.models.dt import DecisionTransformer


class History:
    """Sliding windows of the last h steps for N copies: states, actions, timesteps, padding."""

    def __init__(self, obs: np.ndarray, h: int):
        n, d = obs.shape
        self.states = np.zeros((n, h, d), dtype=np.int64)
        self.actions = np.zeros((n, h), dtype=np.int64)
        self.timesteps = np.zeros((n, h), dtype=np.int64)
        self.pad = np.ones((n, h), dtype=bool)
        self.t = np.zeros(n, dtype=np.int64)
        self.states[:, -1], self.pad[:, -1] = obs, False

    def record_action(self, rows: np.ndarray, actions: np.ndarray) -> None:
        self.actions[rows, -1] = actions[rows]

    def push(self, rows: np.ndarray, obs: np.ndarray) -> None:
        """Shift the windows of ``rows`` one step and append the new state (its action comes later)."""
        for arr in (self.states, self.actions, self.timesteps, self.pad):
            arr[rows] = np.roll(arr[rows], -1, axis=1)
        self.t[rows] += 1
        self.states[rows, -1] = obs[rows]
        self.actions[rows, -1] = 0
        self.timesteps[rows, -1] = self.t[rows]
        self.pad[rows, -1] = False

    def batch(self, rows: np.ndarray, device) -> dict:
        take = lambda a: torch.from_numpy(np.ascontiguousarray(a[rows])).to(device)  # noqa: E731
        return {"states": take(self.states), "actions": take(self.actions), "timesteps": take(self.timesteps),
                "pad": take(self.pad)}


def _greedy(model: DecisionTransformer, batch: dict, **cond) -> np.ndarray:
    with torch.no_grad():
        logits = model(batch["states"], batch["actions"], batch["timesteps"], batch["pad"], **cond)
    return logits[:, -1].argmax(-1).cpu().numpy()


class HNSDTAgent(HierarchicalAgent):
    """The paper's method: the symbolic plan's current operator, as ψ(o), conditions the DT."""

    name = "hnsdt"

    def __init__(self, layout: Layout, model: DecisionTransformer, config: ExecutorConfig | None = None):
        super().__init__(layout, config)
        self.model = model
        self.device = next(model.parameters()).device
        self.history: History | None = None

    def reset(self, obs: np.ndarray) -> None:
        super().reset(obs)
        self.history = History(obs, self.model.cfg.context)
        self._live = np.ones(len(obs), dtype=bool)

    def low_level(self, obs: np.ndarray, subgoal_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
        actions = np.full(len(obs), PICK, dtype=np.int64)  # no operator (done or trapped): a harmless no-op
        rows = np.flatnonzero((subgoal_ids > 0) & self._live)
        if len(rows):
            batch = self.history.batch(rows, self.device)
            actions[rows] = _greedy(self.model, batch,
                                    subgoal_ids=torch.from_numpy(subgoal_ids[rows]).to(self.device),
                                    subgoal_targets=torch.from_numpy(targets[rows]).to(self.device))
        return actions

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        rows = np.flatnonzero(active)
        if actions is not None:
            self.history.record_action(rows, np.asarray(actions))
        self.history.push(rows, obs)
        self._live = np.asarray(active, bool).copy()
        super().observe(obs, active)


class PureDTAgent:
    """The pure decision transformer baseline: conditioned on return-to-go, no planner, no sub-goals."""

    name = "pure_dt"

    def __init__(self, model: DecisionTransformer, target_return: float):
        self.model = model
        self.target_return = float(target_return)
        self.device = next(model.parameters()).device

    def reset(self, obs: np.ndarray) -> None:
        h = self.model.cfg.context
        self.history = History(obs, h)
        self.returns = np.zeros((len(obs), h), dtype=np.float32)
        self.returns[:, -1] = self.target_return
        self._live = np.ones(len(obs), dtype=bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        actions = np.full(len(obs), PICK, dtype=np.int64)
        rows = np.flatnonzero(self._live)
        if len(rows):
            batch = self.history.batch(rows, self.device)
            actions[rows] = _greedy(self.model, batch, returns=torch.from_numpy(self.returns[rows]).to(self.device))
        return actions

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        rows = np.flatnonzero(active)
        if actions is not None:
            self.history.record_action(rows, np.asarray(actions))
        last = self.returns[rows, -1] - (np.asarray(rewards)[rows] if rewards is not None else 0.0)
        self.returns[rows] = np.roll(self.returns[rows], -1, axis=1)
        self.returns[rows, -1] = last
        self.history.push(rows, obs)
        self._live = np.asarray(active, bool).copy()

    def finish(self) -> None:
        pass
