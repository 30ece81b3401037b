"""Agents driven by a decision transformer: HNSDT (planner + executor + DT controller) and the pure DT.

How a model decides depends on its formulation (:mod:`hnsdt.models.dt`). Window: per environment copy, the
last ``h`` steps of (state, action, timestep) as the model's window, left-padded exactly as in training; only
copies that need a decision are run through the model, and identical windows only once (episodes of one cell
start alike and stay alike until an action fails: at fail_prob 0 all of them). Episode: one new token per copy and
step through the model's key/value cache, copies with identical histories so far computed once (the same actions,
in less time). Actions are the argmax of the action distribution.
"""

from __future__ import annotations

import numpy as np
import torch

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.hierarchical import HierarchicalAgent
from hnsdt.agents.rollout import distinct_rows
from hnsdt.envs.keydoor import PICK
from hnsdt.envs.layout import Layout
from hnsdt.models.dt import NO_ACTION, DecisionTransformer


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
    if len(inputs["actions"]) == 0:
        return np.zeros(0, dtype=np.int64)
    first, inverse = distinct_rows(*inputs.values())
    device = next(model.parameters()).device
    with torch.no_grad():
        logits = model(**{k: torch.from_numpy(np.ascontiguousarray(a[first])).to(device) for k, a in inputs.items()})
    return logits[:, -1].argmax(-1).cpu().numpy()[inverse]


class WindowContext:
    """The window formulation's decisions: the last h steps of each copy (:class:`History`), the whole window
    through the model at every decision; returns-to-go kept per step of the window."""

    every_step = False  # a copy's steps without an operator need no decision

    def __init__(self, model: DecisionTransformer, states: np.ndarray):
        self.model, h = model, model.cfg.context
        self.history = History(states, h)
        self.returns = np.zeros((len(states), h), dtype=np.float32)

    def decide(self, rows: np.ndarray, subgoal_ids=None, subgoal_targets=None, returns=None) -> np.ndarray:
        inputs = self.history.window(rows)
        if subgoal_ids is not None:
            inputs |= {"subgoal_ids": subgoal_ids[rows], "subgoal_targets": subgoal_targets[rows]}
        if returns is not None:
            self.returns[rows, -1] = returns[rows]
            inputs["returns"] = self.returns[rows]
        return _greedy(self.model, inputs)

    def observe(self, rows: np.ndarray, actions, states: np.ndarray) -> None:
        if actions is not None:
            self.history.record_action(rows, np.asarray(actions))
        self.returns[rows] = np.roll(self.returns[rows], -1, axis=1)
        self.history.push(rows, states)


class CachedContext:
    """The episode formulation's decisions: one new token per step through the model, attending to its
    key/value cache of the last h − 1 steps (:meth:`DecisionTransformer.step`). Every live copy's step goes
    through the model (the cache must hold each step), whether its action is used or not — but copies whose
    histories are identical so far (all of a cell's at fail_prob 0; at other fail_probs until an action fails)
    share one cache row and are computed once; a row is copied when its copies' next inputs part."""

    every_step = True

    def __init__(self, model: DecisionTransformer, states: np.ndarray):
        self.model = model
        self.device = next(model.parameters()).device
        self.cache = model.start(len(states))
        self.row = np.zeros(len(states), dtype=np.int64)  # each copy's cache row (copies may share one)
        self.states = states.copy()
        self.prev = np.full(len(states), NO_ACTION, dtype=np.int64)
        self.t = np.zeros(len(states), dtype=np.int64)

    def decide(self, rows: np.ndarray, subgoal_ids=None, subgoal_targets=None, returns=None) -> np.ndarray:
        """Actions of copies ``rows``: every live copy, each step."""
        if len(rows) == 0:
            return np.zeros(0, dtype=np.int64)
        inputs = {"states": self.states[rows], "prev_actions": self.prev[rows], "timesteps": self.t[rows]}
        if subgoal_ids is not None:
            inputs |= {"subgoal_ids": subgoal_ids[rows], "subgoal_targets": subgoal_targets[rows]}
        if returns is not None:
            inputs["returns"] = returns[rows].astype(np.float32)
        first, inverse = distinct_rows(self.row[rows], *inputs.values())  # a history (its cache row) and a
        old = self.row[rows[first]]  # next token in common: one computation
        new = self._rows(old)
        moved = new != old
        if moved.any():
            self.cache.copy_rows(torch.from_numpy(old[moved]).to(self.device),
                                 torch.from_numpy(new[moved]).to(self.device))
        self.row[rows] = new[inverse]
        order = np.argsort(new)  # the model takes its cache rows sorted
        tensors = {k: torch.from_numpy(np.ascontiguousarray(v[first][order])).to(self.device)
                   for k, v in inputs.items()}
        logits = self.model.step(self.cache, torch.from_numpy(new[order]).to(self.device), **tensors)
        actions = np.empty(len(first), dtype=np.int64)
        actions[order] = logits.argmax(-1).cpu().numpy()
        return actions[inverse]

    @staticmethod
    def _rows(old: np.ndarray) -> np.ndarray:
        """The cache rows 0 … g − 1 of g histories that were at rows ``old`` (several at one row: a history that
        parts ways): the first at a row below g keeps it, the others take the free rows below g in turn (a copy
        of their old row), so the model reads the first g rows of its cache as they are, without a gather."""
        g = len(old)
        if old.max() < g and len(np.unique(old)) == g:  # (no history parted, none ended)
            return old
        _, first = np.unique(old, return_index=True)
        keep = np.zeros(g, dtype=bool)
        keep[first[old[first] < g]] = True
        new = old.copy()
        new[~keep] = np.setdiff1d(np.arange(g), old[keep])
        return new

    def observe(self, rows: np.ndarray, actions, states: np.ndarray) -> None:
        if actions is not None:
            self.prev[rows] = np.asarray(actions)[rows]
        self.t[rows] += 1
        self.states[rows] = states[rows]


