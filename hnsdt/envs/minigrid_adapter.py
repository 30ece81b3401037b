"""MiniGrid's DoorKey worlds as our layouts: an external test set of layouts nobody here designed.

:func:`from_minigrid` resets a ``minigrid`` environment (e.g. ``MiniGrid-DoorKey-8x8-v0``) with a seed and
converts the grid its own generator produced, cell by cell: ``Wall`` → ``#``, empty → ``.``, ``Key`` → ``a``,
locked ``Door`` → ``A`` (an unlocked one → ``.``), ``Goal`` → ``G``, the agent's cell → ``@``. MiniGrid's
``(x, y)`` is our ``(col, row)``.

Only the layout is taken: episodes on it run with our dynamics (four moves and pick/open, failures with
``fail_prob``, a closed door cell that traps), not MiniGrid's turn / forward / toggle with an agent
direction. A converted layout goes through the same validation as a layout file.
"""

from __future__ import annotations

from hnsdt.envs.layout import Layout, LayoutError, parse_layout

DOORKEY_IDS = ("MiniGrid-DoorKey-5x5-v0", "MiniGrid-DoorKey-6x6-v0", "MiniGrid-DoorKey-8x8-v0",
               "MiniGrid-DoorKey-16x16-v0")


def minigrid_cells(env_id: str, seed: int) -> list[list[str]]:
    """MiniGrid's own grid after ``reset(seed=seed)``, as rows of cell type names (``"empty"``, ``"wall"``,
    ``"key"``, ``"door"`` / ``"door_locked"``, ``"goal"``, ``"agent"``)."""
    try:
        import gymnasium as gym
        import minigrid  # noqa: F401  (registers the MiniGrid ids)
    except ImportError:
        raise LayoutError("the minigrid package is not installed (it is pinned in requirements.lock)") from None
    if env_id not in gym.registry:
        raise LayoutError(f"{env_id!r} is not a registered MiniGrid id (e.g. {', '.join(DOORKEY_IDS)})")
    env = gym.make(env_id)
    try:
        env.reset(seed=int(seed))
        u = env.unwrapped
        rows = []
        for y in range(u.height):
            row = []
            for x in range(u.width):
                obj = u.grid.get(x, y)
                if (x, y) == tuple(int(v) for v in u.agent_pos):
                    row.append("agent")
                elif obj is None:
                    row.append("empty")
                elif obj.type == "door":
                    row.append("door_locked" if obj.is_locked else "door")
                else:
                    row.append(obj.type)
            rows.append(row)
        return rows
    finally:
        env.close()


SYMBOLS = {"empty": ".", "door": ".", "wall": "#", "key": "a", "door_locked": "A", "goal": "G", "agent": "@"}


def from_minigrid(env_id: str, seed: int) -> Layout:
    """Our layout of MiniGrid's ``env_id`` world for ``seed``, named ``<env_id>@<seed>``."""
    cells = minigrid_cells(env_id, seed)
    unknown = sorted({c for row in cells for c in row} - set(SYMBOLS))
    if unknown:
        raise LayoutError(f"{env_id} seed {seed}: cell types {unknown} have no counterpart in our worlds")
    if sum(row.count("key") for row in cells) > 1 or sum(row.count("door_locked") for row in cells) > 1:
        raise LayoutError(f"{env_id} seed {seed}: more than one key or locked door (only DoorKey worlds convert)")
    text = "\n".join("".join(SYMBOLS[c] for c in row) for row in cells) + "\n"
    return parse_layout(text, name=f"{env_id}@{seed}")
