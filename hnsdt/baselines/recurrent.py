"""RNN baselines, trained offline on whole episodes of the LeRobot dataset: ``lstm_hier`` (3 × 256 LSTM with a
sub-goal head and a sub-goal-conditioned action head) and ``gru`` (2 × 128 GRU, plain behaviour cloning).

Training: Adam on batches of whole episodes (padded to the longest in the batch, padding masked out of the
loss), the episodes of the chosen collection behaviours only. Acting: greedy, one recurrent step per
environment step, carrying the recurrent state through the episode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hnsdt.agents.rollout import distinct_rows
from hnsdt.envs.dynamics import PICK
from hnsdt.models.windows import Frames
from hnsdt.models.fit import FitState, Objective, Validation, fit, to_device, weighted_loss
from hnsdt.models.recurrent import START_ACTION, RecurrentConfig, RecurrentPolicy
from hnsdt.models.train import validation_episodes
from hnsdt.models.view import turned_maps


@dataclass
class RecurrentTrainConfig:
    epochs: int = 20  # passes over the training episodes ...
    max_steps: int = 0  # ... capped at this many gradient steps (0 = no cap)
    batch_size: int = 16  # episodes per gradient step
    lr: float = 1e-3
    seed: int = 0
    device: str = "cpu"
    log_every: int = 10  # one training-curve row per this many steps
    behaviours: tuple[str, ...] = ()  # collection behaviours to learn from (empty = all)
    symmetries: int = 1  # each episode, every epoch anew, on its map turned at random (view networks only;
    #                      hnsdt.models.view.turned_maps)
    patience: int = 0  # > 0: stop once the validation measure has not improved for this many epochs, keeping the
    #                    best epoch's weights; `epochs` is then the cap. 0: train every epoch. The measure: the loss
    #                    on held-out episodes with `validation` > 0 (the transformers' rule), else the greedy steps
    #                    to the exit from validation start states (the unseen layouts': their validation layouts';
    #                    a paper map's: its start and random states of it; hnsdt.evaluation.validation.StepsToExit)
    validation: float = 0.0  # > 0: this share of each behaviour's episodes is held out of training and measured
    #                          (hnsdt.models.train.validation_episodes: the transformers' held-out episodes)
    starts: int = 64  # with patience: about this many start states, spread over the validation layouts


def training_episodes(frames: Frames, behaviours=()) -> tuple[np.ndarray, np.ndarray]:
    """First frame and length of every episode collected by one of ``behaviours`` (all when empty)."""
    starts = np.unique(frames.episode_start)
    lengths = np.diff(np.r_[starts, len(frames)])
    if len(behaviours):
        keep = np.isin(frames.policy[starts], list(behaviours))
        starts, lengths = starts[keep], lengths[keep]
    return starts, lengths


def episode_batch(frames: Frames, starts: np.ndarray, lengths: np.ndarray, start_action: int = START_ACTION
                  ) -> dict[str, np.ndarray]:
    """Whole episodes, right-padded to the longest: states, previous actions (``start_action`` before the first),
    actions, sub-goals, mask."""
    T = int(lengths.max())
    t = np.arange(T)
    mask = t[None, :] < lengths[:, None]
    idx = np.where(mask, starts[:, None] + t[None, :], starts[:, None])
    actions = frames.actions[idx]
    prev = np.concatenate([np.full((len(starts), 1), start_action), actions[:, :-1]], axis=1)
    return {"states": frames.states[idx], "prev_actions": prev, "actions": actions,
            "subgoals": frames.subgoals[idx], "mask": mask}


def train_recurrent(frames: Frames, model_cfg: RecurrentConfig, cfg: RecurrentTrainConfig, progress: bool = True,
                    desc: str = "train", network: type = RecurrentPolicy, state: FitState | None = None,
                    stop_after: int | None = None, measure=None):
    """Train from scratch (or on from ``state``); returns the model (eval mode), its curve and the data used,
    or a :class:`~hnsdt.models.fit.FitState` when ``stop_after`` epochs come before the end. With
    ``cfg.patience``, training stops at the plateau of ``measure(model)`` (lower is better, e.g.
    :class:`hnsdt.evaluation.validation.StepsToExit`), which the data used then records per epoch."""
    starts, lengths = training_episodes(frames, cfg.behaviours)
    if len(starts) == 0:
        raise ValueError(f"no training episodes from behaviours {list(cfg.behaviours) or 'any'} in the dataset")
    if cfg.validation > 0:  # held-out episodes: out of training, their loss the measure
        if not cfg.patience:
            raise ValueError("validation > 0 holds out episodes to stop at the plateau of their loss: set patience")
        held = validation_episodes(frames, cfg.validation)[starts]
        measure = held_out_loss(frames, starts[held], lengths[held], cfg.batch_size)
        starts, lengths = starts[~held], lengths[~held]
    elif cfg.patience and measure is None:
        raise ValueError("patience > 0 stops on the steps to the exit from validation start states: the trainer "
                         "needs that measure (or validation > 0: the loss on held-out episodes)")
    validation = Validation(measure, cfg.patience) if cfg.patience else None
    per_epoch = int(np.ceil(len(starts) / cfg.batch_size))
    objective = Objective(
        np.arange(len(starts)), lambda rows: episode_batch(frames, starts[rows], lengths[rows], network.n_actions),
        lambda rows: int(lengths[rows].sum()),
        lambda step, epoch, seen, loss: {"step": step, "epoch": step / per_epoch, "frames_seen": seen, "loss": loss},
        clip_grad_norm=1.0, augment=turned_maps(model_cfg, cfg.symmetries, cfg.seed))
    out = fit(network, model_cfg, objective, epochs=cfg.epochs, max_steps=cfg.max_steps, batch_size=cfg.batch_size,
              lr=cfg.lr, seed=cfg.seed, device=torch.device(cfg.device), log_every=cfg.log_every,
              progress=progress, desc=desc, state=state, stop_after=stop_after, validation=validation)
    if isinstance(out, FitState):
        return out
    model, curve = out
    seen, step = (curve[-1]["frames_seen"], curve[-1]["step"]) if curve else (0, 0)
    usage = {"dataset_frames": int(lengths.sum()), "dataset_episodes": int(len(starts)), "frames_seen": seen,
             "gradient_steps": step, "epochs": round(seen / int(lengths.sum()), 3)}
    if validation is not None:  # the budget the evidence chose
        usage |= validation.record(getattr(measure, "name", "steps"))
    return model, curve, usage


def held_out_loss(frames: Frames, starts: np.ndarray, lengths: np.ndarray, batch_size: int):
    """The measure of held-out episodes (``starts``, ``lengths``): a model's mean loss per action on them, failed
    actions and recoveries included, which the greedy steps from a start never see."""
    def measure(model) -> float:
        device = next(model.parameters()).device
        parts = np.array_split(np.arange(len(starts)), max(1, -(-len(starts) // batch_size)))
        return weighted_loss(model, (to_device(episode_batch(frames, starts[rows], lengths[rows], model.n_actions),
                                               device) for rows in parts), "mask")

    measure.name = "loss"
    return measure


class RecurrentAgent:
    """Greedy actions of a recurrent controller (:meth:`RecurrentPolicy.step`); the hierarchical one also
    reports its chosen sub-goals. Live copies only, and copies with identical histories so far computed once
    (a history is its recurrent state: identical histories give identical states)."""

    def __init__(self, model: RecurrentPolicy, layout=None):
        self.model, self.layout = model, layout  # (a view model reads the layout around the agent)
        self.device = next(model.parameters()).device

    def reset(self, obs: np.ndarray) -> None:
        n = len(obs)
        self.hidden = None
        self.prev = np.full(n, START_ACTION, dtype=np.int64)
        self.history = np.zeros(n, dtype=np.int64)  # copies with one history so far share an id
        self.live = np.ones(n, dtype=bool)
        self.subgoal_ids = np.zeros(n, dtype=np.int64)

    def act(self, obs: np.ndarray) -> np.ndarray:
        rows = np.flatnonzero(self.live)
        states = np.asarray(self.model.model_states(self.layout, obs), np.int64)[rows]
        first, inverse = distinct_rows(self.history[rows], states, self.prev[rows])
        self.history[rows] = inverse
        hidden = self.hidden
        if hidden is not None:  # the first copy of each distinct history stands for its copies
            pick = torch.from_numpy(rows[first]).to(self.device)
            hidden = tuple(h[:, pick] for h in hidden) if isinstance(hidden, tuple) else hidden[:, pick]
        logits, sub_logits, new = self.model.step(torch.from_numpy(states[first]).to(self.device),
                                                  torch.from_numpy(self.prev[rows[first]]).to(self.device), hidden)
        self.hidden = self._spread(new, rows, inverse, len(obs))
        actions = np.full(len(obs), PICK, dtype=np.int64)  # (done copies: a harmless no-op)
        actions[rows] = logits.argmax(-1).cpu().numpy()[inverse]
        if sub_logits is not None:
            self.subgoal_ids[rows] = sub_logits.argmax(-1).cpu().numpy()[inverse]
            self.last_subgoals = (self.subgoal_ids.copy(), np.full((len(obs), 2), -1, dtype=np.int64))
        return actions

    def _spread(self, new, rows: np.ndarray, inverse: np.ndarray, n: int):
        """The recurrent state of every copy: its history's, at its row (written into the previous state, which
        the step read through a gather; zeros at the first step; done copies keep theirs)."""
        index = torch.from_numpy(rows).to(self.device)
        src = torch.from_numpy(inverse).to(self.device)
        parts = new if isinstance(new, tuple) else (new,)
        old = self.hidden if isinstance(self.hidden, tuple) else (self.hidden,) if self.hidden is not None else None
        out = []
        for k, part in enumerate(parts):
            full = old[k] if old is not None else part.new_zeros(part.shape[0], n, part.shape[2])
            full[:, index] = part[:, src]
            out.append(full)
        return tuple(out) if isinstance(new, tuple) else out[0]

    def observe(self, obs, active, actions=None, rewards=None) -> None:
        if actions is not None:
            self.prev = np.where(active, np.asarray(actions, np.int64), self.prev)
        self.live = np.asarray(active, bool).copy()

    def finish(self) -> None:
        pass


def make_agent(model: RecurrentPolicy, meta: dict, layout, executor, epsilon: float = 0.0, seed: int = 0):
    """The registry's agent factory (:mod:`hnsdt.core.methods`)."""
    return RecurrentAgent(model, layout)
