"""What the online learners share: the training environment, a replay buffer, the ε schedule and the
per-episode statistics of the training curve."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
import torch

from hnsdt.envs.layout import Layout
from hnsdt.envs.vector import KeyDoorVectorEnv, Streams
from hnsdt.models.optim import Adam


@dataclass
class OnlineConfig:
    """Knobs every online learner has; each learner's config adds its own."""

    env_steps: int = 50_000  # environment steps to train for (summed over the parallel copies)
    num_envs: int = 8  # environment copies stepped together
    fail_probs: tuple[float, ...] = (0.0, 0.1, 0.2, 0.3)  # the copies cycle through these
    lr: float = 5e-4  # Adam learning rate
    gamma: float = 0.99  # discount
    buffer_size: int = 50_000  # replay capacity, in transitions
    batch_size: int = 128  # replayed transitions per gradient step
    learning_starts: int = 2_000  # env steps of exploration before learning from replay
    target_period: int = 250  # gradient steps between target-network copies
    epsilon_start: float = 1.0  # exploration ε at the start ...
    epsilon_end: float = 0.05  # ... decays linearly to this ...
    exploration_fraction: float = 0.5  # ... over this fraction of env_steps
    seed: int = 0
    device: str = "cpu"
    log_every: int = 2_000  # env steps between training-curve rows


def training_env(layout: Layout | list[Layout], max_steps: int, num_envs: int, fail_probs, view_radius: int = 0):
    """``num_envs`` copies whose failure probabilities cycle through ``fail_probs``, so one policy learns
    the same mix of failure probabilities the offline methods see in the dataset. A list of layouts (the
    generalisation experiment) gives copies that each draw a layout of the list at every reset and observe
    view states (:class:`~hnsdt.envs.pool.LayoutPoolVectorEnv`)."""
    per_copy = np.resize(np.asarray(fail_probs, dtype=np.float64), num_envs)
    if isinstance(layout, (list, tuple)):
        from hnsdt.envs.pool import LayoutPoolVectorEnv

        return LayoutPoolVectorEnv(layout, num_envs, per_copy, max_steps, view_radius)
    return KeyDoorVectorEnv(num_envs, layout, per_copy, max_steps)


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    return end if duration <= 0 else max(end, start + (end - start) * t / duration)


class ReplayBuffer:
    """Uniform replay of (s, a, r, s', terminated) plus any extra integer column (the option, for
    option-critic). Truncated episodes are stored as not terminated so their value is bootstrapped."""

    def __init__(self, size: int, state_dim: int, rng: np.random.Generator):
        self.size, self.rng, self.n, self.pos = size, rng, 0, 0
        self.obs = np.zeros((size, state_dim), np.int64)
        self.next_obs = np.zeros((size, state_dim), np.int64)
        self.actions = np.zeros(size, np.int64)
        self.options = np.zeros(size, np.int64)
        self.rewards = np.zeros(size, np.float32)
        self.terminated = np.zeros(size, np.float32)

    def add(self, obs, actions, rewards, next_obs, terminated, options=None) -> None:
        k = len(obs)
        idx = (self.pos + np.arange(k)) % self.size
        self.obs[idx], self.actions[idx], self.rewards[idx] = obs, actions, rewards
        self.next_obs[idx], self.terminated[idx] = next_obs, terminated
        if options is not None:
            self.options[idx] = options
        self.pos = int((self.pos + k) % self.size)
        self.n = min(self.n + k, self.size)

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        idx = self.rng.integers(0, self.n, batch_size)
        return {"obs": self.obs[idx], "actions": self.actions[idx], "rewards": self.rewards[idx],
                "next_obs": self.next_obs[idx], "terminated": self.terminated[idx], "option": self.options[idx]}


class EpisodeStats:
    """Running return, length and success of each copy; the finished episodes since the last curve row."""

    def __init__(self, n: int):
        self.ret = np.zeros(n)
        self.length = np.zeros(n, np.int64)
        self.finished: list[tuple[float, int, bool]] = []
        self.episodes = 0

    def update(self, rewards, terminated, done) -> None:
        self.ret += rewards
        self.length += 1
        for i in np.flatnonzero(done):
            self.finished.append((float(self.ret[i]), int(self.length[i]), bool(terminated[i])))
        self.episodes += int(done.sum())
        self.ret[done], self.length[done] = 0.0, 0

    def row(self) -> dict:
        """Mean return / success / length of the episodes finished since the previous row (NaN if none)."""
        f, self.finished = self.finished, []
        if not f:
            return {"episodes": self.episodes, "return": float("nan"), "success": float("nan"),
                    "length": float("nan")}
        r, n, s = zip(*f)
        return {"episodes": self.episodes, "return": float(np.mean(r)), "success": float(np.mean(s)),
                "length": float(np.mean(n))}


