"""DQN baseline (Mnih et al., 2015), after CleanRL's ``dqn.py``: online Q-learning with an experience replay
buffer, a periodically copied target network and a linearly decaying ε-greedy exploration.

Copies of the environment are stepped together; finished copies restart at once from the layout's start.
Acting after training is greedy (``eval_epsilon`` adds ε-greedy noise if set).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.baselines.online import (OnlineAgent, OnlineRun, ReplayConfig, finish, linear_schedule, seed_configs,
                                    start_run)
from hnsdt.envs.keydoor import N_ACTIONS
from hnsdt.envs.layout import Layout
from hnsdt.models.qnetwork import QNetwork, QNetworkConfig


@dataclass
class DQNConfig(ReplayConfig):
    """The shared online knobs (:class:`ReplayConfig`: budget, replay, target period, ε schedule), plus:"""

    train_every: int = 4  # env steps per gradient step


def train_dqn(layout: Layout | list[Layout], max_steps: int, net_cfg: QNetworkConfig, cfg: DQNConfig | list[DQNConfig],
              progress: bool = True, desc: str = "train", network: type = QNetwork, state: OnlineRun | None = None,
              stop_after: int | None = None, measure=None):
    """``layout``: one map, or a list to draw from at every reset (then ``network`` reads views). ``cfg``: one
    config, or one per seed of a stack trained in lockstep (:class:`OnlineRun`). Returns the model, its curve and
    the data used (a list of them for a list of configs); or, when ``stop_after`` env steps come before the end,
    the paused :class:`OnlineRun`, which ``state`` continues. With ``cfg.patience``, each seed stops at the
    plateau of ``measure`` (:class:`~hnsdt.baselines.online.Plateau`)."""
    cfgs = seed_configs(cfg)
    c = cfgs[0]
    run = start_run(layout, max_steps, network, net_cfg, cfgs, state, measure)
    q, target, device, steps = run.net, run.target, run.device, run.steps
    due = run.loop.get("due", 0.0)
    explore_steps = int(c.exploration_fraction * c.env_steps)
    limit = c.env_steps if stop_after is None else min(stop_after, c.env_steps)
    bar = tqdm(total=c.env_steps, initial=steps, desc=desc, unit="step", unit_scale=True, disable=not progress)
    while steps < limit:
        # 1. act ε-greedily in every copy (each seed's draws from its own generator)
        epsilon = linear_schedule(c.epsilon_start, c.epsilon_end, explore_steps, steps)
        with torch.no_grad():
            greedy = q(torch.from_numpy(run.obs).to(device)).argmax(-1).cpu().numpy()
        actions = np.stack([np.where(rng.random(c.num_envs) < epsilon, rng.integers(0, N_ACTIONS, c.num_envs), g)
                            for rng, g in zip(run.rngs, greedy)])
        # 2. store the transitions; finished copies restart
        next_obs, _, _, done = run.step(actions)
        run.restart(next_obs, done)
        steps += c.num_envs
        bar.update(c.num_envs)
        # 3. learn: one gradient step per `train_every` env steps, once the buffer has warmed up
        if steps >= c.learning_starts:
            due += c.num_envs / c.train_every
            while due >= 1:
                due -= 1
                b = run.sample(c.batch_size)
                with torch.no_grad():
                    td_target = b["rewards"] + c.gamma * target(b["next_obs"]).max(-1).values * (1 - b["terminated"])
                value = q(b["obs"]).gather(-1, b["actions"][..., None]).squeeze(-1)
                run.learn(F.mse_loss(value, td_target, reduction="none").mean(-1), c.target_period)
        # 4. with patience, every `validate_every` env steps: each seed's greedy steps to the exit on validation;
        # 5. a curve row every `log_every` env steps, and at each evaluation
        if run.row_due(steps, c, measure, may_stop=steps >= explore_steps):
            run.curve_rows(steps, epsilon)
            bar.set_postfix(success=f"{run.curves[0][-1]['success']:.2f}", eps=f"{epsilon:.2f}")
        if run.done():  # every seed at its plateau
            break
    bar.close()
    return finish(run, steps, cfg, due=due)


class DQNAgent(OnlineAgent):
    """Greedy in Q (or ε-greedy with ``epsilon`` > 0, from the seeded generator)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.epsilon_greedy(self.outputs(obs).argmax(-1).cpu().numpy())


def make_agent(model, meta: dict, layout, executor, epsilon: float = 0.0, seed: int = 0) -> DQNAgent:
    """The registry's agent factory (:mod:`hnsdt.core.methods`)."""
    return DQNAgent(model, epsilon, seed, layout)
