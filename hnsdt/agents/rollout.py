"""Run a batched :class:`Agent` for one episode in every copy of a :class:`KeyDoorVectorEnv` and keep the
trajectories.

``last_subgoals`` (ids and target cells chosen by ``act``) is recorded when the agent has it, and ``executors`` (one
:class:`PlanExecutor` per copy) supply the plan, sub-goal segments and replans of each episode.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from hnsdt.envs.keydoor import N_ACTIONS
from hnsdt.envs.vector import KeyDoorVectorEnv
from hnsdt.symbolic.subgoals import NONE_ID


@dataclass
class Episode:
    states: np.ndarray  # (T+1, d) int64: s_0 .. s_T
    actions: np.ndarray  # (T,) int64
    rewards: np.ndarray  # (T,) float64
    subgoal_ids: np.ndarray  # (T,) int64, the sub-goal being pursued when a_t was chosen (0 = none)
    subgoal_targets: np.ndarray  # (T, 2) int64
    success: bool
    plan: list[str] = field(default_factory=list)
    segments: list = field(default_factory=list)
    replans: int = 0
    replan_counts: dict = field(default_factory=dict)  # replans per reason (hnsdt.agents.executor.REPLAN_REASONS)
    plans: int = 0  # the planner's calls: its first plan and every replan (0: an episode no planner drove)

    @property
    def length(self) -> int:
        return len(self.actions)

    @property
    def ret(self) -> float:
        return float(self.rewards.sum())


@runtime_checkable
class Agent(Protocol):
    """What every method's evaluated policy is (the registry's ``agent`` builds one): a batched policy over the
    copies of a vector env, called once per step for all of them."""

    def reset(self, obs: np.ndarray) -> None:
        """A new episode in every copy, from these observations."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """One action per copy (those already done are ignored)."""

    def observe(self, obs: np.ndarray, active: np.ndarray, actions: np.ndarray, rewards: np.ndarray) -> None:
        """The step's outcome: new observations, the copies live during it, what they did and got."""

    def finish(self) -> None:
        """Every copy is done."""


class RandomAgent:
    """Uniformly random actions (the paper's exploration policy)."""

    name = "random"

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)

    def reset(self, obs: np.ndarray) -> None:
        self.n = len(obs)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.rng.integers(0, N_ACTIONS, size=len(obs))

    def observe(self, obs: np.ndarray, active: np.ndarray, actions=None, rewards=None) -> None:
        pass

    def finish(self) -> None:
        pass


def rollout(env: KeyDoorVectorEnv, agent: Agent, seed: int | Sequence[int], start_states: np.ndarray | None = None,
            epsilon: float = 0.0) -> list[Episode]:
    """One episode per copy. ``epsilon`` replaces each action by a uniform one with that probability. ``seed``:
    the env's (one per equal run of copies: a sequence, :class:`hnsdt.envs.vector.Streams`)."""
    noise = np.random.default_rng([seed, 7919] if np.ndim(seed) == 0 else [*seed, 7919])
    options = {"states": start_states} if start_states is not None else None
    obs, _ = env.reset(seed=seed, options=options)
    agent.reset(obs)
    n, d, horizon = env.num_envs, obs.shape[1], env.max_steps
    states = np.zeros((horizon + 1, n, d), dtype=np.int64)
    actions = np.zeros((horizon, n), dtype=np.int64)
    rewards = np.zeros((horizon, n), dtype=np.float64)
    sub_ids = np.full((horizon, n), NONE_ID, dtype=np.int64)
    sub_targets = np.full((horizon, n, 2), -1, dtype=np.int64)
    lengths = np.zeros(n, dtype=np.int64)
    states[0] = obs
    t = 0
    while not env.done.all():
        active = ~env.done
        a = np.asarray(agent.act(obs), dtype=np.int64)
        if hasattr(agent, "last_subgoals"):
            sub_ids[t], sub_targets[t] = agent.last_subgoals
        if epsilon > 0:
            a = np.where(noise.random(n) < epsilon, noise.integers(0, N_ACTIONS, n), a)
        obs, r, _, _, _ = env.step(a)
        actions[t], rewards[t], states[t + 1] = a, r, obs
        lengths += active
        agent.observe(obs, active, a, r)
        t += 1
    agent.finish()
    executors = getattr(agent, "executors", None)
    episodes = []
    for i in range(n):
        T = int(lengths[i])
        ex = executors[i] if executors else None
        episodes.append(Episode(
            states=states[: T + 1, i].copy(), actions=actions[:T, i].copy(), rewards=rewards[:T, i].copy(),
            subgoal_ids=sub_ids[:T, i].copy(), subgoal_targets=sub_targets[:T, i].copy(),
            success=bool(env.terminated[i]),
            plan=list(ex.initial_plan) if ex else [], segments=list(ex.segments) if ex else [],
            replans=ex.replans if ex else 0, replan_counts=dict(ex.replan_counts) if ex else {},
            plans=1 + ex.replans if ex else 0,
        ))
    return episodes


def distinct_rows(*arrays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)`` of the distinct rows of the arrays side by side (each (n, ...)): the index of each
    distinct row's first occurrence, and of each row's distinct row. (As bytes: ``np.unique(axis=0)`` takes
    about 30× as long on these small tables.)"""
    n = len(arrays[0])
    key = np.concatenate([np.ascontiguousarray(a.reshape(n, -1)).view(np.uint8).reshape(n, -1) for a in arrays],
                         axis=1)
    _, first, inverse = np.unique(key.view(np.dtype((np.void, key.shape[1]))).reshape(n), return_index=True,
                                  return_inverse=True)
    return first, inverse.reshape(n)
