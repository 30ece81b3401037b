"""What the online learners on MiniGrid's own worlds (PPO, DQN, option-critic) share: the copies of the env they
train in, each reset onto a training world (MiniGrid's reset seed) drawn by the run's generator, copy i under
``fail_probs[i % len]`` — so that an online learner meets the worlds and failures the offline learners' datasets
hold —, and their training to the plateau of a validation measure."""

from __future__ import annotations

import numpy as np
import torch.nn as nn

from hnsdt.baselines.online import Plateau
from hnsdt.minigrid.live import make_env
from hnsdt.models.minigrid_nets import step_states


class TrainingCopies:
    """``num_envs`` MiniGrid envs, each reset onto a training world drawn by ``rng`` when its episode ends."""

    def __init__(self, env_id: str, seeds: list[int], fail_probs: list[float], n: int, rng: np.random.Generator):
        self.seeds, self.rng = seeds, rng
        self.envs = [make_env(env_id, fail_probs[i % len(fail_probs)]) for i in range(n)]
        self.episodes = 0
        self.obs = [None] * n
        self.current: list = [None] * n  # each copy's state vector now (computed once a step)
        for i in range(n):
            self.reset(i)

    def reset(self, i: int) -> None:
        seed = int(self.rng.choice(self.seeds))
        self.obs[i], _ = self.envs[i].reset(seed=seed, options={"failure_seed": self.episodes})
        self.current[i] = self.state(i, self.obs[i])
        self.episodes += 1

    def step(self, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Step copy i with ``actions[i]``; a copy whose episode ended is reset at once (copy by copy, in order).
        Returns per copy the state vector it reached (before any reset), its reward, whether the episode ended
        terminated (a goal reached, or lost) and whether MiniGrid's step limit cut it."""
        n = len(self.envs)
        reached, rewards = [], np.zeros(n)
        terminated, truncated = np.zeros(n, bool), np.zeros(n, bool)
        for i, a in enumerate(actions):
            obs, rewards[i], terminated[i], truncated[i], _ = self.envs[i].step(int(a))
            reached.append(self.state(i, obs))
            if terminated[i] or truncated[i]:
                self.reset(i)
            else:
                self.obs[i], self.current[i] = obs, reached[-1]
        return np.stack(reached), rewards, terminated, truncated

    def states(self) -> np.ndarray:
        """Every copy's state vector now (:func:`step_states`)."""
        return np.stack(self.current)

    def state(self, i: int, obs) -> np.ndarray:
        """What the online learners' networks read of an observation (:class:`hnsdt.models.minigrid_nets.ViewConv`),
        as a state vector: the direction and the view (the cell and the carried object, which they never read,
        left 0: the run need not read the world's state)."""
        return step_states([0, 0, int(obs["direction"]), 0, 0], obs["image"])

    def used(self, frames: int, gradient_steps: int) -> dict:
        """What a run has used: its env steps, the episodes its copies finished, its gradient steps."""
        return {"frames": frames, "episodes": self.episodes - len(self.envs), "gradient_steps": gradient_steps}

    def close(self) -> None:
        for env in self.envs:
            env.close()


class Validated:
    """A run's measurements on the validation worlds (``measure``: lower is better, with a ``floor`` and a
    ``ceiling``) and its stop at their plateau (:class:`hnsdt.baselines.online.Plateau`: ``patience`` measurements
    without a better one, never while none has reached a goal)."""

    def __init__(self, measure, patience: int):
        self.measure = measure
        self.plateau = Plateau(patience, float(getattr(measure, "floor", float("-inf"))),
                               float(getattr(measure, "ceiling", float("inf"))))

    @property
    def stopped(self) -> bool:
        return self.plateau.stopped is not None

    def check(self, net: nn.Module, frames: int, used: dict, may_stop: bool = True) -> float:
        """Measure ``net`` greedily now (in eval mode, then back to training) and update the plateau."""
        net.eval()
        value = float(self.measure(net))
        net.train()
        self.plateau.update(frames, value, net, used, may_stop)
        return value

    def finish(self, net: nn.Module, used: dict) -> dict:
        """Put the best measurement's weights into ``net`` (eval mode); what the run used when it stopped (``used``
        when it never did) and its measurements."""
        if self.plateau.best is not None:
            net.load_state_dict(self.plateau.best[3])
        net.eval()
        return {**(self.plateau.stopped or used), **self.plateau.record()}
