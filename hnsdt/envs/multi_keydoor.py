"""Multi-goal key–door grid world (Case Study 2 of the paper, Appendix A.2).

Description:
    Two keys open two doors in sequence (key a behind nothing, key b behind door A), two items must both be
    collected, and the exit only counts once every item is held. The default 9×9 layout::

        @..#...#.
        ...#.1.#.
        a..A...B.
        ...#.b.#2
        ...#...#.
        ...#...#.
        ...#...#.
        ...#...#.
        ...#...#G

Actions, observation, rewards and termination:
    As :class:`hnsdt.envs.keydoor.KeyDoorEnv` (the dynamics are the same; only the default layout and the step
    limit differ). The observation is ``row, col, has_key_a, has_key_b, door_open_A, door_open_B, has_item_1,
    has_item_2`` for the default layout.

Registered ids:
    ``hnsdt/MultiKeyDoor-v0`` (default layout ``multikeydoor_9x9``, ``max_steps=250``), same keyword arguments
    as ``hnsdt/KeyDoor-v0``. Any valid layout with more keys, doors or items works through ``layout``.
"""

from __future__ import annotations

from hnsdt.envs.keydoor import KeyDoorEnv


class MultiKeyDoorEnv(KeyDoorEnv):
    default_layout = "multikeydoor_9x9"

    def __init__(self, layout=None, fail_prob: float = 0.0, max_steps: int = 250, render_mode=None,
                 view_radius=None):
        super().__init__(layout=layout, fail_prob=fail_prob, max_steps=max_steps, render_mode=render_mode,
                         view_radius=view_radius)
