"""Stages `train_generalisation`, `train_generalisation_baselines`: one method on views, every seed."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params, compute_settings


def plan_unseen(params: Params, method: str, dataset: Path) -> list:
    """One :class:`hnsdt.compose.training.TrainTask` per seed of ``method``'s view network: offline on the ``dataset``
    of the training layouts, online on the layouts; budgets chosen on the validation layouts."""
    from hnsdt.compose import generalisation as gen
    from hnsdt.compose.training import plan_layout_runs

    return plan_layout_runs(params, method, dataset, [s.layout for s in gen.training_layouts(params)],
                            lambda: [s.layout for s in gen.validation_layouts(params)])


def train_unseen(params: Params, method: str, dataset: Path, out: Path, curves: Path, compute=None,
                 progress: bool = True) -> None:
    """Stages `train_generalisation`, `train_generalisation_baselines`: one method on views, every seed."""
    from hnsdt.compose.training import train_all

    runs = plan_unseen(params, method, dataset)
    train_all(runs, params.need("generalisation").family, out, curves, compute or compute_settings(params),
              progress=progress)
    print(f"wrote {', '.join(f'seed{r.seed}' for r in runs)} -> {out}/ (curves: {curves}/)")
