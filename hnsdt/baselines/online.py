"""What the online learners share: the training environment, a replay buffer, the ε schedule, the per-episode
statistics of the training curve, and the stack their seeds train in (:class:`OnlineRun`): a learner's seeds step
in lockstep through one network whose weights are theirs side by side, since on a network this small torch's
per-step cost, not arithmetic, is most of a step (DQN on Case 1: 5 seeds in a stack 39 s, one seed alone 17 s)."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace

import numpy as np
import torch
import torch.nn as nn

from hnsdt.agents.rollout import distinct_rows
from hnsdt.envs.keydoor import N_ACTIONS
from hnsdt.envs.layout import Layout
from hnsdt.envs.vector import KeyDoorVectorEnv, Streams
from hnsdt.models.kernels import Linear
from hnsdt.models.optim import Adam


@dataclass
class OnlineConfig:
    """Knobs every online learner has; each learner's config adds its own."""

    env_steps: int = 50_000  # environment steps to train for (summed over the parallel copies)
    num_envs: int = 8  # environment copies stepped together
    fail_probs: tuple[float, ...] = (0.0, 0.1, 0.2, 0.3)  # the copies cycle through these
    lr: float = 5e-4  # Adam learning rate
    gamma: float = 0.99  # discount
    exploration_fraction: float = 0.5  # the first fraction of env_steps, in which a seed explores and does not
    #                                    stop at a plateau (DQN, option-critic: their ε decays over it)
    seed: int = 0
    device: str = "cpu"
    log_every: int = 2_000  # env steps between training-curve rows
    patience: int = 0  # > 0: a seed stops once its greedy steps to the exit on validation start states have not
    #                    improved for this many evaluations, its exploration over, keeping its best evaluation's
    #                    weights (env_steps is then the cap); 0: it trains all env_steps
    validate_every: int = 10_000  # with patience: env steps between those evaluations
    starts: int = 1  # with patience: about this many validation start states: the map's start, then random states
    #                  of it (which a learner from the start never visits); the unseen layouts': spread over the
    #                  validation layouts, each one's start first


@dataclass
class ReplayConfig(OnlineConfig):
    """The shared online knobs, plus those of learning from a replay buffer under an ε-greedy schedule (DQN,
    option-critic)."""

    buffer_size: int = 50_000  # replay capacity, in transitions
    batch_size: int = 128  # replayed transitions per gradient step
    learning_starts: int = 2_000  # env steps of exploration before learning from replay
    target_period: int = 250  # gradient steps between target-network copies
    epsilon_start: float = 1.0  # exploration ε at the start ...
    epsilon_end: float = 0.05  # ... decays linearly to this over exploration_fraction of env_steps


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


def sample_categorical(logits: torch.Tensor, rng: np.random.Generator) -> np.ndarray:
    """One draw per row from softmax(logits), with numpy's seeded generator."""
    probs = torch.softmax(logits, -1).detach().cpu().numpy().astype(np.float64)
    cum = probs.cumsum(-1)
    u = rng.random(len(probs))[:, None] * cum[:, -1:]
    return np.minimum((u > cum).sum(-1), probs.shape[1] - 1)


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
    """Running return, length and success of each copy; the finished episodes since the last curve row; how many
    episodes have finished, and how many of them at the exit."""

    def __init__(self, n: int):
        self.ret = np.zeros(n)
        self.length = np.zeros(n, np.int64)
        self.finished: list[tuple[float, int, bool]] = []
        self.episodes = 0
        self.exits = 0  # episodes that ended at the exit

    def update(self, rewards, terminated, done) -> None:
        self.ret += rewards
        self.length += 1
        for i in np.flatnonzero(done):
            self.finished.append((float(self.ret[i]), int(self.length[i]), bool(terminated[i])))
        self.episodes += int(done.sum())
        self.exits += int((done & terminated).sum())
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