def decision_context(model: DecisionTransformer, states: np.ndarray):
    """How ``model`` decides: recomputing its window, or stepping its cache."""
    return (CachedContext if model.cfg.formulation == "episode" else WindowContext)(model, states)


class HNSDTAgent(HierarchicalAgent):
    """The paper's method: the symbolic plan's current operator, as ψ(o), conditions the DT."""

    def __init__(self, layout: Layout, model: DecisionTransformer, config: ExecutorConfig | None = None):
        super().__init__(layout, config)
        self.model = model
        self.context = None

    def reset(self, obs: np.ndarray) -> None:
        super().reset(obs)
        self.context = decision_context(self.model, self.model.model_states(self.layout, obs))
        self._live = np.ones(len(obs), dtype=bool)

    def low_level(self, obs: np.ndarray, subgoal_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
        actions = np.full(len(obs), PICK, dtype=np.int64)  # no operator (done or trapped): a harmless no-op
        rows = np.flatnonzero(((subgoal_ids > 0) | self.context.every_step) & self._live)
        if len(rows):
            decided = self.context.decide(rows, subgoal_ids, targets)
            use = subgoal_ids[rows] > 0
            actions[rows[use]] = decided[use]
        return actions

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        rows = np.flatnonzero(active)
        self.context.observe(rows, actions, self.model.model_states(self.layout, obs))
        self._live = np.asarray(active, bool).copy()
        super().observe(obs, active)


class PureDTAgent:
    """The pure decision transformer baselines, no planner, no sub-goals: conditioned on return-to-go (ours,
    ``target_return`` given) or on nothing (the paper's, ``target_return=None``)."""

    def __init__(self, model: DecisionTransformer, target_return: float | None, layout: Layout | None = None):
        self.model, self.layout = model, layout  # (a view model reads the layout around the agent)
        self.target_return = float(target_return) if target_return is not None else None

    def reset(self, obs: np.ndarray) -> None:
        self.context = decision_context(self.model, self.model.model_states(self.layout, obs))
        self.returns = np.full(len(obs), self.target_return or 0.0, dtype=np.float32)  # each copy's return-to-go
        self._live = np.ones(len(obs), dtype=bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        actions = np.full(len(obs), PICK, dtype=np.int64)
        rows = np.flatnonzero(self._live)
        if len(rows):
            actions[rows] = self.context.decide(rows, returns=self.returns if self.target_return is not None
                                                else None)
        return actions

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        rows = np.flatnonzero(active)
        if rewards is not None:
            self.returns[rows] = self.returns[rows] - np.asarray(rewards)[rows]  # (in the rewards' precision)
        self.context.observe(rows, actions, self.model.model_states(self.layout, obs))
        self._live = np.asarray(active, bool).copy()

    def finish(self) -> None:
        pass


def make_agent(model: DecisionTransformer, meta: dict, layout: Layout, executor: ExecutorConfig,
               epsilon: float = 0.0, seed: int = 0):
    """The registry's agent factory (:mod:`hnsdt.core.methods`), by what conditions the model: a sub-goal token
    (HNSDT, under the plan executor), the return-to-go (target: the dataset's best return) or nothing."""
    condition = model.cfg.condition
    if condition == "subgoal":
        return HNSDTAgent(layout, model, executor)
    return PureDTAgent(model, meta["target_return"] if condition == "return" else None, layout)
