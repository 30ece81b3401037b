"""Sharing a collected dataset on the Hugging Face Hub, through LeRobot's own ``push_to_hub``: the card from the
arguments kept in ``meta/hnsdt.json`` (:mod:`hnsdt.data.card`), the codebase version tag. The only module that
reaches the network; the rest of the package reads datasets offline."""

from __future__ import annotations

from pathlib import Path

from hnsdt.core.provenance import git_revision
from hnsdt.data.card import render_card, template_values

# (hnsdt.data.lerobot_io, which imports lerobot and torch — seconds —, is imported where a dataset is read: a push
# that cannot reach the Hub fails at once)


def push_plan(root: str | Path, repo_id: str) -> tuple[list[str], str]:
    """What ``hnsdt dataset push`` would upload: the files (as ``push_to_hub`` selects them) and the card."""
    from hnsdt.data.lerobot_io import open_dataset

    root = Path(root)
    meta = _card_meta(root)
    files = sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                   if p.is_file() and not p.relative_to(root).as_posix().startswith("images/"))
    info = open_dataset(root, repo_id=repo_id).meta.info
    return files, render_card(meta["card"], info, repo_id, meta["data_md5"], git_revision())


def _card_meta(root: Path) -> dict:
    """The dataset's ``meta/hnsdt.json`` after the usual checks, with the card's arguments in it."""
    from hnsdt.data.lerobot_io import DatasetError, check_dataset

    meta = check_dataset(root)
    if "card" not in meta:
        raise DatasetError(f"dataset {root}: no card arguments in meta/hnsdt.json (written before cards were "
                           "kept; collect it again)")
    return meta


def push_dataset(root: str | Path, repo_id: str, private: bool = False) -> None:
    """Upload with LeRobot's own ``push_to_hub`` (the card from the kept arguments, the codebase version tag);
    any failure to reach or write to the Hub is one RuntimeError naming it."""
    import os

    if os.environ.get("HF_HUB_OFFLINE", "0").lower() in ("1", "true", "yes", "on"):
        raise RuntimeError("cannot push to the Hugging Face Hub: HF_HUB_OFFLINE is set")
    from hnsdt.data.lerobot_io import open_dataset

    meta = _card_meta(Path(root))
    card = meta["card"]
    ds = open_dataset(root, repo_id=repo_id)
    try:
        ds.push_to_hub(tags=card["tags"], license=card["license"], private=private, tag_version=True,
                       **template_values(card, meta["data_md5"], git_revision()))
    except Exception as e:  # noqa: BLE001  (requests, huggingface_hub and lerobot raise many kinds)
        raise RuntimeError(f"cannot push {root} to the Hugging Face Hub as {repo_id}: {type(e).__name__}: {e} "
                           "(network? `huggingface-cli login`?)") from None
