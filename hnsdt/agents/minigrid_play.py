"""The learners acting in MiniGrid's own worlds (:mod:`hnsdt.models.minigrid_nets`): HNSDT under the symbolic
planner, the pure DT, the recurrent controllers and PPO's actor-critic.

HNSDT: at every step the planner's operator at the head of its plan (the symbolic agent's plan-keeping,
:class:`hnsdt.minigrid.controllers.SymbolicAgent`: drop what the state has achieved, replan from the true state
when the next operator can no longer be done) becomes the step's sub-goal token, and the transformer picks the
action — the hand-written controllers never act. The pure DT reads a return-to-go instead (the target return,
less what the episode has earned). The recurrent controllers (the LSTM, the GRU) carry their recurrent state
through the episode, and the hierarchical one picks its own sub-goal. The online learners' networks read the current
step alone: PPO's actor-critic and DQN act greedily (the most likely action, the highest value), as do the others;
option-critic executes its options call-and-return as it trained (greedy options, actions and terminations drawn
from π_ω and β_ω by a generator of the episode's own: the world's seed and failure stream).

Many episodes are played in lockstep (one row each of the transformer's key/value cache), so that each step is one
forward pass for all of them; each episode ends when MiniGrid ends it (success, or its own step limit) or at
``max_steps`` when given (counted a failure). At fail_prob 0 a world's episodes of a greedy learner are one
episode, played once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hnsdt.minigrid.collect import state_vector, subgoal_of
from hnsdt.minigrid.controllers import SymbolicAgent
from hnsdt.minigrid.live import Episode, GaveUp, Step, carried_name, close_trace, make_env, read_world, snapshot
from hnsdt.minigrid.operators import PlanState
from hnsdt.baselines.online import sample_categorical
from hnsdt.baselines.options import choose_options
from hnsdt.models.minigrid_nets import (MiniGridActorCritic, MiniGridDT, MiniGridOptionCritic, MiniGridQNetwork,
                                        MiniGridRecurrent, step_states)


@dataclass(frozen=True)
class Job:
    """One episode to play: MiniGrid's world ``seed`` under ``fail_prob``, failure stream ``failure_seed``."""

    seed: int
    fail_prob: float
    failure_seed: int = 0


class _Game:
    """One episode in play: its env, world, what the learner saw last and (HNSDT) its planner."""

    def __init__(self, env_id: str, job: Job, subgoals: bool, traced: bool):
        self.env = make_env(env_id, job.fail_prob, **({"render_mode": "rgb_array", "tile_size": 16} if traced
                                                      else {}))
        self.obs, _ = self.env.reset(seed=int(job.seed), options={"failure_seed": int(job.failure_seed)})
        self.world, self.live = read_world(self.env, env_id, job.seed)
        self.planner = SymbolicAgent(self.world) if subgoals else None
        self.steps, self.earned = 0, 0.0

    def state(self):
        return snapshot(self.world, self.env, self.live)

    def operator(self, s):
        """HNSDT's sub-goal now: the plan's head, replanned when it can no longer be done (GaveUp: no plan)."""
        ps = PlanState.of(s)
        if not self.planner.advance(ps):
            self.planner.replan(ps)
        return self.planner.plan[0] if self.planner.plan else None


class _Transformer:
    """A decision transformer's acting: its key/value cache, each episode's previous action and return-to-go."""

    def __init__(self, model: MiniGridDT, n: int, target_return: float):
        self.model, self.target_return = model, target_return
        self.cache = model.start(n)
        self.prev = np.full(n, model.n_actions, np.int64)  # (NO_ACTION before the first step)

    def actions(self, rows: list[int], states, kinds, targets, games) -> np.ndarray:
        t = lambda x, **kw: torch.as_tensor(x, device=self.cache.seen.device, **kw)  # noqa: E731
        subgoals = self.model.cfg.condition == "subgoal"
        returns = t([self.target_return - games[i].earned for i in rows], dtype=torch.float32)
        logits = self.model.step(self.cache, t(rows), t(states), t(self.prev[rows]), t([games[i].steps for i in rows]),
                                 t(kinds) if subgoals else None, t(targets) if subgoals else None,
                                 None if subgoals else returns)
        actions = logits.argmax(-1).cpu().numpy()
        self.prev[rows] = actions
        return actions


class _Recurrent:
    """A recurrent controller's acting: each episode's recurrent state (a column of one batch) and previous action;
    the hierarchical one picks its own sub-goal (no planner)."""

    def __init__(self, model: MiniGridRecurrent, n: int):
        rnn, self.model = model.rnn, model
        self.lstm = isinstance(rnn, torch.nn.LSTM)  # (its state is (h, c); a GRU's h alone)
        self.parts = [torch.zeros(rnn.num_layers, n, rnn.hidden_size) for _ in range(2 if self.lstm else 1)]
        self.prev = np.full(n, model.n_actions, np.int64)  # (the start token before the first step)

    def actions(self, rows: list[int], states, kinds, targets, games) -> np.ndarray:
        index = torch.as_tensor(rows)
        hidden = tuple(part[:, index] for part in self.parts)
        logits, _, new = self.model.step(torch.as_tensor(states), torch.as_tensor(self.prev[rows]),
                                         hidden if self.lstm else hidden[0])
        for part, rows_new in zip(self.parts, new if self.lstm else (new,)):
            part[:, index] = rows_new
        actions = logits.argmax(-1).cpu().numpy()
        self.prev[rows] = actions
        return actions