@dataclass
class OnlineRun:
    """What every online learner starts from, built in one order so that a seed gives the same run."""

    rng: np.random.Generator  # actions, exploration and replay sampling
    device: torch.device
    env: KeyDoorVectorEnv
    net: torch.nn.Module
    target: torch.nn.Module  # a copy of ``net``, refreshed every ``target_period`` gradient steps
    opt: torch.optim.Optimizer
    obs: np.ndarray
    buffer: ReplayBuffer
    stats: EpisodeStats
    grad_steps: int = 0
    losses: list[float] = field(default_factory=list)  # since the last curve row
    steps: int = 0  # env steps so far
    curve: list[dict] = field(default_factory=list)
    loop: dict = field(default_factory=dict)  # the learner's own loop variables, kept while paused
    torch_rng: torch.Tensor | None = None  # the torch stream, kept while paused (no learner here draws from it yet)

    def pause(self, steps: int, obs: np.ndarray, curve: list[dict], **loop) -> OnlineRun:
        """The run as it stands, to continue later, in this process or another (pickled whole: the networks,
        the optimiser, the copies, the buffer and the streams), to the same bytes as one run in one go."""
        self.steps, self.obs, self.curve, self.loop = steps, obs, curve, loop
        self.torch_rng = torch.get_rng_state()
        return self

    def resume(self) -> OnlineRun:
        if self.torch_rng is not None:
            torch.set_rng_state(self.torch_rng)
        return self

    def learn(self, loss: torch.Tensor, target_period: int) -> None:
        """One Adam step on ``loss``; the target network copies the online one every ``target_period`` steps."""
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.opt.step()
        self.grad_steps += 1
        self.losses.append(loss.item())
        if self.grad_steps % target_period == 0:
            self.target.load_state_dict(self.net.state_dict())

    def curve_row(self, steps: int, epsilon: float, **extra) -> dict:
        """A training-curve row: env steps, ε, the episodes finished and the mean loss since the last row."""
        row = {"step": steps, "epsilon": round(epsilon, 4), **self.stats.row(),
               "loss": float(np.mean(self.losses)) if self.losses else float("nan"), **extra}
        self.losses = []
        return row

    def result(self, steps: int, curve: list[dict]) -> tuple[torch.nn.Module, list[dict], dict]:
        """The trainer's return: the network (eval mode), its curve and the data it used."""
        self.net.eval()
        return self.net, curve, {"env_steps": steps, "episodes": self.stats.episodes,
                                 "gradient_steps": self.grad_steps}


def start_run(layout: Layout | list[Layout], max_steps: int, network: type, net_cfg, cfg: OnlineConfig,
              state: OnlineRun | None = None) -> OnlineRun:
    """Seed torch and numpy, build the training copies, the network (``network(net_cfg)``), its target
    copy, Adam, the first observations, the replay buffer and the episode statistics; or continue ``state``,
    a paused run (:meth:`OnlineRun.pause`)."""
    if state is not None:
        return state.resume()
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    device = torch.device(cfg.device)
    env = training_env(layout, max_steps, cfg.num_envs, cfg.fail_probs, getattr(net_cfg, "view_radius", 0))
    net = network(net_cfg).to(device)
    target = copy.deepcopy(net)
    opt = Adam(net.parameters(), lr=cfg.lr)
    obs, _ = env.reset(seed=cfg.seed)
    return OnlineRun(rng, device, env, net, target, opt, obs, ReplayBuffer(cfg.buffer_size, obs.shape[1], rng),
                     EpisodeStats(cfg.num_envs))


class OnlineAgent:
    """Batched acting with a trained online learner: ``epsilon`` and a seeded generator for its randomness
    (``seed``: an int, or :class:`Streams` — one generator per equal run of copies, as the env's).
    Subclasses implement ``act``; ``reset`` starts a new batch of episodes."""

    def __init__(self, model: torch.nn.Module, epsilon: float = 0.0, seed: int | Streams = 0,
                 layout: Layout | None = None):
        self.model, self.epsilon, self.layout = model, float(epsilon), layout  # (a view model reads the layout)
        self.rng = seed if isinstance(seed, Streams) else np.random.default_rng(seed)
        self.device = next(model.parameters()).device

    def states(self, obs: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.asarray(self.model.model_states(self.layout, obs), np.int64)).to(self.device)

    def reset(self, obs: np.ndarray) -> None:
        pass

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        pass

    def finish(self) -> None:
        pass
