"""Agents driven by a decision transformer: HNSDT (planner + executor + DT controller) and the pure DT.

Both keep, per environment copy, the last ``h`` steps of (state, action, timestep) as the model's window; the
model sees it left-padded exactly as in training. Only copies that need a decision are run through the model,
and identical windows only once: episodes of one cell start alike and stay alike until an action fails (at
fail_prob 0 all of them), which saved 45% of the evaluation's time when measured. Actions are the argmax of the action
distribution.
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

    def window(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        return {"states": self.states[rows], "actions": self.actions[rows], "timesteps": self.timesteps[rows],
                "pad": self.pad[rows]}


def _greedy(model: DecisionTransformer, inputs: dict[str, np.ndarray]) -> np.ndarray:
    """The argmax action of each row of ``inputs`` (the model's keyword arguments as arrays), running each
    distinct row through the model once."""
    n = len(inputs["actions"])
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    key = np.concatenate([np.ascontiguousarray(a.reshape(n, -1)).view(np.uint8).reshape(n, -1)
                          for a in inputs.values()], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    device = next(model.parameters()).device
    with torch.no_grad():
        logits = model(**{k: torch.from_numpy(np.ascontiguousarray(a[first])).to(device) for k, a in inputs.items()})
    return logits[:, -1].argmax(-1).cpu().numpy()[inverse.reshape(-1)]


class HNSDTAgent(HierarchicalAgent):
    """The paper's method: the symbolic plan's current operator, as ψ(o), conditions the DT."""

    def __init__(self, layout: Layout, model: DecisionTransformer, config: ExecutorConfig | None = None):
        super().__init__(layout, config)
        self.model = model
        self.history: History | None = None

    def reset(self, obs: np.ndarray) -> None:
        super().reset(obs)
        self.history = History(self.model.model_states(self.layout, obs), self.model.cfg.context)
        self._live = np.ones(len(obs), dtype=bool)

    def low_level(self, obs: np.ndarray, subgoal_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
        actions = np.full(len(obs), PICK, dtype=np.int64)  # no operator (done or trapped): a harmless no-op
        rows = np.flatnonzero((subgoal_ids > 0) & self._live)
        if len(rows):
            actions[rows] = _greedy(self.model, self.history.window(rows) | {
                "subgoal_ids": subgoal_ids[rows], "subgoal_targets": targets[rows]})
        return actions

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        rows = np.flatnonzero(active)
        if actions is not None:
            self.history.record_action(rows, np.asarray(actions))
        self.history.push(rows, self.model.model_states(self.layout, obs))
        self._live = np.asarray(active, bool).copy()
        super().observe(obs, active)


class PureDTAgent:
    """The pure decision transformer baselines, no planner, no sub-goals: conditioned on return-to-go (ours,
    ``target_return`` given) or on nothing (the paper's, ``target_return=None``)."""

    def __init__(self, model: DecisionTransformer, target_return: float | None, layout: Layout | None = None):
        self.model, self.layout = model, layout  # (a view model reads the layout around the agent)
        self.target_return = float(target_return) if target_return is not None else None

    def reset(self, obs: np.ndarray) -> None:
        h = self.model.cfg.context
        self.history = History(self.model.model_states(self.layout, obs), h)
        self.returns = np.zeros((len(obs), h), dtype=np.float32)
        self.returns[:, -1] = self.target_return or 0.0
        self._live = np.ones(len(obs), dtype=bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        actions = np.full(len(obs), PICK, dtype=np.int64)
        rows = np.flatnonzero(self._live)
        if len(rows):
            inputs = self.history.window(rows)
            if self.target_return is not None:
                inputs["returns"] = self.returns[rows]
            actions[rows] = _greedy(self.model, inputs)
        return actions

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        rows = np.flatnonzero(active)
        if actions is not None:
            self.history.record_action(rows, np.asarray(actions))
        last = self.returns[rows, -1] - (np.asarray(rewards)[rows] if rewards is not None else 0.0)
        self.returns[rows] = np.roll(self.returns[rows], -1, axis=1)
        self.returns[rows, -1] = last
        self.history.push(rows, self.model.model_states(self.layout, obs))
        self._live = np.asarray(active, bool).copy()

    def finish(self) -> None:
        pass


def make_agent(model: DecisionTransformer, meta: dict, layout: Layout, executor: ExecutorConfig,
               epsilon: float = 0.0, seed: int = 0):
    """The registry's agent factory (:mod:`hnsdt.methods`), by what conditions the model: a sub-goal token
    (HNSDT, under the plan executor), the return-to-go (target: the dataset's best return) or nothing."""
    condition = model.cfg.condition
    if condition == "subgoal":
        return HNSDTAgent(layout, model, executor)
    return PureDTAgent(model, meta["target_return"] if condition == "return" else None, layout)
