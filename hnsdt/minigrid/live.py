"""Live MiniGrid envs: make one from its gymnasium id (with the paper's action failures), read its world and state.

:func:`make_env` checks the id once and wraps MiniGrid's env in :class:`ActionFailures`; :func:`read_world` turns a
freshly reset env into a :class:`World`; :func:`snapshot` reads the :class:`WorldState` of a live env, so that
MiniGrid's own stepping and :meth:`World.step` can be compared state for state.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import gymnasium as gym
import numpy as np

from hnsdt.minigrid.view import fast_observations
from hnsdt.minigrid.world import (
    CARRIABLE, CARRIED, CLOSED, GOAL, GONE, LOCKED, MOVEMENT, OPEN, OPEN_DOOR, PICKUP, Actions, Door, MiniGridError,
    Thing, World, WorldState,
)

KNOWN_CELLS = {"wall", "door", "goal", *CARRIABLE}  # what World models; anything else (lava, floor tiles) is refused


class ActionFailures(gym.Wrapper):
    """The paper's action failures on MiniGrid: each movement action (left, right, forward) fails with
    probability ``fail_prob`` and the world stays as it was — the wrapper steps MiniGrid's ``done`` action, a
    no-op that still counts a step, as a failed move counts one in our worlds. Pickup, drop and toggle never fail,
    as pick/open never fails in ours. One uniform draw every step, from a stream of its own seeded with the
    reset's seed, so that failures do not change the worlds MiniGrid generates."""

    def __init__(self, env: gym.Env, fail_prob: float):
        super().__init__(env)
        if not 0.0 <= float(fail_prob) <= 1.0:
            raise ValueError(f"fail_prob must be in [0, 1], got {fail_prob}")
        self.fail_prob = float(fail_prob)
        self._failures = np.random.default_rng()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """``options={"failure_seed": k}`` draws another failure stream on the same world (episode k of it)."""
        options = dict(options or {})
        failure_seed = int(options.pop("failure_seed", 0))
        if seed is not None:  # ("fail": a stream apart from MiniGrid's own)
            self._failures = np.random.default_rng([int(seed), failure_seed, 0x6661696C])
        return self.env.reset(seed=seed, options=options or None)

    def step(self, action):
        failed = bool(self._failures.random() < self.fail_prob) and int(action) in MOVEMENT
        obs, reward, terminated, truncated, info = self.env.step(int(Actions.done) if failed else action)
        return obs, reward, terminated, truncated, {**info, "move_failed": failed}


def check_id(env_id: str) -> None:
    """One clear line for an id that is not a MiniGrid env."""
    import minigrid  # noqa: F401  (registers MiniGrid's ids)
    from minigrid.minigrid_env import MiniGridEnv

    if env_id not in gym.registry:
        raise MiniGridError(f"{env_id!r} is not a registered gymnasium id (e.g. MiniGrid-DoorKey-8x8-v0)")
    spec = gym.registry[env_id]
    env = gym.make(spec)
    try:
        if not isinstance(env.unwrapped, MiniGridEnv):
            raise MiniGridError(f"{env_id} is not a MiniGrid env (its env is {type(env.unwrapped).__name__})")
    finally:
        env.close()


def make_env(env_id: str, fail_prob: float = 0.0, **kwargs) -> ActionFailures:
    """MiniGrid's env ``env_id`` (keyword arguments go to ``gymnasium.make``) under :class:`ActionFailures`, its
    observation computed by :func:`hnsdt.minigrid.view.gen_obs` (MiniGrid's own bytes, faster)."""
    check_id(env_id)
    return ActionFailures(fast_observations(gym.make(env_id, **kwargs)), fail_prob)


def _task(u) -> tuple[str, Any]:
    """What ends ``u``'s episodes with success, read from the env: the object its mission picks up
    (UnlockPickup, KeyCorridor, BlockedUnlockPickup), the door it opens (Unlock), or a goal cell (DoorKey)."""
    from minigrid.envs import UnlockEnv

    if isinstance(u, UnlockEnv):
        return OPEN_DOOR, u.door
    obj = getattr(u, "obj", None)
    if obj is not None and obj.type in CARRIABLE and "pick up" in str(u.mission):
        return PICKUP, obj
    if any(c is not None and c.type == "goal" for c in u.grid.grid):
        return GOAL, None
    raise MiniGridError(f"{u.spec.id if u.spec else type(u).__name__}: cannot tell what ends its episodes "
                        "(no goal cell, no door to open, no object to pick up)")


def read_world(env: gym.Env, env_id: str, seed: int) -> tuple[World, list]:
    """The :class:`World` of ``env`` just after ``reset(seed=seed)``, and the live objects in
    :attr:`World.objects`' order (what :func:`snapshot` follows)."""
    u = env.unwrapped
    walls, goals, doors, door_objs, things, live = set(), set(), [], [], [], []
    for y in range(u.height):
        for x in range(u.width):
            obj, cell = u.grid.get(x, y), (y, x)
            if obj is None:
                continue
            if obj.type not in KNOWN_CELLS:
                raise MiniGridError(f"{env_id} seed {seed}: cell type {obj.type!r} at {cell} is not modelled "
                                    f"(only {', '.join(sorted(KNOWN_CELLS))})")
            if obj.type == "wall":
                walls.add(cell)
            elif obj.type == "goal":
                goals.add(cell)
            elif obj.type == "door":
                doors.append(Door(cell, obj.color))
                door_objs.append(obj)
            else:
                if obj.type == "box" and obj.contains is not None:
                    raise MiniGridError(f"{env_id} seed {seed}: a box holding a {obj.contains.type} is not modelled")
                things.append(Thing(obj.type, obj.color))
                live.append(obj)
    if not any(t.kind == "key" for t in things) or not any(o.is_locked for o in door_objs):
        raise MiniGridError(f"{env_id} has no key and locked door: not a key-door world")
    task, target = _task(u)
    target_index = (-1 if task == GOAL else
                    next(i for i, o in enumerate(door_objs if task == OPEN_DOOR else live) if o is target))
    carrying = next((i for i, o in enumerate(live) if o is u.carrying), -1)
    start = WorldState(
        cell=(int(u.agent_pos[1]), int(u.agent_pos[0])), direction=int(u.agent_dir), carrying=carrying,
        doors=tuple(_door_state(o) for o in door_objs), objects=tuple(_cell_of(o, u) for o in live))
    world = World(env_id=env_id, seed=int(seed), shape=(u.height, u.width), walls=frozenset(walls),
                  goals=frozenset(goals), doors=tuple(doors), objects=tuple(things), task=task, target=target_index,
                  max_steps=int(u.max_steps), start=start)
    return world, live


