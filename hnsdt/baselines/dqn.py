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

from hnsdt.baselines.online import OnlineAgent, OnlineConfig, OnlineRun, linear_schedule, start_run
from hnsdt.envs.keydoor import N_ACTIONS
from hnsdt.envs.layout import Layout
from hnsdt.models.qnetwork import QNetwork, QNetworkConfig


@dataclass
class DQNConfig(OnlineConfig):
    """The shared online knobs (:class:`OnlineConfig`: budget, replay, target period, ε schedule), plus:"""

    train_every: int = 4  # env steps per gradient step


def train_dqn(layout: Layout | list[Layout], max_steps: int, net_cfg: QNetworkConfig, cfg: DQNConfig,
              progress: bool = True, desc: str = "train", network: type = QNetwork, state: OnlineRun | None = None,
              stop_after: int | None = None):
    """``layout``: one map, or a list to draw from at every reset (then ``network`` reads views). Returns the
    model, its curve and the data used; or, when ``stop_after`` env steps come before the end, the paused
    :class:`OnlineRun`, which ``state`` continues."""
    run = start_run(layout, max_steps, network, net_cfg, cfg, state)
    rng, device, env, q, target = run.rng, run.device, run.env, run.net, run.target
    obs, buffer, stats, steps, curve = run.obs, run.buffer, run.stats, run.steps, run.curve
    due, next_log = run.loop.get("due", 0.0), run.loop.get("next_log", cfg.log_every)
    explore_steps = int(cfg.exploration_fraction * cfg.env_steps)
    limit = cfg.env_steps if stop_after is None else min(stop_after, cfg.env_steps)
    bar = tqdm(total=cfg.env_steps, initial=steps, desc=desc, unit="step", unit_scale=True, disable=not progress)
    while steps < limit:
        # 1. act ε-greedily in every copy
        epsilon = linear_schedule(cfg.epsilon_start, cfg.epsilon_end, explore_steps, steps)
        with torch.no_grad():
            greedy = q(torch.from_numpy(obs).to(device)).argmax(-1).cpu().numpy()
        explore = rng.random(cfg.num_envs) < epsilon
        actions = np.where(explore, rng.integers(0, N_ACTIONS, cfg.num_envs), greedy)
        next_obs, rewards, terminated, truncated, _ = env.step(actions)
        # 2. store; truncation is not termination, so its next state is bootstrapped
        buffer.add(obs, actions, rewards, next_obs, terminated)
        done = terminated | truncated
        stats.update(rewards, terminated, done)
        obs = env.reset(options={"reset_mask": done})[0] if done.any() else next_obs
        steps += cfg.num_envs
        bar.update(cfg.num_envs)
        # 3. learn: one gradient step per `train_every` env steps, once the buffer has warmed up
        if steps >= cfg.learning_starts:
            due += cfg.num_envs / cfg.train_every
            while due >= 1:
                due -= 1
                b = {k: torch.from_numpy(v).to(device) for k, v in buffer.sample(cfg.batch_size).items()}
                with torch.no_grad():
                    td_target = b["rewards"] + cfg.gamma * target(b["next_obs"]).max(-1).values * (
                        1 - b["terminated"])
                value = q(b["obs"]).gather(1, b["actions"][:, None]).squeeze(1)
                run.learn(F.mse_loss(value, td_target), cfg.target_period)
        # 4. one curve row per `log_every` env steps
        if steps >= next_log or steps >= cfg.env_steps:
            next_log += cfg.log_every
            curve.append(run.curve_row(steps, epsilon))
            bar.set_postfix(success=f"{curve[-1]['success']:.2f}", eps=f"{epsilon:.2f}")
    bar.close()
    if steps < cfg.env_steps:
        return run.pause(steps, obs, curve, due=due, next_log=next_log)
    return run.result(steps, curve)


class DQNAgent(OnlineAgent):
    """Greedy in Q (or ε-greedy with ``epsilon`` > 0, from the seeded generator)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            actions = self.model(self.states(obs)).argmax(-1).cpu().numpy()
        if self.epsilon > 0:
            explore = self.rng.random(len(obs)) < self.epsilon
            actions = np.where(explore, self.rng.integers(0, N_ACTIONS, len(obs)), actions)
        return actions


def make_agent(model, meta: dict, layout, executor, epsilon: float = 0.0, seed: int = 0) -> DQNAgent:
    """The registry's agent factory (:mod:`hnsdt.core.methods`)."""
    return DQNAgent(model, epsilon, seed, layout)