def stack_networks(nets: list[nn.Module]) -> nn.Module:
    """Networks of one architecture as one network whose every parameter is the stack (S, …) of theirs: a forward
    maps inputs (S, …) to outputs (S, …), each network's slice through its own weights. Every layer with weights
    must be a :class:`~hnsdt.models.kernels.Linear`, whose stacked products are one GEMM per network (so each gets
    the bytes it would get alone; the rest of a value network is elementwise or row by row, and a network whose
    elementwise op rounds by position reads ``stack_size``, e.g. option-critic's sigmoid)."""
    stacked = copy.deepcopy(nets[0])
    stacked.stack_size = len(nets)
    for module in stacked.modules():
        if any(True for _ in module.parameters(recurse=False)) and not isinstance(module, Linear):
            raise TypeError(f"{type(module).__name__} has weights but is no kernels.Linear: it cannot be stacked")
    for name, _ in nets[0].named_parameters():
        owner, _, attr = name.rpartition(".")
        setattr(stacked.get_submodule(owner), attr,
                nn.Parameter(torch.stack([net.get_parameter(name).detach() for net in nets])))
    return stacked


def clip_seed_norms(stacked: nn.Module, max_norm: float) -> None:
    """``torch.nn.utils.clip_grad_norm_`` for each network of a stack (:func:`stack_networks`) apart: seed i's
    gradients (every parameter's slice i) scaled by min(1, max_norm / (their global norm + 1e-6)), each norm
    summed slice by slice, as alone."""
    grads = [p.grad for p in stacked.parameters() if p.grad is not None]
    for i in range(len(grads[0]) if grads else 0):
        norm = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(g[i]) for g in grads]))
        scale = torch.clamp(max_norm / (norm + 1e-6), max=1.0)
        for g in grads:
            g[i].mul_(scale)


def unstack_network(stacked: nn.Module, nets: list[nn.Module]) -> list[nn.Module]:
    """Each of ``nets`` with its slice of ``stacked``'s weights (:func:`stack_networks`)."""
    with torch.no_grad():
        for i, net in enumerate(nets):
            for name, param in net.named_parameters():
                param.copy_(stacked.get_parameter(name)[i])
    return nets


@dataclass
class Plateau:
    """One seed's training to the plateau of a validation measure (``OnlineConfig.patience``; lower is better,
    e.g. :class:`hnsdt.evaluation.validation.StepsToExit`): its evaluations, the best one's weights, and what the
    seed had used when it stopped — it stops once ``patience`` evaluations bring no better value, but not while
    it still explores (ε above its end), nor while every evaluation has had the measure's ``ceiling`` (a seed
    that has never reached the exit greedily is not at a plateau), or as soon as one reaches the measure's
    ``floor`` (no model does better: no later one could replace it). Seeds in a stack stop apart; a stopped
    seed's weights go on training beside the others but are not its result."""

    patience: int
    floor: float
    ceiling: float = float("inf")
    history: list[dict] = field(default_factory=list)  # {"step", "value"} per evaluation
    best: tuple | None = None  # (value, evaluation index, step, weights) of the best evaluation so far
    stopped: dict | None = None  # the data used when it stopped (env steps, episodes, gradient steps)

    def update(self, steps: int, value: float, net: nn.Module, used: dict, may_stop: bool = True) -> None:
        self.history.append({"step": steps, "value": value})
        never = self.best is not None and min(value, self.best[0]) >= self.ceiling - 1e-9  # (no exit reached yet:
        # the latest of the ties at the ceiling, a seed that never reaches the exit keeps its most trained weights)
        if self.best is None or value < self.best[0] or never:
            self.best = (value, len(self.history) - 1, steps,
                         {k: v.detach().cpu().clone() for k, v in net.state_dict().items()})
        waited = len(self.history) - 1 - self.best[1] >= self.patience
        reached = self.best[0] < self.ceiling - 1e-9  # (some evaluation has reached the exit)
        if value <= self.floor + 1e-9 or (may_stop and reached and waited):
            self.stopped = used  # (at the floor at once: no later evaluation could replace it)

    def record(self, name: str = "steps") -> dict:
        """What a checkpoint's usage says of the budget the evidence chose (as the offline learners'
        :meth:`hnsdt.models.fit.Validation.record`, in env steps)."""
        floor = {"validation_floor": self.floor} if np.isfinite(self.floor) else {}
        return {"best_step": self.best[2] if self.best else None, "stopped_early": self.stopped is not None,
                f"validation_{name}": self.history, **floor}


