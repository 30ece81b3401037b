"""What each ingredient of the unseen-layout experiment buys: measured variants, the report's ablation table and
its scaling figure (held-out steps / optimum against the number of training maps).

A variant is the experiment with some knobs changed — the encoder, the number of training maps, relabelled
rounds of the learner's own states — run by ``python benchmarks/generalisation.py --record NAME --ingredient I``
through the experiment's own stage functions. ``dvc repro`` does not rerun them (one costs minutes to half an
hour of 2 cores; 4,000 maps more), so each row carries what made it: the command, the git revision, the digest
of the params and of the dataset it trained on, the CPU and the time. The file is kept in git
(``benchmarks/results/generalisation.csv``) and read by the report stage.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hnsdt.fileio import atomic_file

INGREDIENTS = ("reference", "encoder", "maps", "relabelling", "family")  # reference: the default's knobs
COLUMNS = [  # one row per variant x method x split
    "variant", "ingredient", "family", "train_layouts", "episodes_per_map", "encoder", "relabel_rounds", "seeds",
    "method", "split", "success", "success_std", "steps_ratio", "validation_steps",
    "command", "revision", "params_digest", "dataset_digest", "cpu", "seconds"]


def read(path: str | Path) -> pd.DataFrame:
    """The recorded rows; one clear error when the file is not such a table."""
    rows = pd.read_csv(path)
    missing = [c for c in COLUMNS if c not in rows]
    if missing:
        raise ValueError(f"{path}: not a table of measured variants (missing columns: {', '.join(missing)})")
    unknown = sorted(set(rows.ingredient) - set(INGREDIENTS))
    if unknown:
        raise ValueError(f"{path}: unknown ingredient(s) {unknown}; expected one of {', '.join(INGREDIENTS)}")
    return rows[COLUMNS]


def record(path: str | Path, rows: pd.DataFrame) -> None:
    """Add one variant's rows to the file at ``path`` (written whole, atomically), replacing the rows of a
    variant of the same name in place; other variants keep their order."""
    if rows.variant.nunique() != 1:
        raise ValueError("record() takes the rows of one variant")
    if rows.ingredient.iloc[0] not in INGREDIENTS:
        raise ValueError(f"unknown ingredient {rows.ingredient.iloc[0]!r}; expected one of {', '.join(INGREDIENTS)}")
    path = Path(path)
    name = rows.variant.iloc[0]
    old = read(path) if path.is_file() else pd.DataFrame(columns=COLUMNS)
    if name in set(old.variant):
        at = int(np.flatnonzero(old.variant.to_numpy() == name)[0])
        kept = old[old.variant != name]
        new = pd.concat([kept.iloc[:at], rows[COLUMNS], kept.iloc[at:]], ignore_index=True)
    else:
        new = pd.concat([old, rows[COLUMNS]], ignore_index=True) if len(old) else rows[COLUMNS]
    with atomic_file(path) as tmp:
        new.to_csv(tmp, index=False, float_format="%.4f")


def scaling_points(rows: pd.DataFrame) -> pd.DataFrame:
    """The variants that differ from the reference in their maps alone: per method and split, the number of
    training maps (and episodes per map) against success and steps / optimum."""
    ref = rows[rows.ingredient == "reference"]
    if ref.empty:
        return rows.iloc[:0]
    same = (rows.encoder == ref.encoder.iloc[0]) & (rows.family == ref.family.iloc[0]) & (rows.relabel_rounds == 0)
    return rows[rows.ingredient.isin(["reference", "maps"]) & same].sort_values("train_layouts", kind="stable")
