"""Stage 1 of Figure 1: the stochastic key–door grid worlds, as gymnasium environments.

All registrations live here. ``gymnasium.make("hnsdt/KeyDoor-v0")`` gives the single environment;
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")`` gives the numpy-batched one.
"""

from gymnasium.envs.registration import register, registry

from hnsdt.envs.keydoor import ACTION_NAMES, N_ACTIONS, KeyDoorEnv
from hnsdt.envs.layout import BUILTIN_LAYOUTS, Layout, LayoutError, load_layout, parse_layout
from hnsdt.envs.multi_keydoor import MultiKeyDoorEnv
from hnsdt.envs.vector import KeyDoorVectorEnv

ENV_IDS = {
    "hnsdt/KeyDoor-v0": (KeyDoorEnv, {"layout": "keydoor_5x5", "max_steps": 100}),
    "hnsdt/MultiKeyDoor-v0": (MultiKeyDoorEnv, {"layout": "multikeydoor_9x9", "max_steps": 250}),
}

for _id, (_cls, _kwargs) in ENV_IDS.items():
    if _id not in registry:
        register(id=_id, entry_point=_cls, vector_entry_point=KeyDoorVectorEnv, kwargs=dict(_kwargs))

__all__ = [
    "ACTION_NAMES", "BUILTIN_LAYOUTS", "ENV_IDS", "N_ACTIONS", "KeyDoorEnv", "KeyDoorVectorEnv", "Layout",
    "LayoutError", "MultiKeyDoorEnv", "load_layout", "parse_layout",
]
