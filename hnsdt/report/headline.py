"""The headline metrics that ``dvc metrics show`` and ``dvc exp show`` compare: a folder of one small JSON file
per split (``metrics/headline/keydoor.json``: every learned method's success, HNSDT's steps / optimum), so that
``dvc metrics show`` prints one row per split and one column per method, about 150 characters wide."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from hnsdt.core.fileio import atomic_dir
from hnsdt.core.methods import METHODS, PROPOSED
from hnsdt.report.common import methods_in


HEADLINE_SPLITS = ("heldout", "minigrid", "drawn")  # the unseen-layout splits in the headline (training maps:


def headline_metrics(summ: pd.DataFrame, unseen: pd.DataFrame | None = None,
                     experiments: dict[str, pd.DataFrame] | None = None) -> dict:
    """The few numbers `dvc metrics show` and `dvc exp show` compare by default (the per-cell tables stay in
    ``results/`` and ``metrics/summary.csv``): per split (each paper env, each unseen-layout split) every method's
    success and HNSDT's steps / optimum, each the mean over the failure probabilities of the mean over seeds.
    The methods that learn nothing (the planners with hand-written controllers, at 1.000 in every cell here) are
    left to the report, so that the headline stays at about 40 numbers. Short keys (``keydoor.hnsdt``), so that
    `dvc exp show --only-changed` fits a terminal."""
    def mean(values: pd.Series) -> float | None:
        return None if values.isna().all() else round(float(values.mean()), 4)

    splits = [(env, summ[summ.env == env], "steps_ratio") for env in dict.fromkeys(summ.env)]
    if unseen is not None:
        splits += [(split, unseen[unseen.split == split], "steps_ratio_mean") for split in HEADLINE_SPLITS]
    for name, d in (experiments or {}).items():  # further experiments: their held-out maps
        splits.append((f"{name}.heldout", d[d.split == "heldout"], "steps_ratio_mean"))
    out = {}
    for name, d, ratio_column in splits:
        if len(d):
            out[name] = {m: mean(d[d.method == m].success_mean) for m in methods_in(d) if METHODS[m].training != "none"}
            ratio = mean(d[d.method == PROPOSED][ratio_column]) if ratio_column in d else None
            if ratio is not None:
                out[name][f"{PROPOSED}_steps_ratio"] = ratio
    return out


def _order(split: str) -> tuple:
    """The paper envs first, then the unseen-layout splits, then the further experiments' (``NAME.heldout``)."""
    if split in HEADLINE_SPLITS:
        return (1, HEADLINE_SPLITS.index(split), "")
    return (2 if "." in split else 0, 0, split)


def write_headline(metrics: dict, folder: Path) -> None:
    """:func:`headline_metrics` as ``folder/<split>.json``, replacing the folder whole (atomically)."""
    with atomic_dir(folder) as tmp:
        tmp.mkdir(parents=True)
        for split, values in metrics.items():
            (tmp / f"{split}.json").write_text(json.dumps(values, indent=2) + "\n")


def read_headline(folder: Path) -> dict:
    """``split -> {metric: value}`` from a folder :func:`write_headline` wrote, in the report's order."""
    files = sorted(Path(folder).glob("*.json"), key=lambda f: _order(f.stem))
    if not files:
        raise FileNotFoundError(f"{folder}: no headline metrics (run `dvc repro report`)")
    return {f.stem: json.loads(f.read_text()) for f in files}
