"""Offline training of a decision transformer on a LeRobot dataset, and its checkpoints.

Adam, batches of windows or of whole episodes (:func:`objective_for`), a fixed number of epochs; CUDA when
available, CPU otherwise. Same seed and thread count on CPU ⇒ same weights (the executor sets the threads). Checkpoints: :mod:`hnsdt.models.checkpoint`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hnsdt.models.windows import (Frames, episode_spans, make_episodes, make_windows, supervised_frames,
                                  window_ends)
from hnsdt.models.fit import FitState, Objective, Validation, fit, mean_loss
from hnsdt.models.checkpoint import load_checkpoint, save_checkpoint  # noqa: F401  (re-exported)
from hnsdt.models.dt import DecisionTransformer, DTConfig


@dataclass
class TrainConfig:
    epochs: int = 20
    max_steps: int = 0  # stop after this many gradient steps (0 = run all epochs)
    batch_size: int = 128
    lr: float = 1e-3
    seed: int = 0
    device: str = "auto"  # "auto" = cuda if available, else cpu
    log_every: int = 10  # one training-curve row per this many steps
    behaviours: tuple[str, ...] = ()  # train on episodes of these collection behaviours (empty = all)
    loss: str = "window"  # the steps the loss counts: "window", "last" or "achieving" (hnsdt.models.windows)
    validation: float = 0.0  # > 0: this share of the episodes (of each behaviour) is held out, its loss (or the
    #                          trainer's `measure`) measured after each epoch; training stops once it has not
    #                          improved for `patience` epochs (`epochs` is then the cap) and keeps the best epoch's
    #                          weights. A `measure` on other data (validation layouts) stops training with 0 here
    patience: int = 2
    symmetries: int = 1  # each training episode, every epoch anew, on its map turned (4: a random quarter turn; 8:
    #                      and mirrored) — networks that read views only, episode formulation (hnsdt.models.view)


SEEN = {"window": "windows_seen", "episode": "steps_seen"}  # the training curve's count of examples, by formulation


def objective_for(frames: Frames, model_cfg: DTConfig, cfg: TrainConfig, part: str = "train") -> Objective:
    """What a decision transformer trains on: windows ending at every frame it learns (the window formulation)
    or whole episodes, batched by their steps (the episode formulation). ``part``: the examples outside the
    validation episodes (``train``) or in them (``validation``; :func:`validation_episodes`)."""
    seen = SEEN[model_cfg.formulation]
    row = lambda step, epoch, n, loss: {"step": step, "epoch": epoch, seen: n, "loss": loss}  # noqa: E731
    held = validation_episodes(frames, cfg.validation)
    if part == "train":
        held = ~held
    if model_cfg.formulation == "episode":
        starts, lengths = episode_spans(frames, cfg.behaviours)
        keep = held[starts]
        supervised = supervised_frames(frames, model_cfg.condition, cfg.loss)  # once, not per batch
        if model_cfg.condition == "subgoal":  # supervised steps: those with a sub-goal (that achieved it)
            count = np.r_[0, np.cumsum(supervised if supervised is not None else frames.subgoals != 0)]
            keep &= count[starts + lengths] - count[starts] > 0
        starts, lengths = starts[keep], lengths[keep]
        if len(starts) == 0:
            raise ValueError(f"no {part} episodes: no {model_cfg.condition} episodes from behaviours "
                             f"{list(cfg.behaviours) or 'any'} in the dataset")
        augment = None
        if part == "train" and cfg.symmetries != 1:  # (the view networks' module: no stage of the paper's map needs it)
            from hnsdt.models.view import turned_maps

            augment = turned_maps(model_cfg, cfg.symmetries, cfg.seed)
        return Objective(np.arange(len(starts)),
                         lambda rows: make_episodes(frames, starts[rows], lengths[rows], model_cfg.condition,
                                                    supervised),
                         lambda rows: int(lengths[rows].sum()), row, sizes=lengths,
                         augment=augment)
    ends = window_ends(frames, model_cfg.condition, cfg.behaviours, cfg.loss)
    ends = ends[held[ends]]
    if len(ends) == 0:
        raise ValueError(f"no {part} windows: no {model_cfg.condition} frames from behaviours "
                         f"{list(cfg.behaviours) or 'any'} in the dataset")
    return Objective(ends, lambda rows: make_windows(frames, rows, model_cfg.context, model_cfg.condition,
                                                     cfg.loss), len, row)


def validation_for(frames: Frames, model_cfg: DTConfig, cfg: TrainConfig, measure=None) -> Validation | None:
    """The stopping measure: ``measure(model)`` if given (lower is better; e.g.
    :class:`hnsdt.evaluation.validation.StepsToExit`), else, when ``cfg.validation`` > 0, the loss on the held-out
    episodes."""
    if measure is None and cfg.validation <= 0:
        return None
    if measure is None:
        held_out = objective_for(frames, model_cfg, cfg, "validation")
        measure = mean_loss(held_out, cfg.batch_size, pick_device(cfg.device))
    return Validation(measure, cfg.patience)


def validation_episodes(frames: Frames, share: float) -> np.ndarray:
    """Per frame: is its episode held out for validation? ``share`` of each behaviour's episodes (at least one of
    a behaviour with two or more), the same whatever the training seed (none when ``share`` is 0)."""
    if share <= 0:
        return np.zeros(len(frames), dtype=bool)
    starts, lengths = episode_spans(frames)
    chosen = np.zeros(len(starts), dtype=bool)
    rng = np.random.default_rng(0)
    for policy in sorted(set(frames.policy[starts])):
        mine = np.flatnonzero(frames.policy[starts] == policy)
        n = max(1, int(round(share * len(mine)))) if len(mine) > 1 else 0  # one at least; never the only one
        chosen[rng.choice(mine, size=n, replace=False)] = True
    return np.repeat(chosen, lengths)


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def train_dt(frames: Frames, model_cfg: DTConfig, cfg: TrainConfig, progress: bool = True,
             desc: str = "train", on_epoch=None, network: type = DecisionTransformer,
             state: FitState | None = None, stop_after: int | None = None,
             validation: Validation | None = None):
    """Train from scratch (or on from ``state``); returns the model (in eval mode) and the curve (mean loss every
    ``log_every``), or a :class:`~hnsdt.models.fit.FitState` when ``stop_after`` epochs come before the end
    (:func:`hnsdt.models.fit.fit`). ``on_epoch(epoch, step, model)``, if given, is called after each complete
    epoch and must not change the model or draw random numbers (budget studies copy it: the model after e
    epochs of a longer run is the model of an e-epoch run, as nothing here depends on the total).
    ``network``: the model class (a :class:`DecisionTransformer` or a subclass of it, e.g.
    :class:`hnsdt.models.view.ViewDecisionTransformer`). With ``cfg.validation`` > 0 it stops at the plateau of
    the loss on the held-out episodes (``validation``, made here unless given, records it)."""
    objective = objective_for(frames, model_cfg, cfg)
    return fit(network, model_cfg, objective, epochs=cfg.epochs, max_steps=cfg.max_steps,
               batch_size=cfg.batch_size, lr=cfg.lr, seed=cfg.seed, device=pick_device(cfg.device),
               log_every=cfg.log_every, progress=progress, desc=desc, state=state, stop_after=stop_after,
               on_epoch=on_epoch, validation=validation or validation_for(frames, model_cfg, cfg))


def train_decision_transformer(frames: Frames, model_cfg: DTConfig, cfg: TrainConfig, progress: bool = True,
                               desc: str = "train", network: type = DecisionTransformer,
                               state: FitState | None = None, stop_after: int | None = None, measure=None):
    """The registry's trainer (:mod:`hnsdt.core.methods`): :func:`train_dt` and the data it used, or the
    :class:`~hnsdt.models.fit.FitState` of a run stopped after ``stop_after`` epochs. ``measure``: the
    validation measure when not the held-out loss (:func:`validation_for`; its ``name`` keys the record)."""
    validation = validation_for(frames, model_cfg, cfg, measure)
    out = train_dt(frames, model_cfg, cfg, progress=progress, desc=desc, network=network, state=state,
                   stop_after=stop_after, validation=validation)
    if isinstance(out, FitState):
        return out
    model, curve = out
    used = np.isin(frames.policy, list(cfg.behaviours)) if cfg.behaviours else np.ones(len(frames), bool)
    seen = curve[-1][SEEN[model_cfg.formulation]]
    usage = {"dataset_frames": int(used.sum()), SEEN[model_cfg.formulation]: seen, "gradient_steps": curve[-1]["step"],
             "epochs": round(seen / objective_for(frames, model_cfg, cfg).per_epoch(), 3)}
    if validation is not None:  # the budget the evidence chose
        used_frames = used & ~validation_episodes(frames, cfg.validation)
        usage |= {"dataset_frames": int(used_frames.sum()), "validation_frames": int((used & ~used_frames).sum()),
                  **validation.record(getattr(measure, "name", "loss"))}
    return model, curve, usage
