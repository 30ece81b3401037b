"""What each MiniGrid learner used and where it stopped, and the learners measured outside the default run.

DQN and option-critic learn in MiniGrid's worlds too, but cost ≈ 15–30 minutes a world on 2 cores (by the CPU),
so the default run leaves them out (docs/minigrid.md, "Cost"). ``python benchmarks/minigrid_learn_runs.py --world W
--methods dqn options --stage OUT --record FILE`` runs the stage's own function for them — the default's worlds,
training and test seeds, test episodes and plateau rule — and adds its rows to ``FILE`` (kept in git:
``benchmarks/results/minigrid_learners.csv``): per method and fail_prob the stage's ``summary.csv`` row, what the
seeds used and where they stopped (:func:`learner_budget`), and what made them — the command, the git revision and
params digest the stage ran with, the dataset's md5, the CPU and the seconds. ``dvc repro`` does not rerun them;
the report reads the file and sets its rows, marked, beside the default run's.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from hnsdt.core.fileio import atomic_file
from hnsdt.evaluation.minigrid import LEARNED_COLUMNS

COLUMNS = [*LEARNED_COLUMNS, "data", "stopped", "best_validation", "command", "revision", "params_digest",
           "dataset_md5", "cpu", "seconds"]


def span(values: list, form: str) -> str:
    """``lo–hi`` of ``values`` in ``form`` (one value when they are all alike)."""
    lo, hi = form.format(min(values)), form.format(max(values))
    return lo if lo == hi else f"{lo}–{hi}"


def learner_budget(folder: Path, method: str, ceiling: float) -> dict[str, str]:
    """What ``method``'s seeds trained on (``data``), where they stopped (``stopped``) and their best validation
    steps (``best_validation``), from the stage output ``folder``'s ``curves/<method>-seed<k>.json``; ``ceiling``:
    the validation measure of a learner that never reaches a goal."""
    used = [json.loads(p.read_text())["usage"] for p in sorted((Path(folder) / "curves").glob(f"{method}-seed*.json"))]
    if not used:
        raise FileNotFoundError(f"{folder}/curves: no curves of {method}")
    best = [min(v["value"] for v in u["validation_steps"]) for u in used]
    stopped = f"{sum(u['stopped_early'] for u in used)} of {len(used)} at their plateau"
    if "frames" in used[0]:  # (online: env steps)
        data = f"{span([u['frames'] for u in used], '{:,}')} env steps"
        stop = (f"{stopped} (best measurement at {span([u['best_step'] for u in used], '{:,}')} steps)"
                if min(best) < ceiling else "none: no measurement reached a goal, so each trained to its cap")
    else:
        data = f"{used[0]['dataset_frames']:,} dataset frames"
        stop = (f"{stopped}, after {span([u['epochs'] for u in used], '{:g}')} epochs (best "
                f"{span([u['best_epoch'] for u in used], '{}')})")
    return {"data": data, "stopped": stop, "best_validation": span(best, "{:.1f}")}


def stage_rows(out: Path, methods: list[str], ceiling: float, **made: object) -> pd.DataFrame:
    """The rows of ``methods`` from a finished `minigrid_learn` output ``out`` (its summary.csv, curves,
    checkpoints' dataset md5 and provenance.json: the revision and params digest it ran with), with ``made``'s
    columns (command, cpu, seconds)."""
    from hnsdt.evaluation.minigrid import read_csv

    out = Path(out)
    if not (out / "summary.csv").is_file():
        raise FileNotFoundError(f"{out}: no finished minigrid_learn output (summary.csv)")
    summary = [r for r in read_csv((out / "summary.csv").read_text()) if r["method"] in methods]
    missing = sorted(set(methods) - {r["method"] for r in summary})
    if missing:
        raise ValueError(f"{out}/summary.csv: no rows of {', '.join(missing)}")
    provenance = json.loads((out / "provenance.json").read_text())
    md5 = {m: json.loads(next((out / "models" / m).glob("seed*/config.json")).read_text())["dataset_md5"]
           for m in methods}
    budgets = {m: learner_budget(out, m, ceiling) for m in methods}
    return pd.DataFrame([r | budgets[r["method"]] | {"revision": provenance["git_revision"],
                                                     "params_digest": provenance["params_digest"],
                                                     "dataset_md5": md5[r["method"]]} | made
                         for r in summary])[COLUMNS]


def read(path: str | Path) -> pd.DataFrame:
    """The recorded rows; one clear error when the file is not such a table."""
    rows = pd.read_csv(path)
    missing = [c for c in COLUMNS if c not in rows]
    if missing:
        raise ValueError(f"{path}: not a table of MiniGrid learners (missing columns: {', '.join(missing)})")
    return rows[COLUMNS]


def record(path: str | Path, rows: pd.DataFrame) -> None:
    """Add ``rows`` to the file at ``path`` (written whole, atomically): a world's method measured again replaces
    its rows; the others keep their order."""
    path = Path(path)
    old = read(path) if path.is_file() else pd.DataFrame(columns=COLUMNS)
    measured = set(zip(rows.env, rows.method))
    kept = old[[key not in measured for key in zip(old.env, old.method)]]
    new = pd.concat([kept, rows[COLUMNS]], ignore_index=True) if len(kept) else rows[COLUMNS].reset_index(drop=True)
    with atomic_file(path) as tmp:
        new.to_csv(tmp, index=False, float_format="%.6f")
