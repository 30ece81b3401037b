"""Key–door grid world (Case Study 1 of the paper, Appendix A.1).

Description:
    The agent must pick up a key, open the door it belongs to and reach the goal cell. Any layout (see
    :mod:`hnsdt.envs.layout`) works; the default is the paper's 5×5 single key–door grid::

        @.#.G
        ..#..
        ..A..
        ..#..
        a.#..

Actions (Discrete(5)):
    0 up, 1 right, 2 down, 3 left, 4 pick/open. A move fails with probability ``fail_prob`` and the agent
    stays; walls and grid edges block. A closed door cell can be entered but not left until the door is open
    (the paper's stochastic blocking: without the key the agent is trapped). Pick/open takes the key or item on
    the agent's cell, or opens the door on it if the agent holds that door's key; otherwise it does nothing.
    Pick/open never fails.

Observation (MultiDiscrete, int64):
    The paper's state tuple, flat: ``row, col``, then one 0/1 flag per key held (keys in letter order), per
    door open (doors in letter order) and per item collected (items in digit order).

Rewards:
    −0.1 every step, plus +1 on the step that reaches the goal holding every item.

Termination:
    Terminated on success; truncated after ``max_steps`` steps.

Registered ids:
    ``hnsdt/KeyDoor-v0`` (default layout ``keydoor_5x5``, ``max_steps=100``). Keyword arguments: ``layout``
    (a built-in name, a layout file's path or the ASCII text itself), ``fail_prob``, ``max_steps``,
    ``render_mode`` (``"ansi"`` or ``"rgb_array"``). ``reset(options={"state": obs})`` starts from any state.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hnsdt.envs.layout import MOVES, Layout, load_layout
from hnsdt.envs.render import render_ansi, render_rgb

STEP_REWARD = -0.1
GOAL_REWARD = 1.0
PICK = 4
N_ACTIONS = 5
ACTION_NAMES = ("up", "right", "down", "left", "pick/open")


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
    ):
        check_env_params(fail_prob, max_steps)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.layout = load_layout(layout if layout is not None else self.default_layout)
        self.fail_prob = float(fail_prob)
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.observation_space = observation_space_for(self.layout)
        self.action_space = gym.spaces.Discrete(N_ACTIONS)
        lay = self.layout
        self._key_index = {cell: i for i, cell in enumerate(lay.keys.values())}
        self._door_index = {cell: i for i, cell in enumerate(lay.doors.values())}
        self._item_index = {cell: i for i, cell in enumerate(lay.items.values())}
        self._door_key = [lay.door_key_index(d) for d in lay.doors]
        self._state = self._initial_state()
        self._steps = 0

    # Flags live in one vector: [keys | doors | items], offset by 2 in the observation.
    def _initial_state(self) -> np.ndarray:
        state = np.zeros(2 + self.layout.n_flags, dtype=np.int64)
        state[:2] = self.layout.start
        return state

    @property
    def state(self) -> np.ndarray:
        return self._state.copy()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._state = self._initial_state()
        if options and options.get("state") is not None:
            state = np.asarray(options["state"], dtype=np.int64)
            if state.shape != self._state.shape or not self.observation_space.contains(state):
                raise ValueError(f"reset state {state.tolist()} is not a valid observation of this layout")
            if self.layout.walls[state[0], state[1]]:
                raise ValueError(f"reset state puts the agent in a wall at {tuple(state[:2])}")
            self._state = state.copy()
        self._steps = 0
        return self._state.copy(), {"success": False}

    def step(self, action):
        action = int(action)
        if not 0 <= action < N_ACTIONS:
            raise ValueError(f"action must be in 0..{N_ACTIONS - 1}, got {action}")
        # One uniform draw every step, move or not, so the vectorised env can replay the same stream.
        move_failed = action < PICK and self.np_random.random() < self.fail_prob
        if action >= PICK:
            self.np_random.random()
        s = self._state
        cell = (int(s[0]), int(s[1]))
        nk, nd = len(self.layout.keys), len(self.layout.doors)
        if action < PICK:
            door = self._door_index.get(cell)
            trapped = door is not None and not s[2 + nk + door]
            dr, dc = MOVES[action]
            r, c = cell[0] + dr, cell[1] + dc
            h, w = self.layout.shape
            if not move_failed and not trapped and 0 <= r < h and 0 <= c < w and not self.layout.walls[r, c]:
                s[0], s[1] = r, c
        else:
            if cell in self._key_index:
                s[2 + self._key_index[cell]] = 1
            elif cell in self._item_index:
                s[2 + nk + nd + self._item_index[cell]] = 1
            elif cell in self._door_index:
                door = self._door_index[cell]
                if s[2 + self._door_key[door]]:
                    s[2 + nk + door] = 1
        self._steps += 1
        success = (int(s[0]), int(s[1])) == self.layout.goal and bool(np.all(s[2 + nk + nd :]))
        reward = STEP_REWARD + (GOAL_REWARD if success else 0.0)
        truncated = not success and self._steps >= self.max_steps
        return s.copy(), reward, success, truncated, {"success": success, "move_failed": bool(move_failed)}

    def render(self):
        if self.render_mode == "ansi":
            return render_ansi(self.layout, self._state)
        if self.render_mode == "rgb_array":
            return render_rgb(self.layout, self._state)
        return None
