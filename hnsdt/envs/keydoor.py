"""Key–door grid world (Case Study 1 of the paper, Appendix A.1).

Description:
    The agent must pick up a key, open the door it belongs to and reach the goal cell. Any layout (see
    :mod:`hnsdt.envs.layout`) works; the default is the paper's 5×5 single key–door grid::

        @.#.G
        ..#..
        ..A..
        ..#..
        a.#..

Actions (Discrete(5), :class:`hnsdt.envs.dynamics.Actions`):
    0 up, 1 right, 2 down, 3 left, 4 pick/open. The rules (:mod:`hnsdt.envs.dynamics`, shared with the vector
    env): a move fails with probability ``fail_prob`` and the agent
    stays; walls and grid edges block. A closed door cell can be entered but not left until the door is open
    (the paper's stochastic blocking: without the key the agent is trapped). Pick/open takes the key or item on
    the agent's cell, or opens the door on it if the agent holds that door's key; otherwise it does nothing.
    Pick/open never fails.

Observation (MultiDiscrete, int64):
    The paper's state tuple, flat: ``row, col``, then one 0/1 flag per key held (keys in letter order), per
    door open (doors in letter order) and per item collected (items in digit order). With ``view_radius=r``
    a ``Dict`` of that ``state`` and ``view``: the (2r+1) x (2r+1) cell codes around the agent
    (:mod:`hnsdt.envs.observation`: walls, floor, exit, keys / doors / items by identity, doors open or
    closed), which shows the world, so a learner can act on layouts it has not seen.

Rewards:
    −0.1 every step, plus +1 on the step that reaches the goal holding every item.

Termination:
    Terminated on success; truncated after ``max_steps`` steps.

Registered ids:
    ``hnsdt/KeyDoor-v0`` (default layout ``keydoor_5x5``, ``max_steps=100``). Keyword arguments: ``layout``
    (a built-in name, a layout file's path or the ASCII text itself), ``fail_prob``, ``max_steps``,
    ``render_mode`` (``"ansi"`` or ``"rgb_array"``), ``view_radius`` (``None``: the state only).
    ``reset(options={"state": state})`` starts from any state.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hnsdt.envs.dynamics import ACTION_NAMES, GOAL_REWARD, N_ACTIONS, PICK, STEP_REWARD, Actions, Rules
from hnsdt.envs.layout import Layout, load_layout
from hnsdt.envs.render import render_ansi, render_rgb

__all__ = ["ACTION_NAMES", "GOAL_REWARD", "N_ACTIONS", "PICK", "STEP_REWARD", "Actions", "KeyDoorEnv",
           "check_env_params", "observation_space_for"]


def observation_space_for(layout: Layout) -> gym.spaces.MultiDiscrete:
    h, w = layout.shape
    return gym.spaces.MultiDiscrete([h, w] + [2] * layout.n_flags, dtype=np.int64)


def check_env_params(fail_prob: float, max_steps: int) -> None:
    if not 0.0 <= float(fail_prob) <= 1.0:
        raise ValueError(f"fail_prob must be in [0, 1], got {fail_prob}")
    if int(max_steps) < 1 or int(max_steps) != max_steps:
        raise ValueError(f"max_steps must be a positive integer, got {max_steps}")


class KeyDoorEnv(gym.Env):
    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}
    default_layout = "keydoor_5x5"

    def __init__(
        self,
        layout: str | Layout | None = None,
        fail_prob: float = 0.0,
        max_steps: int = 100,
        render_mode: str | None = None,
        view_radius: int | None = None,
    ):
        check_env_params(fail_prob, max_steps)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.layout = load_layout(layout if layout is not None else self.default_layout)
        self.fail_prob = float(fail_prob)
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.view_radius = view_radius
        self.observation_space = observation_space_for(self.layout)
        if view_radius is not None:
            from hnsdt.envs.observation import N_CODES

            if int(view_radius) < 1:
                raise ValueError(f"view_radius must be >= 1 (or None), got {view_radius}")
            side = 2 * int(view_radius) + 1
            self.observation_space = gym.spaces.Dict({
                "state": self.observation_space,
                "view": gym.spaces.Box(0, N_CODES - 1, (side, side), dtype=np.int64)})
        self.action_space = gym.spaces.Discrete(N_ACTIONS)
        self.rules = Rules(self.layout)
        self._state = self.rules.initial_states(1)[0]
        self._steps = 0

    @property
    def state(self) -> np.ndarray:
        return self._state.copy()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._state = self.rules.initial_states(1)[0]
        if options and options.get("state") is not None:
            state = np.asarray(options["state"], dtype=np.int64)
            if state.shape != self._state.shape or not observation_space_for(self.layout).contains(state):
                raise ValueError(f"reset state {state.tolist()} is not a valid observation of this layout")
            if self.layout.walls[state[0], state[1]]:
                raise ValueError(f"reset state puts the agent in a wall at {tuple(state[:2])}")
            self._state = state.copy()
        self._steps = 0
        return self._observation(), {"success": False}

    def step(self, action):
        action = int(action)
        if not 0 <= action < N_ACTIONS:
            raise ValueError(f"action must be in 0..{N_ACTIONS - 1}, got {action}")
        # One uniform draw every step, move or not: with one copy, the vector env's stream for the same seed.
        u = np.array([self.np_random.random()])
        success, move_failed = self.rules.step(self._state[None], np.array([action]), u, self.fail_prob,
                                               np.ones(1, bool))
        success, move_failed = bool(success[0]), bool(move_failed[0])
        self._steps += 1
        reward = STEP_REWARD + (GOAL_REWARD if success else 0.0)
        truncated = not success and self._steps >= self.max_steps
        return self._observation(), reward, success, truncated, {"success": success, "move_failed": move_failed}

    def _observation(self):
        if self.view_radius is None:
            return self._state.copy()
        from hnsdt.envs.observation import local_view

        return {"state": self._state.copy(), "view": local_view(self.layout, self._state, self.view_radius)[0]}

    def render(self):
        if self.render_mode == "ansi":
            return render_ansi(self.layout, self._state)
        if self.render_mode == "rgb_array":
            return render_rgb(self.layout, self._state)
        return None