class _ActorCritic:
    """The actor-critic's acting: the most likely action of the current step."""

    def __init__(self, model: MiniGridActorCritic):
        self.model = model

    def actions(self, rows, states, kinds, targets, games) -> np.ndarray:
        with torch.no_grad():
            logits, _ = self.model(torch.as_tensor(states, device=next(self.model.parameters()).device))
        return logits.argmax(-1).cpu().numpy()


class _QGreedy:
    """DQN's acting: the action of highest value in the current step."""

    def __init__(self, model: MiniGridQNetwork):
        self.model = model

    def actions(self, rows, states, kinds, targets, games) -> np.ndarray:
        with torch.no_grad():
            return self.model(torch.as_tensor(states)).argmax(-1).numpy()


class _Options:
    """Option-critic's call-and-return execution: each episode's option runs until its termination draw (β_ω of
    the state reached) ends it, the next one greedy in Q_Ω; actions drawn from π_ω. Each episode draws from its
    own generator (its world's seed and failure stream), so that an episode is the same whichever play it is in."""

    def __init__(self, model: MiniGridOptionCritic, jobs: list[Job]):
        self.model = model
        self.rngs = [np.random.default_rng([job.seed, job.failure_seed]) for job in jobs]
        self.option = np.zeros(len(jobs), np.int64)
        self.started = np.zeros(len(jobs), bool)

    def actions(self, rows, states, kinds, targets, games) -> np.ndarray:
        with torch.no_grad():
            q, beta, logits = self.model(torch.as_tensor(states))
        out = np.zeros(len(rows), np.int64)
        for j, i in enumerate(rows):
            rng = self.rngs[i]
            # an option that has run a step ends with probability β_ω(s) in the state it reached
            if not self.started[i] or rng.random() < float(beta[j, self.option[i]]):
                self.option[i] = choose_options(q[j:j + 1], 0.0, rng)[0]
                self.started[i] = True
            out[j] = sample_categorical(logits[j:j + 1, self.option[i]], rng)[0]
        return out


def _same_episodes(model, jobs: list[Job], traces: dict) -> list[int]:
    """For each job, the first job whose episode is certainly its own: at fail_prob 0 no action fails, and a
    learner that acts greedily on what it has seen plays a world's episodes as one episode played again, whatever
    their failure streams. Option-critic draws from each episode's own stream, and a traced job is played itself."""
    if isinstance(model, MiniGridOptionCritic):
        return list(range(len(jobs)))
    first: dict[int, int] = {}
    return [first.setdefault(job.seed, i) if job.fail_prob == 0 and i not in traces else i
            for i, job in enumerate(jobs)]


def play(model: MiniGridDT | MiniGridRecurrent | MiniGridActorCritic | MiniGridQNetwork | MiniGridOptionCritic,
         env_id: str, jobs: list[Job],
         target_return: float = 1.0, max_steps: int = 0, traces: dict[int, list[Step]] | None = None) -> list[Episode]:
    """Play every job with ``model`` (eval mode); the episodes in job order. ``traces``: job index -> a list that
    gets each step's :class:`Step` (MiniGrid's drawing of the world before it) and a closing frame."""
    traces = traces or {}
    same = _same_episodes(model, jobs, traces)
    if len(set(same)) < len(jobs):  # each distinct episode played once, in the order of its first job
        kept = sorted(set(same))
        at = {j: n for n, j in enumerate(kept)}
        episodes = play(model, env_id, [jobs[j] for j in kept], target_return, max_steps,
                        {at[j]: trace for j, trace in traces.items()})
        return [episodes[at[j]] for j in same]
    subgoals = getattr(model.cfg, "condition", "") == "subgoal"
    games = [_Game(env_id, job, subgoals, i in traces) for i, job in enumerate(jobs)]
    done: list[Episode | None] = [None] * len(games)
    actor = (_Transformer(model, len(games), target_return) if isinstance(model, MiniGridDT)
             else _Recurrent(model, len(games)) if isinstance(model, MiniGridRecurrent)
             else _QGreedy(model) if isinstance(model, MiniGridQNetwork)
             else _Options(model, jobs) if isinstance(model, MiniGridOptionCritic) else _ActorCritic(model))
    alive = list(range(len(games)))
    try:
        while alive:
            rows, states, kinds, targets, ops, seen = [], [], [], [], [], []
            for i in alive:
                g = games[i]
                s = g.state()
                try:
                    op = g.operator(s) if subgoals else None
                except GaveUp as exc:
                    done[i] = Episode(False, g.steps, 0.0, g.planner.plans, str(exc)[:200])
                    close_trace(traces.get(i), g.env, g.world, s)
                    continue
                kind, target = subgoal_of(g.world, op)
                rows.append(i)
                states.append(step_states(state_vector(g.world, s), g.obs["image"]))
                kinds.append(kind)
                targets.append(target)
                ops.append(op.name(g.world) if op else "")
                seen.append(s)
            if not rows:
                break
            actions = actor.actions(rows, np.stack(states), kinds, targets, games)
            for i, a, op, s in zip(rows, actions, ops, seen):
                g = games[i]
                frame = g.env.render() if i in traces else None
                g.obs, reward, terminated, truncated, info = g.env.step(int(a))
                g.steps += 1
                g.earned += float(reward)
                if i in traces:
                    traces[i].append(Step(frame, s.direction, carried_name(g.world, s), op, int(a), float(reward),
                                          bool(info["move_failed"])))
                if terminated or truncated or (max_steps and g.steps >= max_steps):
                    done[i] = Episode(bool(terminated and reward > 0), g.steps, float(reward),
                                      g.planner.plans if g.planner else 0)
                    close_trace(traces.get(i), g.env, g.world, g.state())
            alive = [i for i in alive if done[i] is None]
    finally:
        for g in games:
            g.env.close()
    return done

