"""Checkpoints of every learned model: a folder with ``model.safetensors`` (weights) and ``config.json``
(``arch``, the model's config dataclass under ``model``, and training facts). The architectures are the
subclasses of :class:`hnsdt.models.network.Network` in this package: each names its ``arch`` and
``config_class``."""

from __future__ import annotations

import hashlib
import importlib
import json
from dataclasses import asdict
from pathlib import Path

import torch
from safetensors.torch import load, save

from hnsdt.core.fileio import atomic_dir, require_space
from hnsdt.models.network import Network

NETWORK_MODULES = ("dt", "minigrid_nets", "qnetwork", "recurrent", "view")  # the modules of this package that define networks



def architectures() -> dict[str, type]:
    """Checkpoint architecture name -> model class, over every network of this package."""
    for module in NETWORK_MODULES:  # (a network class names its arch when it is defined)
        importlib.import_module(f"hnsdt.models.{module}")
    found, todo = {}, [Network]
    while todo:
        cls = todo.pop()
        todo += cls.__subclasses__()
        if cls is not Network:
            found[cls.arch] = cls
    return found


def save_checkpoint(model: torch.nn.Module, out_dir: str | Path, extra: dict | None = None) -> Path:
    """Write ``model.safetensors`` and ``config.json`` into ``out_dir`` atomically (temp folder, rename)."""
    out = Path(out_dir)
    with atomic_dir(out) as tmp:
        tmp.mkdir()
        state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
        data = save(state)  # (safetensors' own file writer fails a full disk before writing: its size known here)
        require_space(tmp / "model.safetensors", len(data))
        (tmp / "model.safetensors").write_bytes(data)
        meta = {"arch": model.arch, "model": asdict(model.cfg), **(extra or {}),
                "weights_sha256": hashlib.sha256(data).hexdigest()}  # checked when loaded
        (tmp / "config.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return out


def load_checkpoint(path: str | Path, device: str = "cpu") -> tuple[torch.nn.Module, dict]:
    path = Path(path)
    for name in ("model.safetensors", "config.json"):
        if not (path / name).is_file():
            raise FileNotFoundError(f"checkpoint {path}: missing {name} (run `dvc repro`)")
    try:
        meta = json.loads((path / "config.json").read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"checkpoint {path}: config.json is not valid JSON ({e})") from None
    arch = meta.get("arch", "decision_transformer")
    known = architectures()
    if arch not in known:
        raise ValueError(f"checkpoint {path}: unknown arch {arch!r}; known: {', '.join(sorted(known))}")
    network = known[arch]
    try:
        model = network(network.config_class(**meta["model"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"checkpoint {path}: config.json does not describe a {arch} ({e})") from None
    data = (path / "model.safetensors").read_bytes()
    recorded = meta.get("weights_sha256")  # (checkpoints saved before it was recorded: none to check)
    if recorded is not None and hashlib.sha256(data).hexdigest() != recorded:
        raise ValueError(f"checkpoint {path}: model.safetensors is damaged (its sha256 is not the one config.json "
                         f"recorded when it was saved): `dvc checkout {path.parent}` restores the committed copy "
                         "from DVC's cache; if that is damaged too, `dvc repro --force` the stage that trained it")
    try:
        weights = {k: v.to(device) for k, v in load(data).items()}
    except Exception as e:  # noqa: BLE001  (safetensors raises its own error type for a damaged file)
        raise ValueError(f"checkpoint {path}: model.safetensors is unreadable ({type(e).__name__}: {e})") from None
    try:
        model.load_state_dict(weights)
    except RuntimeError:
        raise ValueError(f"checkpoint {path}: the weights in model.safetensors do not match the {arch} that "
                         "config.json describes (shapes or names differ)") from None
    model.to(device).eval()
    return model, meta
