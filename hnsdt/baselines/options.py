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

from hnsdt.baselines.online import OnlineAgent, OnlineConfig, OnlineRun, linear_schedule, start_run
from hnsdt.envs.layout import Layout
from hnsdt.models.qnetwork import OptionCritic, OptionCriticConfig


@dataclass
class OptionsConfig(OnlineConfig):
    """The shared online knobs (:class:`OnlineConfig`; ε is that of the policy over options), plus:"""

    termination_reg: float = 0.01  # ξ: margin that keeps options from terminating every step
    entropy_reg: float = 0.01  # entropy bonus of the intra-option policies


def sample_categorical(logits: torch.Tensor, rng: np.random.Generator) -> np.ndarray:
    """One draw per row from softmax(logits), with numpy's seeded generator."""
    probs = torch.softmax(logits, -1).detach().cpu().numpy().astype(np.float64)
    cum = probs.cumsum(-1)
    u = rng.random(len(probs))[:, None] * cum[:, -1:]
    return np.minimum((u > cum).sum(-1), probs.shape[1] - 1)


def choose_options(q: torch.Tensor, epsilon: float, rng: np.random.Generator) -> np.ndarray:
    greedy = q.argmax(-1).cpu().numpy()
    return np.where(rng.random(len(greedy)) < epsilon, rng.integers(0, q.shape[1], len(greedy)), greedy)


def train_options(layout: Layout | list[Layout], max_steps: int, net_cfg: OptionCriticConfig, cfg: OptionsConfig,
                  progress: bool = True, desc: str = "train", network: type = OptionCritic,
                  state: OnlineRun | None = None, stop_after: int | None = None):
    """``layout``: one map, or a list to draw from at every reset (then ``network`` reads views). Returns the
    model, its curve and the data used; or, when ``stop_after`` env steps come before the end, the paused
    :class:`OnlineRun`, which ``state`` continues."""
    run = start_run(layout, max_steps, network, net_cfg, cfg, state)
    rng, device, env, net, target = run.rng, run.device, run.env, run.net, run.target
    obs, buffer, stats, steps, curve = run.obs, run.buffer, run.stats, run.steps, run.curve
    rows = torch.arange(cfg.num_envs, device=device)
    option = run.loop.get("option", np.zeros(cfg.num_envs, np.int64))
    need_option = run.loop.get("need_option", np.ones(cfg.num_envs, bool))
    next_log, lengths = run.loop.get("next_log", cfg.log_every), run.loop.get("lengths", [])
    option_steps = run.loop.get("option_steps", 0)
    explore_steps = int(cfg.exploration_fraction * cfg.env_steps)
    limit = cfg.env_steps if stop_after is None else min(stop_after, cfg.env_steps)
    bar = tqdm(total=cfg.env_steps, initial=steps, desc=desc, unit="step", unit_scale=True, disable=not progress)
    while steps < limit:
        # 1. pick options where the last one terminated, then an action from each copy's option
        epsilon = linear_schedule(cfg.epsilon_start, cfg.epsilon_end, explore_steps, steps)
        q, _, logits = net(torch.from_numpy(obs).to(device))
        if need_option.any():
            option = np.where(need_option, choose_options(q.detach(), epsilon, rng), option)
        opt_t = torch.from_numpy(option).to(device)
        pi_logits = logits[rows, opt_t]
        actions = sample_categorical(pi_logits, rng)
        next_obs, rewards, terminated, truncated, _ = env.step(actions)
        done = terminated | truncated
        buffer.add(obs, actions, rewards, next_obs, terminated, options=option)
        stats.update(rewards, terminated, done)

        # 2. actor: intra-option policy gradient and termination gradient on the current transitions
        next_t = torch.from_numpy(next_obs).to(device)
        q_next_online, beta_next, _ = net(next_t)
        r_t = torch.from_numpy(rewards.astype(np.float32)).to(device)
        term_t = torch.from_numpy(terminated.astype(np.float32)).to(device)
        with torch.no_grad():
            q_next = target(next_t)[0]
            b = beta_next[rows, opt_t]
            g = r_t + cfg.gamma * (1 - term_t) * ((1 - b) * q_next[rows, opt_t] + b * q_next.max(-1).values)
            advantage = g - q[rows, opt_t]
            margin = q_next_online[rows, opt_t] - q_next_online.max(-1).values + cfg.termination_reg
        log_pi = F.log_softmax(pi_logits, -1)
        entropy = -(log_pi.exp() * log_pi).sum(-1)
        chosen = log_pi.gather(1, torch.from_numpy(actions).to(device)[:, None]).squeeze(1)
        policy_loss = -(chosen * advantage) - cfg.entropy_reg * entropy
        termination_loss = beta_next[rows, opt_t] * margin * torch.from_numpy((~done).astype(np.float32)).to(device)
        loss = (policy_loss + termination_loss).mean()

        # 3. critic: replayed one-step targets through the option's termination
        if steps >= cfg.learning_starts:
            s = {k: torch.from_numpy(v).to(device) for k, v in buffer.sample(cfg.batch_size).items()}
            idx = torch.arange(cfg.batch_size, device=device)
            with torch.no_grad():
                q_t = target(s["next_obs"])[0]
                b_t = net(s["next_obs"])[1][idx, s["option"]]
                y = s["rewards"] + cfg.gamma * (1 - s["terminated"]) * (
                    (1 - b_t) * q_t[idx, s["option"]] + b_t * q_t.max(-1).values)
            critic = net(s["obs"])[0][idx, s["option"]]
            loss = loss + 0.5 * F.mse_loss(critic, y)
        run.learn(loss, cfg.target_period)

        # 4. options end by their termination draw or with the episode
        ended = rng.random(cfg.num_envs) < beta_next[rows, opt_t].detach().cpu().numpy()
        option_steps += cfg.num_envs
        lengths.append(int((ended | done).sum()))
        need_option = ended | done
        obs = env.reset(options={"reset_mask": done})[0] if done.any() else next_obs
        steps += cfg.num_envs
        bar.update(cfg.num_envs)
        if steps >= next_log or steps >= cfg.env_steps:
            next_log += cfg.log_every
            curve.append(run.curve_row(steps, epsilon, option_length=option_steps / max(sum(lengths), 1)))
            lengths, option_steps = [], 0
            bar.set_postfix(success=f"{curve[-1]['success']:.2f}", eps=f"{epsilon:.2f}")
    bar.close()
    if steps < cfg.env_steps:
        return run.pause(steps, obs, curve, option=option, need_option=need_option, next_log=next_log,
                         lengths=lengths, option_steps=option_steps)
    return run.result(steps, curve)


class OptionsAgent(OnlineAgent):
    """Call-and-return execution of the learned options: sampled actions and terminations, greedy options."""

    def reset(self, obs: np.ndarray) -> None:
        self.option = np.zeros(len(obs), np.int64)
        self.need_option = np.ones(len(obs), bool)

    def act(self, obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            q, beta, logits = self.model(self.states(obs))
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
