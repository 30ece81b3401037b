"""The learner's own states, labelled by the planner (DAgger, Ross et al. 2011): a trained executor acts on the
training layouts, and each step it took is labelled with the action the hand-written controller would have taken
there towards the same sub-goal — so the next training round sees the states the learner's own mistakes lead to,
with the way back out of them. One round: collect with the trained model, add the frames, train again. A learner
without a planner (the pure DT) is labelled with the planner's first sub-goal from each state it visited: the
symbolic baseline's action there.

Simplification, named: a relabelled episode's actions are the controller's, also where they are read as the
previous action of the next step's token; the states are the ones the learner's own actions led to.
"""

from __future__ import annotations

import numpy as np

from hnsdt.agents.executor import ExecutorConfig
from hnsdt.agents.rollout import rollout
from hnsdt.agents.symbolic import SymbolicAgent
from hnsdt.data.collect import random_start_states
from hnsdt.envs.dynamics import Rules
from hnsdt.envs.observation import view_states
from hnsdt.envs.vector import KeyDoorVectorEnv
from hnsdt.implementations import code_of, resolve
from hnsdt.models.windows import Frames, frames_from_arrays

RELABELLED = "relabelled"  # the behaviour name of the learner's relabelled episodes (``Frames.policy``)


def learner_frames(model, method: str, facts: dict, layouts: list, executor: ExecutorConfig, view_radius: int,
                   max_steps: int, fail_probs: list[float], episodes: int, seed: int) -> Frames:
    """``episodes`` episodes of ``method``'s trained ``model`` on each layout (half from its start, half from
    random states; spread over ``fail_probs``), as view frames whose actions are the controller's towards each
    step's sub-goal (the planner's operator the learner was executing; for a learner without a planner, the
    planner's first operator from that step's state). Seeded by ``seed``."""
    if getattr(model.cfg, "whole_map", False):  # (its frames would need the dataset's map square)
        raise ValueError("relabelling (DAgger) does not support a model that reads the whole map (whole_map)")
    arrays: dict[str, list] = {k: [] for k in ("states", "actions", "rewards", "ids", "targets", "episode", "t")}
    make_agent = resolve(code_of(method).agent)
    n_episodes = 0
    for li, layout in enumerate(layouts):
        expert = SymbolicAgent(layout, executor)
        for fi, fail_prob in enumerate(fail_probs):
            n = episodes // len(fail_probs) + (fi < episodes % len(fail_probs))
            if n == 0:
                continue
            batch_seed = int(np.random.SeedSequence([seed, li, fi, 6113]).generate_state(1)[0])
            starts = np.vstack([Rules(layout).initial_states(n - n // 2),
                                random_start_states(layout, n // 2, np.random.default_rng(batch_seed))])
            env = KeyDoorVectorEnv(n, layout, fail_prob, max_steps)
            agent = make_agent(model, facts, layout, executor)
            for ep in rollout(env, agent, batch_seed, starts):
                T = ep.length
                if hasattr(agent, "executors"):  # it pursued the planner's sub-goals
                    ids, targets = ep.subgoal_ids, ep.subgoal_targets
                else:  # the planner's first sub-goal from each state it visited
                    expert.reset(ep.states[:T])
                    ids, targets = expert.subgoals()
                arrays["states"].append(view_states(layout, ep.states[:T], view_radius))
                arrays["actions"].append(expert.low_level(ep.states[:T], ids, targets))
                arrays["rewards"].append(ep.rewards)
                arrays["ids"].append(ids)
                arrays["targets"].append(targets)
                arrays["episode"].append(np.full(T, n_episodes))
                arrays["t"].append(np.arange(T))
                n_episodes += 1
    cat = {k: np.concatenate(v) for k, v in arrays.items()}
    return frames_from_arrays(cat["states"], cat["actions"], cat["rewards"], cat["ids"], cat["targets"],
                              cat["episode"], cat["t"], [RELABELLED] * len(cat["t"]))


def join_frames(first: Frames, second: Frames) -> Frames:
    """``first``'s frames, then ``second``'s, its episodes numbered after ``first``'s."""
    offset = int(first.episode.max()) + 1 if len(first) else 0
    inputs = ("states", "actions", "rewards", "subgoals", "targets", "episode", "timestep", "policy")
    both = {f: np.concatenate([getattr(first, f), getattr(second, f)]) for f in inputs}
    both["episode"][len(first):] += offset
    return frames_from_arrays(*(both[f] for f in inputs))  # (episode starts and returns-to-go derived again)
