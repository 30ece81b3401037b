"""The offline training loop of the decision transformers and the RNN baselines, resumable between epochs.

Adam over shuffled batches of examples (window ends; whole episodes), a fixed number of epochs, optionally
capped at a number of gradient steps, or stopped at the plateau of a validation measure (:class:`Validation`).
A run can stop after any complete epoch and hand back a
:class:`FitState` — weights, optimiser moments, both random streams, counters — from which :func:`fit`
continues, in this process or another, to the same bytes as an uninterrupted run (tested). The training
stages use this to run seeds that share workers in parts (:func:`hnsdt.compose.training.pause_at`), so that 5 seeds
keep 2 workers busy for about 2.5 seed-times instead of 3.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch
from tqdm import tqdm

from hnsdt.models.optim import Adam


@dataclass
class FitState:
    """A run stopped after ``epoch`` complete epochs (picklable, tensors on the CPU)."""

    epoch: int
    step: int
    seen: int
    model: dict  # state_dict
    optimizer: dict  # state_dict
    torch_rng: torch.Tensor  # dropout's stream (the CPU generator)
    cuda_rng: torch.Tensor | None  # ... or the CUDA one, for a run on a GPU
    rng: np.random.Generator  # the batch order's stream
    recent: list[float] = field(default_factory=list)  # losses since the last curve row
    curve: list[dict] = field(default_factory=list)
    validated: list[dict] = field(default_factory=list)  # Validation.history so far
    best: tuple | None = None  # (value, epoch, weights) of the best validated epoch so far


@dataclass
class Validation:
    """Training that stops on evidence: after every complete epoch ``measure(model)`` (lower is better; called in
    eval mode, it must not draw random numbers) is recorded in ``history``; once it has not improved for
    ``patience`` epochs training stops, and the model is the best epoch's (``best_epoch``). The epochs
    :func:`fit` is given are the cap. A measure with a ``floor`` (the best value any model can have, e.g. the
    optimum's steps) stops training as soon as an epoch reaches it: later epochs could not replace it. A measure
    with a ``ceiling`` (the value of a model that never reaches the exit) does not stop on patience while every
    epoch has had it: a learner that has never reached the exit is not at a plateau."""

    measure: Callable[[torch.nn.Module], float]
    patience: int
    history: list[dict] = field(default_factory=list)  # {"epoch", "step", "value"} per validated epoch
    best_epoch: int = 0
    stopped_early: bool = False
    floor: float = field(init=False)
    ceiling: float = field(init=False)

    def __post_init__(self):
        self.floor = float(getattr(self.measure, "floor", float("-inf")))
        self.ceiling = float(getattr(self.measure, "ceiling", float("inf")))

    def record(self, name: str) -> dict:
        """What a checkpoint's usage says of the budget the evidence chose; the measure's values as
        ``validation_<name>``."""
        floor = {"validation_floor": self.floor} if np.isfinite(self.floor) else {}
        return {"best_epoch": self.best_epoch, "stopped_early": self.stopped_early,
                f"validation_{name}": self.history, **floor}


@dataclass
class Objective:
    """What one method trains on: ``examples`` (shuffled every epoch), ``batch(rows) -> arrays`` (the model's
    loss input), ``count(rows)`` (added to the curve's ``seen``), ``curve_row(step, epoch, seen, loss)``."""

    examples: np.ndarray
    batch: Callable[[np.ndarray], dict]
    count: Callable[[np.ndarray], int]
    curve_row: Callable[[int, int, int, float], dict]
    clip_grad_norm: float = 0.0  # > 0: clip the gradient's norm to this before each step
    sizes: np.ndarray | None = None  # per example, what it counts towards batch_size (episodes: their steps);
    #                                  None: one each, so a batch is batch_size examples
    augment: Callable[[dict, np.ndarray, int], dict] | None = None  # augment(arrays, rows, epoch): a training
    #                                  batch changed as a function of its rows and epoch alone (so a run resumed
    #                                  in another process draws the same), e.g. turned maps (hnsdt.models.view)

    def batches(self, order: np.ndarray, batch_size: int) -> list[np.ndarray]:
        """One epoch's batches of the shuffled ``order``: slices of ``batch_size`` examples, or (``sizes``) runs
        of consecutive examples each closed once its sizes reach ``batch_size``."""
        if self.sizes is None:
            return [order[b:b + batch_size] for b in range(0, len(order), batch_size)]
        ends = []
        total = 0
        for i, size in enumerate(self.sizes[order]):
            total += size
            if total >= batch_size:
                ends.append(i + 1)
                total = 0
        return [b for b in np.split(order, ends) if len(b)]

    def per_epoch(self) -> int:
        """What an epoch counts towards batches: its examples, or (``sizes``) their sizes."""
        return len(self.examples) if self.sizes is None else int(self.sizes.sum())

    def steps_per_epoch(self, batch_size: int) -> int:
        """Batches in an epoch (with ``sizes``: the expected count; each epoch's own can differ by a few)."""
        return int(np.ceil(self.per_epoch() / batch_size))


def fit(network: type, model_cfg, objective: Objective, *, epochs: int, max_steps: int, batch_size: int,
        lr: float, seed: int, device: torch.device, log_every: int, progress: bool = True, desc: str = "train",
        state: FitState | None = None, stop_after: int | None = None, on_epoch=None,
        validation: Validation | None = None):
    """Train ``network(model_cfg)`` from scratch, or from ``state``; returns ``(model in eval mode, curve)``,
    or a :class:`FitState` when ``stop_after`` (a number of complete epochs) comes before the end.
    ``on_epoch(epoch, step, model)`` is called after each complete epoch and must neither change the model nor
    draw random numbers. ``validation``: stop at the plateau of a validation measure (:class:`Validation`,
    which records what it measured)."""
    torch.manual_seed(seed)
    model = network(model_cfg).to(device)
    groups = model.param_groups(lr) if hasattr(model, "param_groups") else model.parameters()
    opt = Adam(groups, lr=lr)  # (a network may train a part at its own rate: param_groups(lr))
    best = None
    if state is None:
        first, step, seen, recent, curve, rng = 0, 0, 0, [], [], np.random.default_rng(seed)
    else:  # the weights and streams where the earlier part stopped (construction above drew from the stream)
        model.load_state_dict(state.model)
        opt.load_state_dict(state.optimizer)
        torch.set_rng_state(state.torch_rng)
        if state.cuda_rng is not None:
            torch.cuda.set_rng_state(state.cuda_rng)
        first, step, seen, recent, curve, rng = (state.epoch, state.step, state.seen, list(state.recent),
                                                 list(state.curve), state.rng)
        best = state.best
        if validation is not None:
            validation.history = list(state.validated)
    expected = epochs * objective.steps_per_epoch(batch_size)
    total = expected if objective.sizes is None else float("inf")  # exact, or the epochs decide
    if max_steps:
        total = min(total, max_steps)
    end = epochs if stop_after is None else min(epochs, stop_after)
    bar = tqdm(total=min(expected, total), initial=step, desc=desc, disable=not progress, unit="step")
    model.train()
    last_epoch = first
    for epoch in range(first, end):
        if step >= total:
            break
        complete, last_epoch = True, epoch + 1
        for rows in objective.batches(rng.permutation(objective.examples), batch_size):
            if step >= total:
                complete = False
                break
            arrays = objective.batch(rows)
            if objective.augment is not None:
                arrays = objective.augment(arrays, rows, epoch)
            batch = to_device(arrays, device)
            loss = model.loss(batch)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if objective.clip_grad_norm > 0:
                torch.nn.utils.clip_grad_norm_(model.parameters(), objective.clip_grad_norm)
            opt.step()
            step += 1
            seen += objective.count(rows)
            recent.append(loss.item())
            bar.update(1)
            bar.set_postfix(epoch=epoch + 1, loss=f"{recent[-1]:.4f}")
            if step % log_every == 0 or step == total:
                curve.append(objective.curve_row(step, epoch + 1, seen, float(np.mean(recent))))
                recent = []
        if on_epoch is not None and complete:
            on_epoch(epoch + 1, step, model)
        if validation is not None and complete:
            model.eval()
            with torch.no_grad():
                value = float(validation.measure(model))
            model.train()
            validation.history.append({"epoch": epoch + 1, "step": step, "value": value})
            if best is None or value < best[0]:
                best = (value, epoch + 1, {k: v.detach().cpu().clone() for k, v in model.state_dict().items()})
            reached = best[0] < validation.ceiling - 1e-9  # (some epoch has reached the exit)
            if value <= validation.floor + 1e-9 or (reached and epoch + 1 - best[1] >= validation.patience):
                validation.stopped_early = True
                break
    bar.close()
    stopped = validation is not None and validation.stopped_early
    if end < epochs and step < total and not stopped:
        cuda = torch.cuda.get_rng_state() if device.type == "cuda" else None
        return FitState(end, step, seen, {k: v.cpu() for k, v in model.state_dict().items()},
                        _to_cpu(opt.state_dict()), torch.get_rng_state(), cuda, rng, recent, curve,
                        list(validation.history) if validation is not None else [], best)
    if recent:  # steps since the last row (a run whose epochs, not a step count, end it)
        curve.append(objective.curve_row(step, last_epoch, seen, float(np.mean(recent))))
    if best is not None:  # the best validated epoch's weights
        model.load_state_dict(best[2])
        validation.best_epoch = best[1]
    model.eval()
    return model, curve


def to_device(arrays: dict[str, np.ndarray], device: torch.device) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(np.ascontiguousarray(v)).to(device, non_blocking=True) for k, v in arrays.items()}


def mean_loss(objective: Objective, batch_size: int, device: torch.device) -> Callable[[torch.nn.Module], float]:
    """A validation measure: the model's loss over every example of ``objective`` (in order), each supervised
    step weighing the same."""
    def measure(model) -> float:
        return weighted_loss(model, (to_device(objective.batch(rows), device)
                                     for rows in objective.batches(objective.examples, batch_size)), "loss_mask")
    return measure


def weighted_loss(model: torch.nn.Module, batches, mask: str) -> float:
    """``model.loss`` over ``batches`` (on the model's device), each supervised step (``batch[mask]``) weighing
    the same: the mean of a measure over held-out examples, whatever their batches' sizes."""
    total = count = 0.0
    with torch.no_grad():
        for batch in batches:
            n = float(batch[mask].sum())
            total += float(model.loss(batch)) * n
            count += n
    return total / max(count, 1.0)


def _to_cpu(obj):
    if isinstance(obj, torch.Tensor):
        return obj.cpu()
    if isinstance(obj, dict):
        return {k: _to_cpu(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_to_cpu(v) for v in obj]
    return obj