@dataclass
class OnlineRun:
    """What an online learner's seeds start from, built seed by seed in one order so that a seed gives the same
    run whichever seeds train beside it: its generator, training copies, replay buffer and statistics; the
    networks of all of them stacked (:func:`stack_networks`), stepped by one optimiser. Seeds in a stack train in
    lockstep and pay the per-step cost of torch once; each seed's numbers are those of its run alone (tested)."""

    rngs: list[np.random.Generator]  # per seed: actions, exploration and replay sampling
    device: torch.device
    envs: list[KeyDoorVectorEnv]
    nets: list[nn.Module]  # the seeds' own networks: they get the trained weights at the end
    net: nn.Module  # their stack, trained
    target: nn.Module  # a copy of ``net``, refreshed every ``target_period`` gradient steps
    opt: torch.optim.Optimizer
    obs: np.ndarray  # (seeds, copies, state)
    buffers: list[ReplayBuffer] | None  # per seed (learners from replay: ReplayConfig)
    stats: list[EpisodeStats]
    grad_steps: int = 0
    losses: list[list[float]] = field(default_factory=list)  # per seed, since the last curve row
    steps: int = 0  # env steps so far (of each seed)
    curves: list[list[dict]] = field(default_factory=list)
    loop: dict = field(default_factory=dict)  # the learner's own loop variables, kept while paused
    torch_rng: torch.Tensor | None = None  # the torch stream, kept while paused (no learner here draws from it yet)
    plateaus: list[Plateau] | None = None  # per seed, when it trains to a validated plateau
    next_log: int = 0  # env steps of the next curve row ...
    next_check: int = 0  # ... and of the next evaluation (with a plateau)

    def pause(self, steps: int, **loop) -> OnlineRun:
        """The run as it stands, to continue later, in this process or another (pickled whole: the networks,
        the optimiser, the copies, the buffers and the streams), to the same bytes as one run in one go."""
        self.steps, self.loop = steps, loop
        self.torch_rng = torch.get_rng_state()
        return self

    def resume(self) -> OnlineRun:
        if self.torch_rng is not None:
            torch.set_rng_state(self.torch_rng)
        return self

    def step(self, actions: np.ndarray, options: np.ndarray | None = None):
        """Every seed's copies take ``actions`` (seeds, copies); the transitions are stored (truncation is not
        termination: its next state is bootstrapped) and counted. ``(next_obs, rewards, terminated, done)``,
        stacked; the finished copies restart at :meth:`restart`."""
        out = []
        for i, (env, buffer, stats) in enumerate(zip(self.envs, self.buffers or [None] * len(self.envs), self.stats)):
            next_obs, rewards, terminated, truncated, _ = env.step(actions[i])
            if buffer is not None:
                buffer.add(self.obs[i], actions[i], rewards, next_obs, terminated,
                           options=None if options is None else options[i])
            stats.update(rewards, terminated, terminated | truncated)
            out.append((next_obs, rewards, terminated, terminated | truncated))
        return tuple(np.stack(column) for column in zip(*out))

    def restart(self, next_obs: np.ndarray, done: np.ndarray) -> None:
        """The next observations, finished copies restarted at their start."""
        self.obs = np.stack([env.reset(options={"reset_mask": d})[0] if d.any() else o
                             for env, o, d in zip(self.envs, next_obs, done)])

    def sample(self, batch_size: int) -> dict[str, torch.Tensor]:
        """A replayed batch per seed, stacked: (seeds, batch_size, …)."""
        draws = [buffer.sample(batch_size) for buffer in self.buffers]
        return {k: torch.from_numpy(np.stack([d[k] for d in draws])).to(self.device) for k in draws[0]}

    def learn(self, losses: torch.Tensor, target_period: int = 0, max_grad_norm: float = 0.0) -> None:
        """One Adam step on the seeds' ``losses`` (seeds,): their sum, whose gradient reaches each seed's
        weights from its own loss alone; with ``max_grad_norm``, each seed's gradient scaled down to that global
        norm, its own (:func:`clip_seed_norms`); the target network copies the online one every
        ``target_period`` steps."""
        self.opt.zero_grad(set_to_none=True)
        losses.sum().backward()
        if max_grad_norm:
            clip_seed_norms(self.net, max_grad_norm)
        self.opt.step()
        self.grad_steps += 1
        for seed_losses, value in zip(self.losses, losses.tolist()):
            seed_losses.append(value)
        if target_period and self.grad_steps % target_period == 0:
            self.target.load_state_dict(self.net.state_dict())

    def curve_rows(self, steps: int, epsilon: float | None, extra: list[dict] | None = None) -> None:
        """A training-curve row per seed: env steps, ε, the episodes finished and the mean loss since the last
        row, the seed's ``extra``, and with a plateau its validation value at this step (NaN between)."""
        for i, (curve, stats) in enumerate(zip(self.curves, self.stats)):
            losses = self.losses[i]
            validation = {}
            if self.plateaus is not None:
                history = self.plateaus[i].history
                validation = {"validation_steps": history[-1]["value"] if history and history[-1]["step"] == steps
                              else float("nan")}
            explore = {} if epsilon is None else {"epsilon": round(epsilon, 4)}
            curve.append({"step": steps, **explore, **stats.row(),
                          "loss": float(np.mean(losses)) if losses else float("nan"),
                          **(extra[i] if extra else {}), **validation})
            self.losses[i] = []

    def row_due(self, steps: int, cfg: OnlineConfig, measure, may_stop: bool) -> bool:
        """At ``steps``: with a plateau, every ``validate_every`` env steps each seed still training evaluated by
        ``measure`` (:meth:`validate`); whether a curve row is due — every ``log_every`` env steps, at the
        budget's end, and at each evaluation."""
        evaluated = self.plateaus is not None and steps >= self.next_check
        if evaluated:
            self.next_check += cfg.validate_every
            self.validate(steps, measure, may_stop)
        logged = steps >= self.next_log or steps >= cfg.env_steps
        if logged:
            self.next_log += cfg.log_every
        return logged or evaluated

    def validate(self, steps: int, measure, may_stop: bool) -> bool:
        """Every seed still training evaluated by ``measure`` (its greedy agent; :class:`Plateau`), stopped at
        its plateau if ``may_stop``; whether all have stopped (:meth:`done`)."""
        for i, (net, plateau) in enumerate(zip(unstack_network(self.net, self.nets), self.plateaus)):
            if plateau.stopped is None:
                with torch.no_grad():
                    value = float(measure(net.eval()))
                plateau.update(steps, value, net, self.used(i, steps), may_stop)
        return self.done()

    def done(self) -> bool:
        """Whether every seed has stopped at its plateau (never, without one)."""
        return self.plateaus is not None and all(p.stopped is not None for p in self.plateaus)

    def used(self, seed: int, steps: int) -> dict:
        return {"env_steps": steps, "episodes": self.stats[seed].episodes, "exits": self.stats[seed].exits,
                "gradient_steps": self.grad_steps}

    def result(self, steps: int) -> list[tuple[torch.nn.Module, list[dict], dict]]:
        """The trainer's return per seed: its network (eval mode), its curve and the data it used; with a
        plateau, the best evaluation's weights, and the curve and the data up to where the seed stopped."""
        nets = unstack_network(self.net, self.nets)
        out = []
        for i, (net, curve) in enumerate(zip(nets, self.curves)):
            usage = self.used(i, steps)
            if self.plateaus is not None:
                plateau = self.plateaus[i]
                usage = dict(plateau.stopped or usage) | plateau.record()
                curve = [row for row in curve if row["step"] <= usage["env_steps"]]
                if plateau.best is not None:
                    net.load_state_dict(plateau.best[3])
            out.append((net.eval(), curve, usage))
        return out


