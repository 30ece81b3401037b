"""MiniGrid's own worlds, stepped by MiniGrid (issue 69): its key–door envs under the paper's action failures
(:mod:`.live`), their state and rules written out (:mod:`.world`), φ over that state (:mod:`.abstraction`), the
symbolic layer — operators with a Drop (:mod:`.operators`), the planner (:mod:`.planner`), its PDDL export
(:mod:`.pddl`), hand-written controllers and the symbolic agent (:mod:`.controllers`) — the exact optimum
(:mod:`.optimum`), MiniGrid's BabyAI bot as a second reference (:mod:`.bot`), and the labelled episodes the
learners' datasets are made of (:mod:`.collect`).

A package of its own beside :mod:`hnsdt.envs` (our simulator) so that the paper's stages, which depend on that
one, do not rerun for a change here."""

from hnsdt.minigrid.live import ActionFailures, Episode, make_env, read_world, snapshot, world_of
from hnsdt.minigrid.optimum import Optimum, WorldMDP
from hnsdt.minigrid.world import Actions, MiniGridError, World, WorldState

__all__ = ["ActionFailures", "Actions", "Episode", "MiniGridError", "Optimum", "World", "WorldMDP", "WorldState",
           "make_env", "read_world", "snapshot", "world_of"]
