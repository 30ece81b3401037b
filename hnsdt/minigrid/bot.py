"""MiniGrid's BabyAI bot (``minigrid.utils.baby_ai_bot.BabyAIBot``, written by MiniGrid's authors) as a reference
policy on MiniGrid's key–door worlds.

The bot solves BabyAI missions, given as BabyAI instructions; these envs have none, so each gets the instruction
its mission states: ``pick up the <color> <type>`` for UnlockPickup, KeyCorridor and BlockedUnlockPickup,
``open the <color> door`` for Unlock. DoorKey's mission ends on the goal cell, which BabyAI's "go to" does not
(it ends next to the object, facing it): the bot gets the sub-goal "go next to the goal cell" and, when it
says it is done, one forward onto it. The bot's search for a key asks the env for rooms (``room_from_pos``),
which DoorKey's single-grid env has not; it is given one that answers none (the bot only uses it for
instructions that name a location, which these do not). Everything else is the bot's own: it sees only its
7 × 7 view and maps the world as it goes.

Under action failures the bot is told the action it chose (``replan(action_taken)``); it replans from what it
then observes.
"""

from __future__ import annotations

from hnsdt.minigrid.live import Episode, GaveUp, run_episode
from hnsdt.minigrid.world import GOAL, OPEN_DOOR, Actions, World, WorldState


def _instruction(u, task: str):
    from minigrid.envs.babyai.core.verifier import ObjDesc, OpenInstr, PickupInstr

    if task == OPEN_DOOR:
        return OpenInstr(ObjDesc("door", u.door.color))
    if task == GOAL:
        return OpenInstr(ObjDesc("door"))  # replaced by the goal sub-goal below; the bot needs one to start
    return PickupInstr(ObjDesc(u.obj.type, u.obj.color))


class BotPolicy:
    """The bot on a freshly reset env, one action per :meth:`act`."""

    def __init__(self, world: World, env):
        from minigrid.utils.baby_ai_bot import BabyAIBot, GoNextToSubgoal

        u = env.unwrapped
        if not hasattr(u, "room_from_pos"):
            u.room_from_pos = lambda x, y: None
        u.instrs = _instruction(u, world.task)
        u.instrs.reset_verifier(env)
        self.bot, self.goal, self.last = BabyAIBot(env), world.task == GOAL, None
        if self.goal:
            (r, c), = world.goals
            self.bot.stack = [GoNextToSubgoal(self.bot, (c, r))]

    def act(self, state: WorldState) -> int:
        try:
            action = self.bot.replan(self.last)
        except Exception as exc:  # the bot gives up (e.g. an assertion in its planner): a failed episode
            raise GaveUp(f"{type(exc).__name__}: {exc}") from exc
        if action == Actions.done and self.goal:
            action = Actions.forward  # the last step of "go to the goal": onto it
        self.last = action
        return int(action)


def bot_episode(env_id: str, seed: int, fail_prob: float = 0.0, failure_seed: int = 0) -> Episode:
    """One episode of the BabyAI bot on ``env_id``'s world ``seed``, with the failures drawn from
    ``failure_seed``."""
    return run_episode(env_id, seed, fail_prob, failure_seed, BotPolicy)
