"""A validation measure by acting, for training to a plateau: the method's own agent walked from start states
no training episode contains (:class:`StepsToExit`)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from hnsdt.implementations import code_of, resolve


@dataclass(frozen=True)
class Course:
    """Start states on one map, for :class:`StepsToExit`."""

    layout: Any
    max_steps: int
    starts: np.ndarray  # (n, d) environment states


@dataclass(frozen=True)
class StepsToExit:
    """A validation measure by acting (``train.validation.<method>.measure: steps``): the mean episode length of
    the method's own agent from its start states at fail_prob 0, a failure counting the step limit. Lower is
    better; it reads the success and the steps the evaluation reports, on states no training episode contains:
    drawn from the held-out episodes of the method's map (:meth:`from_held_out`), or on validation layouts no
    training episode saw (:meth:`on_layouts`, the unseen-layout experiment). Deterministic: greedy agents, no
    failures. Its ``floor`` is the exact optimum's mean from the same states: no model can do better, so a
    model that reaches it ends training (:class:`hnsdt.models.fit.Validation`); its ``ceiling`` that of a model
    that never reaches the exit."""

    method: str
    executor: Any  # the method's ExecutorConfig
    facts: dict  # the checkpoint's facts the agent reads (the pure DT's target return)
    courses: tuple[Course, ...]
    name: str = "steps"

    @cached_property  # (a seed resumed epoch by epoch builds its Validation, which reads it, once per part)
    def floor(self) -> float:
        from hnsdt.envs.oracle import mdp_for

        return float(np.mean(np.concatenate([mdp_for(c.layout).fewest_steps(c.starts, c.max_steps)
                                             for c in self.courses])))

    @property
    def ceiling(self) -> float:
        """The value of a model that reaches the exit from no start: every start's step limit. A model whose
        evaluations all had it is at no plateau (:class:`hnsdt.models.fit.Validation`)."""
        return float(np.mean(np.concatenate([np.full(len(c.starts), c.max_steps, np.float64)
                                             for c in self.courses])))

    @classmethod
    def from_held_out(cls, frames, held_out: np.ndarray, n: int, method: str, env, executor,
                      facts: dict) -> "StepsToExit":
        """``n`` distinct states of the held-out frames (fixed draw) from which the planner reaches the exit
        (``env``: the map's :class:`hnsdt.compose.config.EnvSpec`)."""
        solvable = _solvable(env.layout, np.unique(frames.states[held_out], axis=0), executor)
        if not len(solvable):
            raise ValueError(f"{method} on {env.name}: no held-out state from which the exit can be reached; "
                             "raise train.validation.<method>.share")
        pick = np.random.default_rng(0).choice(len(solvable), size=min(n, len(solvable)), replace=False)
        return cls(method, executor, facts, (Course(env.layout, env.max_steps, solvable[np.sort(pick)]),))

    @classmethod
    def on_layouts(cls, layouts: list, max_steps: int, n: int, method: str, executor, facts: dict) -> "StepsToExit":
        """About ``n`` start states spread over ``layouts``: each layout's start, then distinct random states
        (fixed draw, as the collection's random starts) from which the planner reaches the exit."""
        from hnsdt.data.collect import random_start_states
        from hnsdt.envs.dynamics import Rules

        per_layout = max(1, -(-n // len(layouts)))
        courses = []
        for i, layout in enumerate(layouts):
            drawn = random_start_states(layout, 4 * per_layout, np.random.default_rng([i, 4099]))
            states = _solvable(layout, np.vstack([Rules(layout).initial_states(1), drawn]), executor)
            _, first = np.unique(states, axis=0, return_index=True)  # distinct, in draw order (the start first)
            courses.append(Course(layout, max_steps, states[np.sort(first)[:per_layout]]))
        return cls(method, executor, facts, tuple(courses))

    def __call__(self, model) -> float:
        from itertools import groupby

        from hnsdt.agents.rollout import rollout
        from hnsdt.envs.vector import KeyDoorVectorEnv

        lengths = []  # consecutive maps with as many starts and the same limit act as one batch, side by side
        for (max_steps, _), run in groupby(self.courses, key=lambda c: (c.max_steps, len(c.starts))):
            run = list(run)
            layout = run[0].layout if len(run) == 1 else tuple(c.layout for c in run)
            starts = np.concatenate([c.starts for c in run])
            agent = resolve(code_of(self.method).agent)(model, self.facts, layout, self.executor)
            env = KeyDoorVectorEnv(len(starts), layout, 0.0, max_steps)
            lengths += [e.length if e.success else max_steps for e in rollout(env, agent, 0, starts)]
        return float(np.mean(lengths))


def _solvable(layout, states: np.ndarray, executor) -> np.ndarray:
    """The states from which the method's planner finds a plan to the exit."""
    from hnsdt.symbolic import NoPlanError, SymbolicState, plan

    keep = []
    for s in states:
        try:
            plan(layout, SymbolicState.from_observation(layout, s), executor.plan_mode, executor.operators)
            keep.append(True)
        except NoPlanError:
            keep.append(False)
    return states[np.array(keep, dtype=bool)]
