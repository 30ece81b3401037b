"""Offline training of a decision transformer on a LeRobot dataset, and its checkpoints.

Adam, batch of windows, a fixed number of epochs over the training windows; CUDA when available, CPU
otherwise. Same seed and thread count on CPU ⇒ same weights (the executor sets the threads). Checkpoints: :mod:`hnsdt.models.checkpoint`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from hnsdt.data.windows import Frames, make_windows, window_ends
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
    loss: str = "window"  # the window steps the loss counts: "window" or "last" (hnsdt.data.windows.make_windows)


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _to_tensors(batch: dict, device: torch.device) -> dict:
    out = {}
    for k, v in batch.items():
        t = torch.from_numpy(np.ascontiguousarray(v))
        out[k] = t.to(device, non_blocking=True)
    return out


def train_dt(frames: Frames, model_cfg: DTConfig, cfg: TrainConfig, progress: bool = True,
             desc: str = "train", on_epoch=None, network: type = DecisionTransformer
             ) -> tuple[DecisionTransformer, list[dict]]:
    """Train from scratch; returns the model (in eval mode) and the curve (mean loss every ``log_every``).
    ``on_epoch(epoch, step, model)``, if given, is called after each complete epoch and must not change the model
    or draw random numbers (budget studies copy it: the model after e epochs of a longer run is the model of
    an e-epoch run, as nothing here depends on the total). ``network``: the model class (a
    :class:`DecisionTransformer` or a subclass of it, e.g. :class:`hnsdt.models.view.ViewDecisionTransformer`)."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    device = pick_device(cfg.device)
    model = network(model_cfg).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    ends = window_ends(frames, model_cfg.condition, cfg.behaviours)
    if len(ends) == 0:
        raise ValueError(f"no training windows: no {model_cfg.condition} frames from behaviours "
                         f"{list(cfg.behaviours) or 'any'} in the dataset")
    steps_per_epoch = int(np.ceil(len(ends) / cfg.batch_size))
    total_steps = cfg.epochs * steps_per_epoch
    if cfg.max_steps:
        total_steps = min(total_steps, cfg.max_steps)
    curve = []
    bar = tqdm(total=total_steps, desc=desc, disable=not progress, unit="step")
    model.train()
    step, seen, recent = 0, 0, []
    for epoch in range(cfg.epochs):
        if step >= total_steps:
            break
        order = rng.permutation(ends)
        for b in range(steps_per_epoch):
            if step >= total_steps:
                break
            rows = order[b * cfg.batch_size : (b + 1) * cfg.batch_size]
            batch = make_windows(frames, rows, model_cfg.context, model_cfg.condition, cfg.loss)
            loss = model.loss(_to_tensors(batch, device))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            seen += len(rows)
            recent.append(loss.item())
            bar.update(1)
            bar.set_postfix(epoch=epoch + 1, loss=f"{recent[-1]:.4f}")
            if step % cfg.log_every == 0 or step == total_steps:
                curve.append({"step": step, "epoch": epoch + 1, "windows_seen": seen,
                              "loss": float(np.mean(recent))})
                recent = []
        if on_epoch is not None and step == (epoch + 1) * steps_per_epoch:  # a complete epoch
            on_epoch(epoch + 1, step, model)
    bar.close()
    model.eval()
    return model, curve


def train_decision_transformer(frames: Frames, model_cfg: DTConfig, cfg: TrainConfig, progress: bool = True,
                               desc: str = "train", network: type = DecisionTransformer
                               ) -> tuple[DecisionTransformer, list[dict], dict]:
    """The registry's trainer (:mod:`hnsdt.methods`): :func:`train_dt` and the data it used."""
    model, curve = train_dt(frames, model_cfg, cfg, progress=progress, desc=desc, network=network)
    used = np.isin(frames.policy, list(cfg.behaviours)) if cfg.behaviours else np.ones(len(frames), bool)
    windows = len(window_ends(frames, model_cfg.condition, cfg.behaviours))
    usage = {"dataset_frames": int(used.sum()), "windows_seen": curve[-1]["windows_seen"],
             "gradient_steps": curve[-1]["step"], "epochs": round(curve[-1]["windows_seen"] / windows, 3)}
    return model, curve, usage
