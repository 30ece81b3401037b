"""PPO on MiniGrid's own worlds, after CleanRL's ``ppo.py`` and MiniGrid's starter code (``rl-starter-files``, whose
defaults these are): the clipped surrogate on rollouts of ``num_envs`` copies of the env, generalised advantage
estimation, a value loss, an entropy bonus, global-norm clipping, :class:`MiniGridActorCritic` as the network.

Each copy plays the training worlds (MiniGrid's reset seeds, drawn by the run's generator at every reset) under one
of the failure probabilities (copy i: ``fail_probs[i % len]``), so PPO meets the worlds and failures the offline
learners' datasets hold. Every ``eval_every`` frames the greedy policy is measured on the validation worlds
(:class:`hnsdt.evaluation.minigrid.StepsOnWorlds`); training stops at that measure's plateau
(:class:`hnsdt.baselines.online.Plateau`: ``patience`` measurements without a better one, never while no
measurement has reached a goal) or at ``max_frames``, and keeps the best measurement's weights. Departures from
CleanRL, named as in :mod:`hnsdt.baselines.ppo`: a constant learning rate, and an episode cut off by MiniGrid's step
limit is not terminal (its last reward gets the discounted value of the state it reached).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.baselines.online import sample_categorical
from hnsdt.baselines.ppo import advantages
from hnsdt.baselines.minigrid_copies import TrainingCopies, Validated
from hnsdt.models.minigrid_nets import MiniGridActorCritic, MiniGridActorCriticConfig
from hnsdt.models.optim import Adam


@dataclass
class MiniGridPPOConfig:
    seed: int = 0
    max_frames: int = 1_000_000  # the cap on env steps (all copies together)
    num_envs: int = 16  # copies stepped together
    rollout_steps: int = 128  # steps of every copy per iteration
    lr: float = 1e-3
    adam_eps: float = 1e-8
    gamma: float = 0.99
    gae_lambda: float = 0.95
    update_epochs: int = 4  # passes over each rollout
    batch_size: int = 256  # steps per minibatch
    clip_coef: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    eval_every: int = 50_000  # frames between validation measurements
    patience: int = 4  # measurements without a better one before stopping


def train_minigrid_ppo(env_id: str, train_seeds: list[int], fail_probs: list[float], net_cfg: MiniGridActorCriticConfig,
                       cfg: MiniGridPPOConfig, measure, progress: bool = True, desc: str = "train"):
    """Train to the plateau of ``measure`` (lower is better, with a ``ceiling``); returns ``(model in eval mode,
    curve, usage)``: the curve a row per iteration (frames, episodes, mean return of the episodes that ended),
    the usage what the run used when it stopped and its measurements."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    model = MiniGridActorCritic(net_cfg)
    opt = Adam(model.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
    validated = Validated(measure, cfg.patience)
    copies = TrainingCopies(env_id, list(train_seeds), list(fail_probs), cfg.num_envs, rng)
    n, T = cfg.num_envs, cfg.rollout_steps
    frames, updates, next_eval, curve, finished = 0, 0, cfg.eval_every, [], []
    states = copies.states()
    bar = tqdm(total=cfg.max_frames, desc=desc, unit="frame", disable=not progress)
    try:
        while frames < cfg.max_frames and not validated.stopped:
            buf_s = np.zeros((T, n, states.shape[1]), np.int64)
            buf_a, buf_logp = np.zeros((T, n), np.int64), np.zeros((T, n), np.float32)
            buf_r, buf_v, buf_d = (np.zeros((T, n), np.float32) for _ in range(3))
            for t in range(T):
                with torch.no_grad():
                    logits, value = model(torch.from_numpy(states))
                actions = sample_categorical(logits, rng)
                buf_s[t], buf_a[t], buf_v[t] = states, actions, value.numpy()
                buf_logp[t] = F.log_softmax(logits, -1).gather(1, torch.from_numpy(actions)[:, None])[:, 0].numpy()
                reached, rewards, terminated, truncated = copies.step(actions)
                buf_r[t], buf_d[t] = rewards, terminated | truncated
                finished += rewards[terminated | truncated].tolist()
                cut = np.flatnonzero(truncated & ~terminated)  # (not terminal: bootstrap from where it stopped)
                if len(cut):
                    with torch.no_grad():
                        _, v = model(torch.from_numpy(reached[cut]))
                    buf_r[t, cut] += cfg.gamma * v.numpy()
                states = copies.states()
            with torch.no_grad():
                _, next_value = model(torch.from_numpy(states))
            adv = advantages(buf_r, buf_v, buf_d, next_value.numpy(), cfg.gamma, cfg.gae_lambda)
            returns = adv + buf_v
            flat = lambda x: torch.from_numpy(np.ascontiguousarray(x.reshape(T * n, *x.shape[2:])))  # noqa: E731
            b_s, b_a, b_logp, b_adv, b_ret = map(flat, (buf_s, buf_a, buf_logp, adv, returns))
            for _ in range(cfg.update_epochs):
                order = torch.from_numpy(rng.permutation(T * n))
                for start in range(0, T * n, cfg.batch_size):
                    mb = order[start:start + cfg.batch_size]
                    logits, value = model(b_s[mb])
                    logp_all = F.log_softmax(logits, -1)
                    ratio = (logp_all.gather(1, b_a[mb][:, None])[:, 0] - b_logp[mb]).exp()
                    a = b_adv[mb]
                    a = (a - a.mean()) / (a.std() + 1e-8)
                    pg = torch.max(-a * ratio, -a * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)).mean()
                    v_loss = 0.5 * ((value - b_ret[mb]) ** 2).mean()
                    entropy = -(logp_all.exp() * logp_all).sum(-1).mean()
                    loss = pg + cfg.vf_coef * v_loss - cfg.ent_coef * entropy
                    opt.zero_grad(set_to_none=True)
                    loss.backward()
                    torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.max_grad_norm)
                    opt.step()
                    updates += 1
            frames += T * n
            bar.update(T * n)
            curve.append({**copies.used(frames, updates), "return": float(np.mean(finished)) if finished else 0.0})
            finished = []
            if frames >= next_eval or frames >= cfg.max_frames:
                next_eval += cfg.eval_every
                value = validated.check(model, frames, copies.used(frames, updates))
                bar.set_postfix(steps=f"{value:.1f}")
    finally:
        bar.close()
        copies.close()
    return model, curve, validated.finish(model, copies.used(frames, updates))
