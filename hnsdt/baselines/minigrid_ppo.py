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

from hnsdt.baselines.online import Plateau, sample_categorical
from hnsdt.baselines.ppo import advantages
from hnsdt.minigrid.live import make_env
from hnsdt.models.minigrid_nets import MiniGridActorCritic, MiniGridActorCriticConfig, step_states
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


class _Copies:
    """``num_envs`` MiniGrid envs, each reset onto a training world drawn by ``rng`` when its episode ends."""

    def __init__(self, env_id: str, seeds: list[int], fail_probs: list[float], n: int, rng: np.random.Generator):
        self.seeds, self.rng = seeds, rng
        self.envs = [make_env(env_id, fail_probs[i % len(fail_probs)]) for i in range(n)]
        self.episodes = 0
        self.obs = [None] * n
        for i in range(n):
            self.reset(i)

    def reset(self, i: int) -> None:
        seed = int(self.rng.choice(self.seeds))
        self.obs[i], _ = self.envs[i].reset(seed=seed, options={"failure_seed": self.episodes})
        self.episodes += 1

    def states(self) -> np.ndarray:
        """Every copy's state vector (:func:`step_states`)."""
        return np.stack([self.state(i, self.obs[i]) for i in range(len(self.envs))])

    def state(self, i: int, obs) -> np.ndarray:
        """What the actor-critic reads of an observation, as a state vector: the direction and the view (the
        cell and the carried object, which it never reads, left 0: the run need not read the world's state)."""
        return step_states([0, 0, int(obs["direction"]), 0, 0], obs["image"])

    def close(self) -> None:
        for env in self.envs:
            env.close()


def train_minigrid_ppo(env_id: str, train_seeds: list[int], fail_probs: list[float], net_cfg: MiniGridActorCriticConfig,
                       cfg: MiniGridPPOConfig, measure, progress: bool = True, desc: str = "train"):
    """Train to the plateau of ``measure`` (lower is better, with a ``ceiling``); returns ``(model in eval mode,
    curve, usage)``: the curve a row per iteration (frames, episodes, mean return of the episodes that ended),
    the usage what the run used when it stopped and its measurements."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    model = MiniGridActorCritic(net_cfg)
    opt = Adam(model.parameters(), lr=cfg.lr, eps=cfg.adam_eps)
    plateau = Plateau(cfg.patience, float(getattr(measure, "floor", float("-inf"))),
                      float(getattr(measure, "ceiling", float("inf"))))
    copies = _Copies(env_id, list(train_seeds), list(fail_probs), cfg.num_envs, rng)
    n, T = cfg.num_envs, cfg.rollout_steps
    frames, updates, next_eval, curve, finished = 0, 0, cfg.eval_every, [], []
    states = copies.states()
    bar = tqdm(total=cfg.max_frames, desc=desc, unit="frame", disable=not progress)
    try:
        while frames < cfg.max_frames and plateau.stopped is None:
            buf_s = np.zeros((T, n, states.shape[1]), np.int64)
            buf_a, buf_logp = np.zeros((T, n), np.int64), np.zeros((T, n), np.float32)
            buf_r, buf_v, buf_d = (np.zeros((T, n), np.float32) for _ in range(3))
            for t in range(T):
                with torch.no_grad():
                    logits, value = model(torch.from_numpy(states))
                actions = sample_categorical(logits, rng)
                buf_s[t], buf_a[t], buf_v[t] = states, actions, value.numpy()
                buf_logp[t] = F.log_softmax(logits, -1).gather(1, torch.from_numpy(actions)[:, None])[:, 0].numpy()
                cut = []
                for i, a in enumerate(actions):
                    obs, reward, terminated, truncated, _ = copies.envs[i].step(int(a))
                    buf_r[t, i] = reward
                    if terminated or truncated:
                        buf_d[t, i] = 1.0
                        finished.append(float(reward))
                        if truncated and not terminated:  # (not terminal: bootstrap from where it stopped)
                            cut.append((i, copies.state(i, obs)))
                        copies.reset(i)
                    else:
                        copies.obs[i] = obs
                if cut:
                    with torch.no_grad():
                        _, v = model(torch.from_numpy(np.stack([s for _, s in cut])))
                    for (i, _), value_cut in zip(cut, v.numpy()):
                        buf_r[t, i] += cfg.gamma * value_cut
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
            curve.append({"frames": frames, "episodes": copies.episodes - n, "gradient_steps": updates,
                          "return": float(np.mean(finished)) if finished else 0.0})
            finished = []
            if frames >= next_eval or frames >= cfg.max_frames:
                next_eval += cfg.eval_every
                model.eval()
                value = float(measure(model))
                model.train()
                plateau.update(frames, value, model, {"frames": frames, "episodes": copies.episodes - n,
                                                      "gradient_steps": updates})
                bar.set_postfix(steps=f"{value:.1f}")
    finally:
        bar.close()
        copies.close()
    if plateau.best is not None:
        model.load_state_dict(plateau.best[3])
    used = plateau.stopped or {"frames": frames, "episodes": copies.episodes - n, "gradient_steps": updates}
    model.eval()
    return model, curve, {**used, **plateau.record()}
