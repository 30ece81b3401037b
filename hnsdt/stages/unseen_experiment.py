"""Stage `unseen_experiment@NAME`: a further unseen-layout experiment collected, trained and evaluated in one
process."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params
from hnsdt.stages.collect_unseen import collect_unseen
from hnsdt.stages.evaluate_unseen import evaluate_unseen
from hnsdt.stages.train_unseen import train_unseen


def run_unseen_experiment(params: Params, out: Path, compute=None, progress: bool = True):
    """Stage `unseen_experiment@NAME` (``params`` as :func:`hnsdt.compose.config.unseen_experiment` gives them): the
    three stages above in one process — ``out``/dataset, ``out``/models/METHOD and ``out``/curves/METHOD for
    every learned method, ``out``/results — each part written whole."""
    from hnsdt.compose.training import require_dt_size

    out = Path(out)
    require_dt_size(params)  # (before the collection's minutes)
    dataset = collect_unseen(params, out / "dataset", progress=progress)
    for method in params.need("generalisation").learned:
        train_unseen(params, method, dataset, out / "models" / method, out / "curves" / method, compute, progress)
    return evaluate_unseen(params, out / "models", out / "results", compute, progress)
