"""DQN baseline (Mnih et al., 2015), after CleanRL's ``dqn.py``: online Q-learning with an experience replay
buffer, a periodically copied target network and a linearly decaying ε-greedy exploration.

Copies of the environment are stepped together; finished copies restart at once from the layout's start.
Acting after training is greedy (``eval_epsilon`` adds ε-greedy noise if set).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.agents.baselines.online import (
    EpisodeStats, OnlineAgent, OnlineConfig, ReplayBuffer, linear_schedule, training_env,
)
from hnsdt.envs.keydoor import N_ACTIONS
from hnsdt.envs.layout import Layout
from hnsdt.models.qnetwork import QNetwork, QNetworkConfig


@dataclass
class DQNConfig(OnlineConfig):
    """The shared online knobs (:class:`OnlineConfig`: budget, replay, target period, ε schedule), plus:"""

    train_every: int = 4  # env steps per gradient step


def train_dqn(layout: Layout, max_steps: int, net_cfg: QNetworkConfig, cfg: DQNConfig, progress: bool = True,
              desc: str = "train") -> tuple[QNetwork, list[dict], dict]:
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    device = torch.device(cfg.device)
    env = training_env(layout, max_steps, cfg.num_envs, cfg.fail_probs)
    q = QNetwork(net_cfg).to(device)
    target = copy.deepcopy(q)
    opt = torch.optim.Adam(q.parameters(), lr=cfg.lr)
    obs, _ = env.reset(seed=cfg.seed)
    buffer = ReplayBuffer(cfg.buffer_size, obs.shape[1], rng)
    stats = EpisodeStats(cfg.num_envs)
    steps, grad_steps, due, next_log, losses, curve = 0, 0, 0.0, cfg.log_every, [], []
    explore_steps = int(cfg.exploration_fraction * cfg.env_steps)
    bar = tqdm(total=cfg.env_steps, desc=desc, unit="step", unit_scale=True, disable=not progress)
    while steps < cfg.env_steps:
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
                loss = F.mse_loss(value, td_target)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                grad_steps += 1
                losses.append(loss.item())
                if grad_steps % cfg.target_period == 0:
                    target.load_state_dict(q.state_dict())
        # 4. one curve row per `log_every` env steps
        if steps >= next_log or steps >= cfg.env_steps:
            next_log += cfg.log_every
            row = {"step": steps, "epsilon": round(epsilon, 4), **stats.row(),
                   "loss": float(np.mean(losses)) if losses else float("nan")}
            losses = []
            curve.append(row)
            bar.set_postfix(success=f"{row['success']:.2f}", eps=f"{epsilon:.2f}")
    bar.close()
    q.eval()
    return q, curve, {"env_steps": steps, "episodes": stats.episodes, "gradient_steps": grad_steps}


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
    """The registry's agent factory (:mod:`hnsdt.methods`)."""
    return DQNAgent(model, epsilon, seed)
