"""Stage `evaluate`: every method × paper map × fail_prob × seed against the exact optimum."""

from __future__ import annotations

from pathlib import Path

from hnsdt.compose.config import Params, compute_settings
from hnsdt.stages.common import provenance


def evaluate(params: Params, models: Path, datasets: Path, out: Path, recordings: Path | None = None,
             metrics: Path | None = None, compute=None, progress: bool = True):
    """Stage `evaluate`: every method × env × fail_prob × seed; the tables under ``out``, the recordings under
    ``recordings`` (default: beside ``out``), and copies of the two small summaries under ``metrics`` (kept in
    git, so the README's table and `dvc plots show` work on a fresh clone)."""
    import shutil

    from hnsdt.compose.config import env_spec, evaluate_settings, executor_config
    from hnsdt.evaluation.paper import paper_evaluation
    from hnsdt.evaluation.runs import evaluate as run_evaluation
    from hnsdt.evaluation.tables import summary
    from hnsdt.core.fileio import atomic_file
    from hnsdt.core.methods import ARMS

    settings = evaluate_settings(params)
    envs = {e: env_spec(params, e) for e in settings.envs}
    executors = {arm: executor_config(params, arm) for arm in ARMS}
    plan = paper_evaluation(settings, envs, executors, models, datasets,
                            recordings if recordings is not None else Path(out).parent / "recordings",
                            provenance(params))
    table = run_evaluation(plan, out, compute or compute_settings(params), progress)
    if metrics is not None:
        for name in ("summary.csv", "metrics.json"):
            with atomic_file(Path(metrics) / name) as tmp:
                shutil.copyfile(Path(out) / name, tmp)
    summ = summary(table)
    print(summ[["method", "env", "fail_prob", "success_mean", "steps_mean", "reward_mean"]].to_string(
        index=False, float_format=lambda v: f"{v:.3f}"))
    return summ
