"""Options baseline: hierarchical RL with 8 learned options, trained online by option-critic (Bacon, Harb and
Precup, 2017), in the deep variant with replay and a target network for the critic.

Every option ω has an intra-option policy π_ω(a|s) and a termination probability β_ω(s); the policy over
options is ε-greedy in Q_Ω(s, ω). Each step:

* the critic regresses Q_Ω(s, ω) on ``r + γ[(1 − β_ω(s')) Q_Ω(s', ω) + β_ω(s') max_ω' Q_Ω(s', ω')]`` (target
  network, replayed transitions);
* the intra-option policy follows that one-step return minus Q_Ω(s, ω) (on-policy, every copy's current
  transition), with an entropy bonus;
* the termination gradient lowers β_ω(s') where ω is still better than the best option by more than a margin
  ξ (``termination_reg``), so options last.

Acting after training samples actions from π_ω and terminations from β_ω (seeded); options are greedy in Q_Ω
(``eval_epsilon`` adds ε-greedy noise if set).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from hnsdt.baselines.online import (OnlineAgent, OnlineRun, ReplayConfig, finish, linear_schedule,
                                    sample_categorical, seed_configs, start_run)
from hnsdt.envs.layout import Layout
from hnsdt.models.qnetwork import OptionCritic, OptionCriticConfig


@dataclass
class OptionsConfig(ReplayConfig):
    """The shared online knobs (:class:`ReplayConfig`; ε is that of the policy over options), plus:"""

    termination_reg: float = 0.01  # ξ: margin that keeps options from terminating every step
    entropy_reg: float = 0.01  # entropy bonus of the intra-option policies


def choose_options(q: torch.Tensor, epsilon: float, rng: np.random.Generator) -> np.ndarray:
    greedy = q.argmax(-1).cpu().numpy()
    return np.where(rng.random(len(greedy)) < epsilon, rng.integers(0, q.shape[1], len(greedy)), greedy)


def train_options(layout: Layout | list[Layout], max_steps: int, net_cfg: OptionCriticConfig,
                  cfg: OptionsConfig | list[OptionsConfig], progress: bool = True, desc: str = "train",
                  network: type = OptionCritic, state: OnlineRun | None = None, stop_after: int | None = None,
                  measure=None):
    """``layout``: one map, or a list to draw from at every reset (then ``network`` reads views). ``cfg``: one
    config, or one per seed of a stack trained in lockstep (:class:`OnlineRun`). Returns the model, its curve and
    the data used (a list of them for a list of configs); or, when ``stop_after`` env steps come before the end,
    the paused :class:`OnlineRun`, which ``state`` continues. With ``cfg.patience``, each seed stops at the
    plateau of ``measure`` (:class:`~hnsdt.baselines.online.Plateau`)."""
    cfgs = seed_configs(cfg)
    c, n = cfgs[0], len(cfgs)
    run = start_run(layout, max_steps, network, net_cfg, cfgs, state, measure)
    net, target, device, steps = run.net, run.target, run.device, run.steps
    seed_rows = torch.arange(n, device=device)[:, None]  # (with copy_rows: each copy's option of each seed)
    copy_rows = torch.arange(c.num_envs, device=device)[None, :]
    option = run.loop.get("option", np.zeros((n, c.num_envs), np.int64))
    need_option = run.loop.get("need_option", np.ones((n, c.num_envs), bool))
    lengths = run.loop.get("lengths", [[] for _ in cfgs])
    option_steps = run.loop.get("option_steps", 0)
    explore_steps = int(c.exploration_fraction * c.env_steps)
    limit = c.env_steps if stop_after is None else min(stop_after, c.env_steps)
    bar = tqdm(total=c.env_steps, initial=steps, desc=desc, unit="step", unit_scale=True, disable=not progress)
    while steps < limit:
        # 1. pick options where the last one terminated, then an action from each copy's option
        epsilon = linear_schedule(c.epsilon_start, c.epsilon_end, explore_steps, steps)
        q, _, logits = net(torch.from_numpy(run.obs).to(device))
        for i, rng in enumerate(run.rngs):
            if need_option[i].any():
                option[i] = np.where(need_option[i], choose_options(q[i].detach(), epsilon, rng), option[i])
        opt_t = torch.from_numpy(option).to(device)
        pi_logits = logits[seed_rows, copy_rows, opt_t]
        actions = np.stack([sample_categorical(pi_logits[i], rng) for i, rng in enumerate(run.rngs)])
        next_obs, rewards, terminated, done = run.step(actions, options=option)

        # 2. actor: intra-option policy gradient and termination gradient on the current transitions
        next_t = torch.from_numpy(next_obs).to(device)
        q_next_online, beta_next, _ = net(next_t)
        r_t = torch.from_numpy(rewards.astype(np.float32)).to(device)
        term_t = torch.from_numpy(terminated.astype(np.float32)).to(device)
        b = beta_next[seed_rows, copy_rows, opt_t]  # β of each copy's option in the state it reached
        with torch.no_grad():
            q_next = target(next_t)[0]
            g = r_t + c.gamma * (1 - term_t) * ((1 - b) * q_next[seed_rows, copy_rows, opt_t]
                                                + b * q_next.max(-1).values)
            advantage = g - q[seed_rows, copy_rows, opt_t]
            margin = q_next_online[seed_rows, copy_rows, opt_t] - q_next_online.max(-1).values + c.termination_reg
        log_pi = F.log_softmax(pi_logits, -1)
        entropy = -(torch.softmax(pi_logits, -1) * log_pi).sum(-1)  # (not log_pi.exp(): MKL's exp)
        chosen = log_pi.gather(-1, torch.from_numpy(actions).to(device)[..., None]).squeeze(-1)
        policy_loss = -(chosen * advantage) - c.entropy_reg * entropy
        termination_loss = b * margin * torch.from_numpy((~done).astype(np.float32)).to(device)
        losses = (policy_loss + termination_loss).mean(-1)  # (seeds,)

        # 3. critic: replayed one-step targets through the option's termination
        if steps >= c.learning_starts:
            s = run.sample(c.batch_size)
            idx = torch.arange(c.batch_size, device=device)[None, :]
            with torch.no_grad():
                q_t = target(s["next_obs"])[0]
                b_t = net(s["next_obs"])[1][seed_rows, idx, s["option"]]
                y = s["rewards"] + c.gamma * (1 - s["terminated"]) * (
                    (1 - b_t) * q_t[seed_rows, idx, s["option"]] + b_t * q_t.max(-1).values)
            critic = net(s["obs"])[0][seed_rows, idx, s["option"]]
            losses = losses + 0.5 * F.mse_loss(critic, y, reduction="none").mean(-1)
        run.learn(losses, c.target_period)

        # 4. options end by their termination draw or with the episode
        ended = np.stack([rng.random(c.num_envs) < beta for rng, beta in zip(run.rngs, b.detach().cpu().numpy())])
        option_steps += c.num_envs
        for seed_lengths, e, d in zip(lengths, ended, done):
            seed_lengths.append(int((e | d).sum()))
        need_option = ended | done
        run.restart(next_obs, done)
        steps += c.num_envs
        bar.update(c.num_envs)
        # with patience, every `validate_every` env steps: each seed's greedy steps to the exit on validation;
        # a curve row every `log_every` env steps, and at each evaluation
        if run.row_due(steps, c, measure, may_stop=steps >= explore_steps):
            run.curve_rows(steps, epsilon, [{"option_length": option_steps / max(sum(seed_lengths), 1)}
                                            for seed_lengths in lengths])
            lengths, option_steps = [[] for _ in cfgs], 0
            bar.set_postfix(success=f"{run.curves[0][-1]['success']:.2f}", eps=f"{epsilon:.2f}")
        if run.done():  # every seed at its plateau
            break
    bar.close()
    return finish(run, steps, cfg, option=option, need_option=need_option, lengths=lengths,
                  option_steps=option_steps)


class OptionsAgent(OnlineAgent):
    """Call-and-return execution of the learned options: sampled actions and terminations, greedy options."""

    def reset(self, obs: np.ndarray) -> None:
        self.option = np.zeros(len(obs), np.int64)
        self.need_option = np.ones(len(obs), bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        q, beta, logits = self.outputs(obs)
        rows = torch.arange(len(obs))
        # an option that has run one step ends with probability β_ω(s) in the state it reached
        ended = self.rng.random(len(obs)) < beta[rows, torch.from_numpy(self.option)].cpu().numpy()
        need = self.need_option | ended
        self.option = np.where(need, choose_options(q, self.epsilon, self.rng), self.option)
        self.need_option[:] = False
        return sample_categorical(logits[rows, torch.from_numpy(self.option)], self.rng)


def make_agent(model, meta: dict, layout, executor, epsilon: float = 0.0, seed: int = 0) -> OptionsAgent:
    """The registry's agent factory (:mod:`hnsdt.core.methods`)."""
    return OptionsAgent(model, epsilon, seed, layout)
