"""Stage `collect@ENV`: a paper map's exploration episodes as a LeRobot dataset."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params


def collect(params: Params, env: str, out: Path, repo_id: str | None = None, progress: bool = True) -> Path:
    """Stage `collect@ENV`: exploration episodes on one env as a LeRobot dataset at ``out``."""
    from hnsdt.compose.config import collect_config
    from hnsdt.data.collect import collect_dataset

    root = collect_dataset(collect_config(params, env), out, repo_id or f"local/{env}", progress=progress)
    print(f"wrote LeRobot dataset {root} (card: {root / 'README.md'})")
    return root
