"""DQN on MiniGrid's own worlds (Mnih et al., 2015), after CleanRL's ``dqn.py``, whose defaults these are: online
Q-learning from a replay buffer, a target network copied every ``target_period`` gradient steps, ε-greedy
exploration decaying linearly over the first ``exploration_fraction`` of the frames, :class:`MiniGridQNetwork` as the
network (the actor-critic's view convolutions, a Q head).

The env copies play the training worlds under every fail_prob (:class:`TrainingCopies`). Every ``eval_every`` frames
the greedy policy is measured on the validation worlds (:class:`hnsdt.evaluation.minigrid.StepsOnWorlds`); training
stops at that measure's plateau (:class:`hnsdt.baselines.online.Plateau`: ``patience`` measurements without a better
one, not while ε still decays, never while no measurement has reached a goal) or at ``max_frames``, and keeps the
best measurement's weights. Departures from CleanRL, named: copies stepped together (``num_envs``, CleanRL's
default is 1), and an episode cut off by MiniGrid's step limit is not terminal (its target bootstraps from the
state it reached), as in our other learners.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.baselines.minigrid_copies import TrainingCopies, Validated
from hnsdt.baselines.online import ReplayBuffer, linear_schedule
from hnsdt.models.minigrid_nets import N_ACTIONS, MiniGridQNetwork, MiniGridQNetworkConfig
from hnsdt.models.optim import Adam


@dataclass
class MiniGridDQNConfig:
    seed: int = 0
    max_frames: int = 500_000  # the cap on env steps (all copies together); CleanRL's total_timesteps
    num_envs: int = 16  # copies stepped together
    lr: float = 2.5e-4
    gamma: float = 0.99
    buffer_size: int = 10_000  # replay capacity, in transitions
    batch_size: int = 128  # replayed transitions per gradient step
    learning_starts: int = 10_000  # frames of exploration before learning from replay
    train_every: int = 10  # frames per gradient step (CleanRL's train_frequency)
    target_period: int = 50  # gradient steps between target copies (CleanRL's 500 frames at train_frequency 10)
    epsilon_start: float = 1.0
    epsilon_end: float = 0.05
    exploration_fraction: float = 0.5  # of max_frames, over which ε decays
    eval_every: int = 50_000  # frames between validation measurements
    patience: int = 4  # measurements without a better one before stopping


def train_minigrid_dqn(env_id: str, train_seeds: list[int], fail_probs: list[float], net_cfg: MiniGridQNetworkConfig,
                       cfg: MiniGridDQNConfig, measure, progress: bool = True, desc: str = "train"):
    """Train to the plateau of ``measure`` (lower is better, with a ``ceiling``); returns ``(model in eval mode,
    curve, usage)``: the curve a row per ``eval_every`` frames (frames, episodes, gradient steps, ε, mean return
    of the episodes that ended, mean TD loss), the usage what the run used when it stopped and its measurements."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    q = MiniGridQNetwork(net_cfg)
    target = copy.deepcopy(q)
    opt = Adam(q.parameters(), lr=cfg.lr)
    validated = Validated(measure, cfg.patience)
    copies = TrainingCopies(env_id, list(train_seeds), list(fail_probs), cfg.num_envs, rng)
    n = cfg.num_envs
    states = copies.states()
    buffer = ReplayBuffer(cfg.buffer_size, states.shape[1], rng)
    explore = int(cfg.exploration_fraction * cfg.max_frames)
    frames, updates, due, next_eval, curve, finished, losses = 0, 0, 0.0, cfg.eval_every, [], [], []
    bar = tqdm(total=cfg.max_frames, desc=desc, unit="frame", disable=not progress)
    try:
        while frames < cfg.max_frames and not validated.stopped:
            # 1. act ε-greedily in every copy; store the transitions (a cut episode is not terminal)
            epsilon = linear_schedule(cfg.epsilon_start, cfg.epsilon_end, explore, frames)
            with torch.no_grad():
                greedy = q(torch.from_numpy(states)).argmax(-1).numpy()
            actions = np.where(rng.random(n) < epsilon, rng.integers(0, N_ACTIONS, n), greedy)
            reached, rewards, terminated, truncated = copies.step(actions)
            buffer.add(states, actions, rewards, reached, terminated)
            finished += rewards[terminated | truncated].tolist()
            states = copies.states()
            frames += n
            bar.update(n)
            # 2. learn: one gradient step per `train_every` frames once the buffer has warmed up
            if frames >= cfg.learning_starts:
                due += n / cfg.train_every
                while due >= 1:
                    due -= 1
                    b = {k: torch.from_numpy(v) for k, v in buffer.sample(cfg.batch_size).items()}
                    with torch.no_grad():
                        td_target = b["rewards"] + cfg.gamma * target(b["next_obs"]).max(-1).values * (
                            1 - b["terminated"])
                    value = q(b["obs"]).gather(1, b["actions"][:, None])[:, 0]
                    loss = F.mse_loss(value, td_target)
                    opt.zero_grad(set_to_none=True)
                    loss.backward()
                    opt.step()
                    losses.append(loss.item())
                    updates += 1
                    if updates % cfg.target_period == 0:
                        target.load_state_dict(q.state_dict())
            # 3. every `eval_every` frames: a curve row, and the greedy policy's steps on the validation worlds
            if frames >= next_eval or frames >= cfg.max_frames:
                next_eval += cfg.eval_every
                used = copies.used(frames, updates)
                curve.append({**used, "epsilon": epsilon, "return": float(np.mean(finished)) if finished else 0.0,
                              "loss": float(np.mean(losses)) if losses else None})
                finished, losses = [], []
                value = validated.check(q, frames, used, may_stop=frames >= explore)
                bar.set_postfix(steps=f"{value:.1f}", eps=f"{epsilon:.2f}")
    finally:
        bar.close()
        copies.close()
    return q, curve, validated.finish(q, copies.used(frames, updates))