def snapshot(world: World, env: gym.Env, live: list) -> WorldState:
    """The state of the live ``env`` in ``world``'s terms (``live``: :func:`read_world`'s objects)."""
    u = env.unwrapped
    doors = []
    for d in world.doors:
        obj = u.grid.get(d.cell[1], d.cell[0])
        doors.append(_door_state(obj))
    carrying = next((i for i, o in enumerate(live) if o is u.carrying), -1)
    return WorldState(cell=(int(u.agent_pos[1]), int(u.agent_pos[0])), direction=int(u.agent_dir),
                      carrying=carrying, doors=tuple(doors), objects=tuple(_cell_of(o, u) for o in live))


def _door_state(obj) -> int:
    return OPEN if obj.is_open else LOCKED if obj.is_locked else CLOSED


def _cell_of(obj, u) -> tuple[int, int]:
    if obj is u.carrying:
        return CARRIED
    if obj.cur_pos is not None:  # (MiniGrid keeps it for objects it placed; one set straight on the grid has none)
        x, y = (int(v) for v in obj.cur_pos)
        if 0 <= x < u.width and 0 <= y < u.height and u.grid.get(x, y) is obj:
            return (y, x)
    for i, cell in enumerate(u.grid.grid):
        if cell is obj:
            return divmod(i, u.width)
    return GONE


@dataclass(frozen=True)
class Episode:
    success: bool
    steps: int
    reward: float  # MiniGrid's
    plans: int = 0  # planner calls (the symbolic agent)
    error: str = ""  # why the policy gave up, when it did (the episode counts as failed)


@dataclass(frozen=True)
class Step:
    """One step of a traced episode, what its recording shows: MiniGrid's own drawing of the world before the
    action (the agent a triangle pointing where it faces), what the agent carries and faces, the operator it
    serves (a planning policy's), the action and its reward."""

    frame: Any  # (H, W, 3) uint8
    direction: int
    carrying: str  # "<color> <kind>" or ""
    operator: str  # "" for a policy without a plan
    action: int
    reward: float
    move_failed: bool


class GaveUp(RuntimeError):
    """A policy that cannot go on (the BabyAI bot's own errors, a planner with no plan): a failed episode."""


def run_episode(env_id: str, seed: int, fail_prob: float, failure_seed: int,
                make_policy: Callable[[World, gym.Env], Any], trace: list[Step] | None = None) -> Episode:
    """One episode of ``make_policy(world, env)`` (an object with ``act(state) -> action`` and optionally a
    ``plans`` count and a ``plan`` list of operators) on ``env_id``'s world ``seed``, with the failures drawn from
    ``failure_seed``; with a ``trace`` list, each step's :class:`Step` is appended to it and the final frame
    closes it (a step with action -1)."""
    env = make_env(env_id, fail_prob, **({"render_mode": "rgb_array", "tile_size": 16} if trace is not None else {}))
    try:
        env.reset(seed=int(seed), options={"failure_seed": int(failure_seed)})
        world, live = read_world(env, env_id, seed)
        policy = make_policy(world, env)
        steps = 0
        while True:
            state = snapshot(world, env, live)
            try:
                action = policy.act(state)
            except GaveUp as exc:
                close_trace(trace, env, world, state)
                return Episode(False, steps, 0.0, getattr(policy, "plans", 0), str(exc)[:200])
            frame = env.render() if trace is not None else None
            _, reward, terminated, truncated, info = env.step(action)
            steps += 1
            if trace is not None:
                plan = getattr(policy, "plan", None)
                trace.append(Step(frame, state.direction, carried_name(world, state), plan[0].name(world) if plan else "",
                                  int(action), float(reward), bool(info["move_failed"])))
            if terminated or truncated:
                close_trace(trace, env, world, snapshot(world, env, live))
                return Episode(bool(terminated and reward > 0), steps, float(reward), getattr(policy, "plans", 0))
    finally:
        env.close()


def carried_name(world: World, state: WorldState) -> str:
    """What the agent carries, "<colour> <kind>", or "" (a trace's and a recording's label)."""
    return world.objects[state.carrying].name if state.carrying >= 0 else ""


def close_trace(trace: list[Step] | None, env, world: World, state: WorldState) -> None:
    """End a trace (when there is one) with the final frame, a step without action."""
    if trace is not None:
        trace.append(Step(env.render(), state.direction, carried_name(world, state), "", -1, 0.0, False))


def world_of(env_id: str, seed: int) -> World:
    """The :class:`World` MiniGrid generates for ``env_id`` and ``seed``."""
    env = make_env(env_id)
    try:
        env.reset(seed=int(seed))
        return read_world(env, env_id, seed)[0]
    finally:
        env.close()