def seed_configs(cfg: OnlineConfig | list[OnlineConfig]) -> list[OnlineConfig]:
    """A learner's config, or one per seed of a stack: those may differ in their seed only."""
    cfgs = list(cfg) if isinstance(cfg, (list, tuple)) else [cfg]
    if any(replace(c, seed=0) != replace(cfgs[0], seed=0) for c in cfgs):
        raise ValueError("the seeds of a stack must share every training knob but their seed")
    return cfgs


def start_run(layout: Layout | list[Layout], max_steps: int, network: type, net_cfg, cfgs: list[OnlineConfig],
              state: OnlineRun | None = None, measure=None) -> OnlineRun:
    """Per seed of ``cfgs`` (:func:`seed_configs`): seed torch and numpy, build the training copies, the network
    (``network(net_cfg)``), the first observations, the replay buffer and the episode statistics; then stack the
    networks, copy the stack as the target and build Adam. Or continue ``state``, a paused run
    (:meth:`OnlineRun.pause`). With ``patience``, ``measure`` is the validation measure its seeds stop on."""
    if state is not None:
        return state.resume()
    cfg, device = cfgs[0], torch.device(cfgs[0].device)
    if cfg.patience and measure is None:
        raise ValueError("patience > 0 stops on the greedy steps to the exit from validation start states: "
                         "the trainer needs that measure")
    rngs, envs, nets, obs = [], [], [], []
    for c in cfgs:
        torch.manual_seed(c.seed)
        rngs.append(np.random.default_rng(c.seed))
        envs.append(training_env(layout, max_steps, c.num_envs, c.fail_probs, getattr(net_cfg, "view_radius", 0)))
        nets.append(network(net_cfg).to(device))
        obs.append(envs[-1].reset(seed=c.seed)[0])
    net = stack_networks(nets)
    obs = np.stack(obs)
    floor, ceiling = (float(getattr(measure, k, d)) for k, d in (("floor", float("-inf")), ("ceiling", float("inf"))))
    return OnlineRun(rngs, device, envs, nets, net, copy.deepcopy(net), Adam(net.parameters(), lr=cfg.lr), obs,
                     [ReplayBuffer(cfg.buffer_size, obs.shape[-1], rng) for rng in rngs]
                     if isinstance(cfg, ReplayConfig) else None,
                     [EpisodeStats(cfg.num_envs) for _ in cfgs], losses=[[] for _ in cfgs],
                     curves=[[] for _ in cfgs],
                     plateaus=[Plateau(cfg.patience, floor, ceiling) for _ in cfgs] if cfg.patience else None,
                     next_log=cfg.log_every, next_check=cfg.validate_every)


