"""PPO baseline (Schulman et al., 2017), after CleanRL's ``ppo.py``: the clipped surrogate objective on rollouts
of every copy, with generalised advantage estimation, a value loss, an entropy bonus and global-norm clipping.

Each iteration collects ``rollout_steps`` steps of every copy with the current policy (sampled from the seed's own
generator), estimates advantages, and takes ``update_epochs`` passes over the rollout in ``minibatches`` shuffled
minibatches. Departures from CleanRL, named: the learning rate is constant (CleanRL anneals it to 0 over the
budget, which a run that stops at its plateau would not reach); an episode cut off by the step limit is not
treated as terminal: its last reward gets the discounted value of the state it reached (the replay learners'
rule, "truncation is not termination"). Acting after training is greedy in the policy (``eval_epsilon`` adds
ε-greedy noise if set), as Stable-Baselines3's ``evaluate_policy`` is by default.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.baselines.online import (OnlineAgent, OnlineConfig, OnlineRun, finish, sample_categorical, seed_configs,
                                    start_run)
from hnsdt.envs.layout import Layout
from hnsdt.models.qnetwork import ActorCritic, ActorCriticConfig


@dataclass
class PPOConfig(OnlineConfig):
    """The shared online knobs (:class:`OnlineConfig`: budget, copies, lr, γ, the plateau's; exploration_fraction
    only holds off the stop: PPO explores by its policy's entropy), plus:"""

    rollout_steps: int = 128  # steps of every copy per iteration (CleanRL's num_steps)
    update_epochs: int = 4  # passes over each rollout
    minibatches: int = 4  # shuffled minibatches per pass
    gae_lambda: float = 0.95  # λ of generalised advantage estimation
    clip_coef: float = 0.2  # the surrogate's ratio clip
    ent_coef: float = 0.01  # entropy bonus
    vf_coef: float = 0.5  # value-loss weight
    max_grad_norm: float = 0.5  # global-norm clip of each seed's gradient


def advantages(rewards, values, dones, next_value, gamma: float, lam: float) -> np.ndarray:
    """Generalised advantage estimates (…, T, N) of a rollout: ``dones[t]`` ends the episode after step t (its
    next state's value is not bootstrapped), ``next_value`` (…, N) is the value of the state after the last."""
    adv = np.zeros_like(rewards)
    last = np.zeros_like(next_value)
    for t in reversed(range(rewards.shape[-2])):
        following = next_value if t == rewards.shape[-2] - 1 else values[..., t + 1, :]
        live = 1.0 - dones[..., t, :]
        delta = rewards[..., t, :] + gamma * following * live - values[..., t, :]
        last = delta + gamma * lam * live * last
        adv[..., t, :] = last
    return adv


def train_ppo(layout: Layout | list[Layout], max_steps: int, net_cfg: ActorCriticConfig,
              cfg: PPOConfig | list[PPOConfig], progress: bool = True, desc: str = "train",
              network: type = ActorCritic, state: OnlineRun | None = None, stop_after: int | None = None,
              measure=None):
    """``layout``: one map, or a list to draw from at every reset (then ``network`` reads views). ``cfg``: one
    config, or one per seed of a stack trained in lockstep (:class:`OnlineRun`). Returns the model, its curve and
    the data used (a list of them for a list of configs); or, when ``stop_after`` env steps come before the end
    (at an iteration's end), the paused :class:`OnlineRun`, which ``state`` continues. With ``cfg.patience``,
    each seed stops at the plateau of ``measure`` (:class:`~hnsdt.baselines.online.Plateau`). Iterations are
    whole: the last may pass ``env_steps`` by less than one rollout."""
    cfgs = seed_configs(cfg)
    c, n = cfgs[0], len(cfgs)
    run = start_run(layout, max_steps, network, net_cfg, cfgs, state, measure)
    net, device, steps = run.net, run.device, run.steps
    explore_steps = int(c.exploration_fraction * c.env_steps)
    limit = c.env_steps if stop_after is None else min(stop_after, c.env_steps)
    T, N, batch = c.rollout_steps, c.num_envs, c.rollout_steps * c.num_envs
    if batch % c.minibatches:
        raise ValueError(f"rollout_steps × num_envs ({batch}) must split into {c.minibatches} equal minibatches")
    seed_rows = torch.arange(n, device=device)[:, None]
    bar = tqdm(total=c.env_steps, initial=steps, desc=desc, unit="step", unit_scale=True, disable=not progress)
    while steps < limit:
        # 1. a rollout of T steps of every copy, actions sampled from each seed's policy and generator
        obs = np.zeros((n, T, N, run.obs.shape[-1]), np.int64)
        actions = np.zeros((n, T, N), np.int64)
        log_probs, values, rewards, dones = (np.zeros((n, T, N), np.float32) for _ in range(4))
        for t in range(T):
            with torch.no_grad():
                logits, value = net(torch.from_numpy(run.obs).to(device))
            obs[:, t], values[:, t] = run.obs, value.cpu().numpy()
            actions[:, t] = np.stack([sample_categorical(logits[i], rng) for i, rng in enumerate(run.rngs)])
            log_probs[:, t] = F.log_softmax(logits, -1).gather(
                -1, torch.from_numpy(actions[:, t]).to(device)[..., None]).squeeze(-1).cpu().numpy()
            next_obs, reward, terminated, done = run.step(actions[:, t])
            reward = reward.astype(np.float32)
            cut = done & ~terminated  # the step limit, not the task, ended it: its value goes on
            if cut.any():
                with torch.no_grad():
                    reward = reward + c.gamma * np.where(cut, net(torch.from_numpy(next_obs).to(device))[1]
                                                         .cpu().numpy(), 0.0).astype(np.float32)
            rewards[:, t], dones[:, t] = reward, done
            run.restart(next_obs, done)
            steps += N
            bar.update(N)
        with torch.no_grad():
            next_value = net(torch.from_numpy(run.obs).to(device))[1].cpu().numpy()
        adv = advantages(rewards, values, dones, next_value, c.gamma, c.gae_lambda)
        returns = adv + values

        # 2. update_epochs passes of minibatches, each seed's rollout shuffled by its own generator
        flat = {"obs": obs.reshape(n, batch, -1), "actions": actions.reshape(n, batch),
                "log_probs": log_probs.reshape(n, batch), "adv": adv.reshape(n, batch),
                "returns": returns.reshape(n, batch)}
        flat = {k: torch.from_numpy(v).to(device) for k, v in flat.items()}
        entropies = []
        for _ in range(c.update_epochs):
            order = np.stack([rng.permutation(batch) for rng in run.rngs])
            for part in np.split(order, c.minibatches, axis=1):
                idx = torch.from_numpy(part).to(device)
                b = {k: v[seed_rows, idx] for k, v in flat.items()}
                logits, value = net(b["obs"])
                log_pi = F.log_softmax(logits, -1)
                ratio = (log_pi.gather(-1, b["actions"][..., None]).squeeze(-1) - b["log_probs"]).exp()
                a = b["adv"]
                a = (a - a.mean(-1, keepdim=True)) / (a.std(-1, keepdim=True) + 1e-8)
                surrogate = torch.max(-a * ratio, -a * ratio.clamp(1 - c.clip_coef, 1 + c.clip_coef)).mean(-1)
                value_loss = 0.5 * ((value - b["returns"]) ** 2).mean(-1)
                entropy = -(torch.softmax(logits, -1) * log_pi).sum(-1).mean(-1)  # (not log_pi.exp(): MKL's exp)
                run.learn(surrogate + c.vf_coef * value_loss - c.ent_coef * entropy, max_grad_norm=c.max_grad_norm)
                entropies.append(entropy.detach().cpu().numpy())

        # 3. with patience, every `validate_every` env steps: each seed's greedy steps to the exit on validation;
        # 4. a curve row every `log_every` env steps (at an iteration's end), and at each evaluation
        if run.row_due(steps, c, measure, may_stop=steps >= explore_steps):
            mean_entropy = np.mean(entropies, axis=0)
            run.curve_rows(steps, None, [{"entropy": round(float(e), 4)} for e in mean_entropy])
            bar.set_postfix(success=f"{run.curves[0][-1]['success']:.2f}", entropy=f"{mean_entropy[0]:.2f}")
        if run.done():  # every seed at its plateau
            break
    bar.close()
    return finish(run, steps, cfg)


class PPOAgent(OnlineAgent):
    """Greedy in the policy (or ε-greedy with ``epsilon`` > 0, from the seeded generator)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.epsilon_greedy(self.outputs(obs)[0].argmax(-1).cpu().numpy())


def make_agent(model, meta: dict, layout, executor, epsilon: float = 0.0, seed: int = 0) -> PPOAgent:
    """The registry's agent factory (:mod:`hnsdt.core.methods`)."""
    return PPOAgent(model, epsilon, seed, layout)
