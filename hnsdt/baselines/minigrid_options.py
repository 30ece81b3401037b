"""Option-critic on MiniGrid's own worlds (Bacon, Harb and Precup, 2017), as on our maps
(:mod:`hnsdt.baselines.options`: the deep variant with replay and a target network for the critic), one seed, with
:class:`MiniGridOptionCritic` as the network (the actor-critic's view convolutions; heads for Q_Ω, β_ω and π_ω).

Every option ω has an intra-option policy π_ω(a|s) and a termination probability β_ω(s); the policy over options
is ε-greedy in Q_Ω(s, ω), ε decaying linearly over the first ``exploration_fraction`` of the frames. Each step of
the copies (:class:`TrainingCopies`):

* the intra-option policy follows the one-step return ``g = r + γ[(1 − β_ω(s')) Q_Ω(s', ω) + β_ω(s') max Q_Ω(s')]``
  (target network) minus Q_Ω(s, ω), on every copy's current transition, with an entropy bonus;
* the termination gradient lowers β_ω(s') where ω is still better than the best option by more than the margin
  ξ (``termination_reg``), so that options last;
* the critic regresses Q_Ω(s, ω) on the same target over replayed transitions, once the buffer has warmed up.

Every ``eval_every`` frames the policy (greedy options, sampled actions and terminations:
:class:`hnsdt.agents.minigrid_play`) is measured on the validation worlds; training stops at that measure's
plateau (:class:`hnsdt.baselines.online.Plateau`, not while ε still decays, never before a goal was reached) or at
``max_frames``, and keeps the best measurement's weights. An episode cut off by MiniGrid's step limit is not
terminal.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.baselines.minigrid_copies import TrainingCopies, Validated
from hnsdt.baselines.online import ReplayBuffer, linear_schedule, sample_categorical
from hnsdt.baselines.options import choose_options
from hnsdt.models.minigrid_nets import MiniGridOptionCritic, MiniGridOptionCriticConfig
from hnsdt.models.optim import Adam


@dataclass
class MiniGridOptionsConfig:
    seed: int = 0
    max_frames: int = 500_000  # the cap on env steps (all copies together)
    num_envs: int = 16  # copies stepped together
    lr: float = 5e-4  # as on our maps (hnsdt.baselines.online.OnlineConfig)
    gamma: float = 0.99
    buffer_size: int = 50_000  # replay capacity, in transitions
    batch_size: int = 128  # replayed transitions per critic step
    learning_starts: int = 2_000  # frames before the critic learns from replay
    target_period: int = 250  # gradient steps between target copies
    epsilon_start: float = 1.0  # the policy over options' ε ...
    epsilon_end: float = 0.05  # ... decays linearly to this over exploration_fraction of max_frames
    exploration_fraction: float = 0.5
    termination_reg: float = 0.01  # ξ: the margin that keeps options from ending every step
    entropy_reg: float = 0.01  # the entropy bonus of the intra-option policies
    eval_every: int = 50_000  # frames between validation measurements
    patience: int = 4  # measurements without a better one before stopping


def train_minigrid_options(env_id: str, train_seeds: list[int], fail_probs: list[float],
                           net_cfg: MiniGridOptionCriticConfig, cfg: MiniGridOptionsConfig, measure,
                           progress: bool = True, desc: str = "train"):
    """Train to the plateau of ``measure`` (lower is better, with a ``ceiling``); returns ``(model in eval mode,
    curve, usage)``: the curve a row per ``eval_every`` frames (frames, episodes, gradient steps, ε, mean return
    of the episodes that ended, mean option length), the usage what the run used when it stopped and its
    measurements."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    net = MiniGridOptionCritic(net_cfg)
    target = copy.deepcopy(net)
    opt = Adam(net.parameters(), lr=cfg.lr)
    validated = Validated(measure, cfg.patience)
    copies = TrainingCopies(env_id, list(train_seeds), list(fail_probs), cfg.num_envs, rng)
    n, rows = cfg.num_envs, torch.arange(cfg.num_envs)
    states = copies.states()
    buffer = ReplayBuffer(cfg.buffer_size, states.shape[1], rng)
    option, need_option = np.zeros(n, np.int64), np.ones(n, bool)
    explore = int(cfg.exploration_fraction * cfg.max_frames)
    frames, updates, next_eval, curve, finished, option_ends, last_row = 0, 0, cfg.eval_every, [], [], 0, 0
    bar = tqdm(total=cfg.max_frames, desc=desc, unit="frame", disable=not progress)
    try:
        while frames < cfg.max_frames and not validated.stopped:
            # 1. pick options where the last one ended, then an action from each copy's option
            epsilon = linear_schedule(cfg.epsilon_start, cfg.epsilon_end, explore, frames)
            q, _, logits = net(torch.from_numpy(states))
            option = np.where(need_option, choose_options(q.detach(), epsilon, rng), option)
            opt_t = torch.from_numpy(option)
            pi_logits = logits[rows, opt_t]
            actions = sample_categorical(pi_logits, rng)
            reached, rewards, terminated, truncated = copies.step(actions)
            done = terminated | truncated
            buffer.add(states, actions, rewards, reached, terminated, options=option)
            finished += rewards[done].tolist()
            # 2. actor: intra-option policy gradient and termination gradient on the current transitions
            reached_t = torch.from_numpy(reached)
            q_next_online, beta_next, _ = net(reached_t)
            r_t, term_t = torch.from_numpy(rewards.astype(np.float32)), torch.from_numpy(terminated.astype(np.float32))
            b = beta_next[rows, opt_t]  # β of each copy's option in the state it reached
            with torch.no_grad():
                q_next = target(reached_t)[0]
                g = r_t + cfg.gamma * (1 - term_t) * ((1 - b) * q_next[rows, opt_t] + b * q_next.max(-1).values)
                advantage = g - q[rows, opt_t]
                margin = q_next_online[rows, opt_t] - q_next_online.max(-1).values + cfg.termination_reg
            log_pi = F.log_softmax(pi_logits, -1)
            entropy = -(torch.softmax(pi_logits, -1) * log_pi).sum(-1)
            chosen = log_pi.gather(1, torch.from_numpy(actions)[:, None])[:, 0]
            loss = (-(chosen * advantage) - cfg.entropy_reg * entropy
                    + b * margin * torch.from_numpy((~done).astype(np.float32))).mean()
            # 3. critic: replayed one-step targets through the option's termination
            if frames >= cfg.learning_starts:
                s = {k: torch.from_numpy(v) for k, v in buffer.sample(cfg.batch_size).items()}
                idx = torch.arange(cfg.batch_size)
                with torch.no_grad():
                    q_t = target(s["next_obs"])[0]
                    b_t = net(s["next_obs"])[1][idx, s["option"]]
                    y = s["rewards"] + cfg.gamma * (1 - s["terminated"]) * (
                        (1 - b_t) * q_t[idx, s["option"]] + b_t * q_t.max(-1).values)
                loss = loss + 0.5 * F.mse_loss(net(s["obs"])[0][idx, s["option"]], y)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            updates += 1
            if updates % cfg.target_period == 0:
                target.load_state_dict(net.state_dict())
            # 4. options end by their termination draw or with the episode
            need_option = (rng.random(n) < b.detach().numpy()) | done
            option_ends += int(need_option.sum())
            states = copies.states()
            frames += n
            bar.update(n)
            # 5. every `eval_every` frames: a curve row, and the policy's steps on the validation worlds
            if frames >= next_eval or frames >= cfg.max_frames:
                next_eval += cfg.eval_every
                used = copies.used(frames, updates)
                curve.append({**used, "epsilon": epsilon, "return": float(np.mean(finished)) if finished else 0.0,
                              "option_length": (frames - last_row) / max(option_ends, 1)})
                finished, option_ends, last_row = [], 0, frames
                value = validated.check(net, frames, used, may_stop=frames >= explore)
                bar.set_postfix(steps=f"{value:.1f}", eps=f"{epsilon:.2f}")
    finally:
        bar.close()
        copies.close()
    return net, curve, validated.finish(net, copies.used(frames, updates))