def finish(run: OnlineRun, steps: int, cfg, **loop):
    """The trainer's return: the paused run when ``steps`` fall short of the budget and a seed has not reached
    its plateau, else the result of each seed (a list for a list of configs, the one result for one)."""
    if steps < seed_configs(cfg)[0].env_steps and not run.done():
        return run.pause(steps, **loop)
    results = run.result(steps)
    return results if isinstance(cfg, (list, tuple)) else results[0]


class OnlineAgent:
    """Batched acting with a trained online learner: ``epsilon`` and a seeded generator for its randomness
    (``seed``: an int, or :class:`Streams` — one generator per equal run of copies, as the env's).
    Subclasses implement ``act``; ``reset`` starts a new batch of episodes."""

    def __init__(self, model: torch.nn.Module, epsilon: float = 0.0, seed: int | Streams = 0,
                 layout: Layout | None = None):
        self.model, self.epsilon, self.layout = model, float(epsilon), layout  # (a view model reads the layout)
        self.rng = seed if isinstance(seed, Streams) else np.random.default_rng(seed)
        self.device = next(model.parameters()).device

    def outputs(self, obs: np.ndarray):
        """The model's outputs for every copy, each distinct state computed once: the policy reads the current
        state alone, and copies that fail or loop alike share states. The whole batch's outputs up to rounding (a
        row's last bits follow the batch's size: OpenBLAS picks its kernels by shape; tested), as the transformers'
        and RNNs' distinct histories are: the same bytes run to run, other last bits than one row per copy."""
        states = np.asarray(self.model.model_states(self.layout, obs), np.int64)
        first, inverse = distinct_rows(states)
        with torch.no_grad():
            out = self.model(torch.from_numpy(states[first]).to(self.device))
        index = torch.from_numpy(inverse).to(self.device)
        return out[index] if isinstance(out, torch.Tensor) else tuple(part[index] for part in out)

    def epsilon_greedy(self, greedy: np.ndarray) -> np.ndarray:
        """``greedy`` actions, each replaced with probability ``epsilon`` by a uniformly random one (seeded)."""
        if self.epsilon <= 0:
            return greedy
        explore = self.rng.random(len(greedy)) < self.epsilon
        return np.where(explore, self.rng.integers(0, N_ACTIONS, len(greedy)), greedy)

    def reset(self, obs: np.ndarray) -> None:
        pass

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        pass

    def finish(self) -> None:
        pass
