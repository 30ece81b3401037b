"""MiniGrid's own observation, the same bytes in less time: :func:`gen_obs` is ``MiniGridEnv.gen_obs`` (the 7 × 7
egocentric view with walls hiding what is behind them, the carried object shown at the agent's cell, the direction,
the mission) computed on plain lists, without the four ``Grid`` copies MiniGrid makes for each step (a slice, up to
four quarter turns) — about half of a MiniGrid step's time. :func:`fast_observations` installs it on one env.

Nothing of the world's rules is computed here: it reads MiniGrid's grid, the agent's position and direction and
what it carries, and applies MiniGrid's own ``get_view_exts``, ``see_behind`` and ``encode``. The test
(``tests/test_minigrid.py``) steps many MiniGrid envs at random with both and fails on any byte that differs.
"""

from __future__ import annotations

import types

import gymnasium as gym
import numpy as np
from minigrid.core.constants import OBJECT_TO_IDX
from minigrid.core.world_object import Wall

_OUTSIDE = Wall()  # what MiniGrid's slice puts beyond the grid's edge (a new Wall() each time: the same encoding)
_EMPTY = (OBJECT_TO_IDX["empty"], 0, 0)
_UNSEEN = (0, 0, 0)


def gen_obs(env) -> dict:
    """``MiniGridEnv.gen_obs`` of the unwrapped ``env`` (which must not see through walls)."""
    n = env.agent_view_size
    top_x, top_y, _, _ = env.get_view_exts(n)
    width, height, cells = env.grid.width, env.grid.height, env.grid.grid
    # view[i][j]: the object at the slice's column i, row j (MiniGrid's Grid.get(i, j))
    view = [[cells[(top_y + j) * width + top_x + i] if 0 <= top_x + i < width and 0 <= top_y + j < height
             else _OUTSIDE for j in range(n)] for i in range(n)]
    for _ in range((env.agent_dir + 1) % 4):  # Grid.rotate_left: new (j, n-1-i) = old (i, j)
        view = [[view[n - 1 - b][a] for b in range(n)] for a in range(n)]
    seen = _visible(view, n)
    view[n // 2][n - 1] = env.carrying or None  # (the agent's cell shows what it carries)
    flat = [_UNSEEN if not seen[i][j] else _EMPTY if view[i][j] is None else view[i][j].encode()
            for i in range(n) for j in range(n)]
    image = np.array(flat, dtype=np.uint8).reshape(n, n, 3)
    return {"image": image, "direction": env.agent_dir, "mission": env.mission}


def _visible(view: list, n: int) -> list:
    """``Grid.process_vis`` from the agent's cell (n // 2, n - 1): light spreads along each row and to the row
    ahead, stopped by what cannot be seen behind."""
    mask = [[False] * n for _ in range(n)]
    mask[n // 2][n - 1] = True
    for j in reversed(range(n)):
        for i in range(n - 1):
            if not mask[i][j]:
                continue
            cell = view[i][j]
            if cell and not cell.see_behind():
                continue
            mask[i + 1][j] = True
            if j > 0:
                mask[i + 1][j - 1] = True
                mask[i][j - 1] = True
        for i in reversed(range(1, n)):
            if not mask[i][j]:
                continue
            cell = view[i][j]
            if cell and not cell.see_behind():
                continue
            mask[i - 1][j] = True
            if j > 0:
                mask[i - 1][j - 1] = True
                mask[i][j - 1] = True
    return mask


def fast_observations(env: gym.Env) -> gym.Env:
    """``env`` (any wrapper of a MiniGrid env) with :func:`gen_obs` in place of MiniGrid's on its unwrapped env,
    unless it sees through walls (then MiniGrid's own stays)."""
    u = env.unwrapped
    if not u.see_through_walls:
        u.gen_obs = types.MethodType(gen_obs, u)
    return env
