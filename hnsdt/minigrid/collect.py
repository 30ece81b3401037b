"""Episodes for the learners on MiniGrid's own worlds: the symbolic agent with random actions mixed in, played in
MiniGrid's env, each frame labelled with the operator it serves (the sub-goal segmentation).

The behaviour is the paper's noisy planner: with probability ``epsilon`` a uniformly random action of the six
that do something (done excluded), else the symbolic agent's (:class:`SymbolicAgent`: plan, controllers,
replanning). A frame's sub-goal is the operator at the head of the agent's plan when it acted — random actions
included, as in our worlds' noisy-planner episodes; ``none`` once the mission is done. Each frame keeps what a
learner may read (MiniGrid's own 7 × 7 egocentric view and direction, what the agent carries) and the true
state the planner reads (cell and direction), the action, MiniGrid's reward and the sub-goal: its kind, its
cell and its object (MiniGrid's type and colour indices).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from hnsdt.minigrid.controllers import SymbolicAgent
from hnsdt.minigrid.live import GaveUp, make_env, read_world, snapshot
from hnsdt.minigrid.operators import DROP, GOTO_GOAL, GOTO_DOOR, KINDS, OPEN_IT, Operator
from hnsdt.minigrid.world import Actions, World, WorldState

RANDOM_ACTIONS = (Actions.left, Actions.right, Actions.forward, Actions.pickup, Actions.drop, Actions.toggle)
SUBGOAL_NAMES = ("none", *KINDS)  # a frame's sub-goal kind: its index here (0 = none)
STATE_NAMES = ("row", "col", "direction", "carrying_type", "carrying_color")


def _indices(kind: str, color: str) -> tuple[int, int]:
    from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX

    return OBJECT_TO_IDX[kind], COLOR_TO_IDX[color]


def subgoal_object(world: World, op: Operator | None) -> tuple[int, int]:
    """The MiniGrid (type, colour) indices of what ``op`` is about: its object, its door, the goal; (0, 0) for a
    Drop or no operator."""
    if op is None or op.kind == DROP:
        return 0, 0
    if op.kind == GOTO_GOAL:
        return _indices("goal", "green")  # (MiniGrid's goal is green)
    if op.kind in (GOTO_DOOR, OPEN_IT):
        return _indices("door", world.doors[op.index].color)
    thing = world.objects[op.index]
    return _indices(thing.kind, thing.color)


def state_vector(world: World, s: WorldState) -> list[int]:
    """A frame's ``observation.state`` (:data:`STATE_NAMES`): the agent's cell and direction, what it carries."""
    carried = world.objects[s.carrying] if s.carrying >= 0 else None
    return [*s.cell, s.direction, *(_indices(carried.kind, carried.color) if carried else (0, 0))]


def subgoal_of(world: World, op: Operator | None) -> tuple[int, list[int]]:
    """A frame's sub-goal: its kind's index in :data:`SUBGOAL_NAMES` and ``(row, col, type, colour)``, its target
    cell (-1, -1: none) and its object (:func:`subgoal_object`)."""
    return (SUBGOAL_NAMES.index(op.kind) if op else 0,
            [*(op.cell if op else (-1, -1)), *subgoal_object(world, op)])


def noisy_episode(env_id: str, seed: int, fail_prob: float, failure_seed: int, epsilon: float,
                  rng: np.random.Generator) -> dict:
    """One labelled episode of the noisy symbolic agent on ``env_id``'s world ``seed``."""
    env = make_env(env_id, fail_prob)
    try:
        obs, _ = env.reset(seed=int(seed), options={"failure_seed": int(failure_seed)})
        world, live = read_world(env, env_id, seed)
        agent = SymbolicAgent(world)
        ep = {k: [] for k in ("views", "states", "actions", "rewards", "subgoals", "targets", "objects", "names")}
        success, gave_up = False, ""
        while True:
            s = snapshot(world, env, live)
            try:
                planned = agent.act(s)
            except GaveUp as exc:  # (a random toggle opened the box to pick up: nothing left to plan)
                gave_up = str(exc)
                break
            op = agent.plan[0] if agent.plan else None
            action = int(rng.choice(RANDOM_ACTIONS)) if rng.random() < epsilon else planned
            kind, target = subgoal_of(world, op)
            ep["views"].append(np.asarray(obs["image"], np.int64).reshape(-1))
            ep["states"].append(state_vector(world, s))
            ep["actions"].append(action)
            ep["subgoals"].append(kind)
            ep["targets"].append(target[:2])
            ep["objects"].append(target[2:])
            ep["names"].append(op.name(world) if op else "none")
            obs, reward, terminated, truncated, _ = env.step(action)
            ep["rewards"].append(float(reward))
            if terminated or truncated:
                success = bool(terminated and reward > 0)
                break
    finally:
        env.close()
    out = {k: np.asarray(v) for k, v in ep.items() if k != "names"}
    out["names"] = ep["names"]
    out["success"] = success
    out["meta"] = dict(env_id=env_id, world_seed=int(seed), fail_prob=float(fail_prob),
                       failure_seed=int(failure_seed), epsilon=float(epsilon), success=success,
                       steps=len(ep["actions"]), reward=float(sum(ep["rewards"])), plans=agent.plans,
                       gave_up=gave_up)
    return out


def collect_episodes(env_id: str, world_seeds: Iterable[int], fail_probs: Iterable[float], episodes_per_world: int,
                     epsilon: float, seed: int, progress: bool = False) -> list[dict]:
    """``episodes_per_world`` episodes per world and fail_prob, in order (world, fail_prob, episode); the random
    actions of each drawn from its own stream, so an episode depends only on its own coordinates."""
    from tqdm import tqdm

    seeds, fail_probs = [int(s) for s in world_seeds], [float(p) for p in fail_probs]
    episodes = []
    for w in tqdm(seeds, desc=f"collect {env_id}", unit="world", disable=not progress):
        for f, p in enumerate(fail_probs):
            for k in range(episodes_per_world):
                rng = np.random.default_rng([int(seed), w, f, k])
                ep = noisy_episode(env_id, w, p, k, epsilon, rng)
                if len(ep["actions"]):  # (an episode whose very first act gave up has no frame)
                    episodes.append(ep)
    return episodes
