"""Our datasets on disk, read without importing lerobot: the checks a dataset must pass, its episode table and
its frame columns.

A dataset is LeRobot v3.0 (written by ``lerobot``, loadable by stock ``LeRobotDataset``:
:mod:`hnsdt.data.lerobot_io`): frames in ``data/chunk-*/file-*.parquet``, in path order, one row per frame;
``meta/info.json``; and ours beside them, ``meta/hnsdt.json`` and ``meta/hnsdt_episodes.parquet``. Training and
evaluation only need the frame columns, the same Arrow table ``LeRobotDataset`` loads (tested column for
column): reading it here spares each stage process the seconds that importing lerobot costs.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from hnsdt.data.features import REQUIRED_DTYPES

HNSDT_META = "meta/hnsdt.json"
EPISODES_TABLE = "meta/hnsdt_episodes.parquet"
FORMAT_VERSION = 1


class DatasetError(RuntimeError):
    """A dataset that is missing, incomplete or not one of ours; the message says which file and why."""


def check_dataset(root: str | Path, required: dict[str, str] = REQUIRED_DTYPES) -> dict:
    """Validate the files of one of our datasets and return its ``meta/hnsdt.json``; raise DatasetError.
    ``required``: the features it must have, with their dtypes (a MiniGrid dataset's differ)."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"dataset {root}: no such folder (run `dvc repro collect` or `hnsdt collect`)")
    for rel in ("meta/info.json", HNSDT_META, EPISODES_TABLE):
        if not (root / rel).is_file():
            raise DatasetError(f"dataset {root}: missing {rel}; the dataset is incomplete or not an hnsdt dataset")
    try:
        info = json.loads((root / "meta/info.json").read_text())
        meta = json.loads((root / HNSDT_META).read_text())
    except json.JSONDecodeError as e:
        raise DatasetError(f"dataset {root}: corrupt JSON metadata ({e})") from None
    if info.get("codebase_version") != "v3.0":
        raise DatasetError(f"dataset {root}: LeRobot format {info.get('codebase_version')}, expected v3.0")
    features = info.get("features", {})
    missing = set(required) - set(features)
    if missing:
        raise DatasetError(f"dataset {root}: features {sorted(missing)} are missing from meta/info.json")
    for name, dtype in required.items():
        if features[name].get("dtype") != dtype:
            raise DatasetError(f"dataset {root}: feature {name!r} has dtype {features[name].get('dtype')}, "
                               f"expected {dtype} (meta/info.json)")
    if not isinstance(info.get("total_episodes"), int) or info["total_episodes"] < 1:
        raise DatasetError(f"dataset {root}: no episodes (meta/info.json total_episodes = "
                           f"{info.get('total_episodes')!r})")
    return meta


def episode_table(root: str | Path) -> pd.DataFrame:
    """One row per episode (behaviour, fail_prob, seed, outcome, ...), in episode order."""
    check_dataset(root)
    return pd.read_parquet(Path(root) / EPISODES_TABLE)


ROW_GROUPS_AT_ONCE = 256  # LeRobot writes one row group per episode; reading a whole file of tens of thousands at
#                            once costs far more memory than its frames (measured: 0.4 GiB for 8,000 row groups
#                            holding 43 MiB of columns), so a file is read this many row groups at a time


def frame_columns(root: str | Path, names: list[str]) -> dict[str, np.ndarray]:
    """The frame columns ``names`` of a dataset (checked by the caller: :func:`check_dataset`) as numpy, one row
    per frame in index order: a vector feature as (frames, size), a scalar one (stored as a 1-element vector or a
    plain value) as (frames,). Each data file is read once, a few row groups at a time into arrays of the final
    size (memory: the columns' own and one file's bytes, whatever the number of episodes), and its md5 is taken
    from the same bytes: a damaged file — truncated or one bit flipped, in the workspace or in DVC's cache it
    came from — against ``meta/hnsdt.json``'s ``data_md5`` (which the card cites) stops with what to run, never
    with a wrong number."""
    import hashlib

    import pyarrow as pa
    import pyarrow.parquet as pq

    root = Path(root)
    files = sorted((root / "data").glob("**/*.parquet"))
    if not files:
        raise DatasetError(f"dataset {root}: no data/**/*.parquet files")
    recorded = json.loads((root / HNSDT_META).read_text()).get("data_md5")
    md5, out, index, at, failure = hashlib.md5(), {}, None, 0, None
    for f in files:  # (the order and bytes hnsdt.data.card.data_md5 hashes)
        data = f.read_bytes()
        md5.update(f.relative_to(root).as_posix().encode())
        md5.update(data)
        if failure is not None:
            continue
        try:
            parquet = pq.ParquetFile(pa.BufferReader(data), pre_buffer=False)
            total = parquet.metadata.num_rows
            for first in range(0, parquet.metadata.num_row_groups, ROW_GROUPS_AT_ONCE):
                groups = range(first, min(first + ROW_GROUPS_AT_ONCE, parquet.metadata.num_row_groups))
                table = parquet.read_row_groups(groups, columns=[*names, "index"])
                part = {name: _as_numpy(table.column(name), table.num_rows) for name in [*names, "index"]}
                if index is None:  # the first rows give each column's shape and dtype; the files' metadata the size
                    rows = sum(pq.read_metadata(g).num_rows for g in files if g != f) + total
                    out = {k: np.empty((rows, *v.shape[1:]), v.dtype) for k, v in part.items() if k != "index"}
                    index = np.empty(rows, part["index"].dtype)
                for k, v in part.items():
                    (index if k == "index" else out[k])[at:at + len(v)] = v
                at += table.num_rows
        except (pa.ArrowException, OSError, ValueError) as e:
            failure = e
    if recorded is not None and md5.hexdigest() != recorded:
        raise DatasetError(f"dataset {root}: its data files are damaged (their md5 is not the {recorded} recorded "
                           f"when it was written): `dvc checkout {root}` restores the committed copy from DVC's "
                           "cache; if that is damaged too, `dvc repro --force` the stage that collected it")
    if failure is not None:
        raise DatasetError(f"dataset {root}: cannot read its data files ({type(failure).__name__}: {failure})")
    if index is None or at != len(index) or not np.array_equal(index, np.arange(at)):
        raise DatasetError(f"dataset {root}: its data files do not hold frames 0..{at - 1} in order")
    return out


def _as_numpy(column, rows: int) -> np.ndarray:
    import pyarrow as pa

    col = column.combine_chunks()
    if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
        values = col.flatten().to_numpy(zero_copy_only=False).reshape(rows, -1)
        return values[:, 0] if values.shape[1] == 1 else values
    return col.to_numpy(zero_copy_only=False)
