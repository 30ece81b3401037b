"""The pipeline's stages as functions: each takes the validated params (:func:`hnsdt.core.config.load_params`) and
explicit paths, does its work on the executor of ``compute`` and writes its outputs, each complete or absent.

The DVC stage scripts in ``pipeline/`` call them directly (so a stage depends on this module, not on the
command line's help texts), and so do the ``hnsdt`` subcommands of the same names. :func:`run` gives a stage
script the command line's error contract: bad input ends with one ``hnsdt: error:`` line and exit status 2.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Sequence

from hnsdt.core.config import Params, compute_settings, load_params


def _provenance(params: Params) -> dict:
    """What the outputs cite: the code's git revision and the params' digest."""
    from hnsdt.core.provenance import git_revision, params_digest

    return {"git_revision": git_revision(), "params_digest": params_digest(params)}


def collect(params: Params, env: str, out: Path, repo_id: str | None = None, progress: bool = True) -> Path:
    """Stage `collect@ENV`: exploration episodes on one env as a LeRobot dataset at ``out``."""
    from hnsdt.core.config import collect_config
    from hnsdt.data.collect import collect_dataset

    root = collect_dataset(collect_config(params, env), out, repo_id or f"local/{env}", progress=progress,
                           provenance=_provenance(params))
    print(f"wrote LeRobot dataset {root} (card: {root / 'README.md'})")
    return root


def train(params: Params, env: str, method: str, dataset: Path, out: Path, curves: Path,
          seeds: list[int] | None = None, compute=None, progress: bool = True) -> None:
    """Stages `train`, `train_offline`, `train_online`: one method on one env, every seed (``train.seeds``
    unless ``seeds``) a task on ``compute``'s executor. Same seed, same weights, whatever the executor and
    however many workers (tested)."""
    from hnsdt.core.config import env_spec, train_settings
    from hnsdt.training import plan_runs, train_all

    ts = train_settings(params)
    if env not in ts.envs:
        raise ValueError(f"env {env!r} is not in train.envs {list(ts.envs)}")
    env_spec(params, env)
    seeds = list(seeds) if seeds is not None else list(ts.seeds)
    runs = plan_runs(params, env, method, seeds, dataset)
    train_all(runs, env, out, curves, compute or compute_settings(params), progress=progress)
    print(f"wrote {', '.join(f'seed{s}' for s in seeds)} -> {out}/ (curves: {curves}/)")


def evaluate(params: Params, models: Path, datasets: Path, out: Path, recordings: Path | None = None,
             metrics: Path | None = None, compute=None, progress: bool = True):
    """Stage `evaluate`: every method × env × fail_prob × seed; the tables under ``out``, the recordings under
    ``recordings`` (default: beside ``out``), and copies of the two small summaries under ``metrics`` (kept in
    git, so the README's table and `dvc plots show` work on a fresh clone)."""
    import shutil

    from hnsdt.core.config import env_spec, evaluate_settings, executor_config
    from hnsdt.evaluation.evaluate import evaluate_all, summary
    from hnsdt.core.fileio import atomic_file
    from hnsdt.core.methods import ARMS

    settings = evaluate_settings(params)
    envs = {e: env_spec(params, e) for e in settings.envs}
    executors = {arm: executor_config(params, arm) for arm in ARMS}
    table = evaluate_all(settings, envs, executors, models, out, datasets, progress=progress,
                         recordings_dir=recordings, compute=compute or compute_settings(params),
                         provenance=_provenance(params))
    if metrics is not None:
        for name in ("summary.csv", "metrics.json"):
            with atomic_file(Path(metrics) / name) as tmp:
                shutil.copyfile(Path(out) / name, tmp)
    summ = summary(table)
    print(summ[["method", "env", "fail_prob", "success_mean", "steps_mean", "reward_mean"]].to_string(
        index=False, float_format=lambda v: f"{v:.3f}"))
    return summ


def report(params: Params, results: Path, out: Path, generalisation: Path | None = None,
           headline: Path | None = None, ablations: Path | None = None, experiments: Path | None = None) -> Path:
    """Stage `report`: figures and report.md, and the headline metrics (``headline``)."""
    from hnsdt.evaluation.report import write_report

    path = write_report(params, results, out, generalisation=generalisation, headline=headline, ablations=ablations,
                        experiments=experiments)
    print(f"wrote {path}")
    return path


def collect_unseen(params: Params, out: Path, progress: bool = True, provenance: dict | None = None) -> Path:
    """Stage `collect_generalisation`: noisy-planner episodes on every training layout of the unseen-layout
    experiment, one LeRobot dataset with local views at ``out``."""
    from hnsdt import generalisation as gen
    from hnsdt.core.config import layout_collect_config
    from hnsdt.data.collect import collect_on_layouts

    g, cfg = params.need("generalisation"), layout_collect_config(params)
    train = gen.training_layouts(params)
    gen.check_sources(train, max(cfg.fail_probs))
    root = collect_on_layouts(cfg, [s.layout for s in train], out, f"local/generated-{g.family}", g.view_radius,
                              g.family, progress, _provenance(params) if provenance is None else provenance)
    print(f"wrote LeRobot dataset {root} (card: {root / 'README.md'})")
    return root


def plan_unseen(params: Params, method: str, dataset: Path) -> list:
    """One :class:`hnsdt.training.TrainTask` per seed of ``method``'s view network: offline on the ``dataset``
    of the training layouts, online on the layouts; budgets chosen on the validation layouts."""
    from hnsdt import generalisation as gen
    from hnsdt.training import plan_layout_runs

    return plan_layout_runs(params, method, dataset, [s.layout for s in gen.training_layouts(params)],
                            lambda: [s.layout for s in gen.validation_layouts(params)])


def train_unseen(params: Params, method: str, dataset: Path, out: Path, curves: Path, compute=None,
                 progress: bool = True) -> None:
    """Stages `train_generalisation`, `train_generalisation_baselines`: one method on views, every seed."""
    from hnsdt.training import train_all

    runs = plan_unseen(params, method, dataset)
    train_all(runs, params.need("generalisation").family, out, curves, compute or compute_settings(params),
              progress=progress)
    print(f"wrote {', '.join(f'seed{r.seed}' for r in runs)} -> {out}/ (curves: {curves}/)")


def evaluate_unseen(params: Params, models: Path, out: Path, compute=None, progress: bool = True,
                    splits: Sequence[str] | None = None, methods: Sequence[str] | None = None):
    """Stage `evaluate_generalisation`: every method × its seeds on every evaluated layout (training, held-out,
    MiniGrid, drawn), the symbolic baseline as the reference, beside the exact optimum; ``splits`` and ``methods``
    name the splits and learned methods to evaluate (default: every one; each episode is the one it is in the
    whole evaluation)."""
    from hnsdt import generalisation as gen
    from hnsdt.core.config import eval_epsilon, layout_executor
    from hnsdt.core.methods import REFERENCE
    from hnsdt.evaluation.evaluate import evaluate_layouts

    g = params.need("generalisation")
    fps = tuple(float(f) for f in params.need("evaluate").fail_probs)
    sources = tuple(gen.layout_splits(params, evaluated_only=True))
    if splits:
        named = list(dict.fromkeys(s.split for s in sources))
        unknown = [s for s in splits if s not in named]
        if unknown:
            raise ValueError(f"--splits: no split {', '.join(unknown)} here (the experiment's: {', '.join(named)})")
    unknown = [m for m in methods or [] if m not in g.learned]
    if unknown:
        raise ValueError(f"--methods: {', '.join(unknown)} not learned here (the experiment's: {', '.join(g.learned)})")
    gen.check_sources(sources, max(fps))
    evaluated = [*(m for m in g.learned if not methods or m in methods), REFERENCE]
    table = evaluate_layouts({m: g.seeds_of(m) for m in evaluated}, sources, fps, g.episodes,
                             {m: layout_executor(params, m) for m in evaluated},  # (generalisation.operators)
                             {m: eval_epsilon(params, m) for m in evaluated}, models, out,
                             compute or compute_settings(params), progress, splits or None)
    print(f"wrote {out}/episodes.csv ({len(table)} episodes), summary.csv, segments.csv, layouts.csv")
    return table


def replay_unseen(params: Params, models: Path, results: Path, episode_id: str, threads: int = 1) -> tuple[dict, dict]:
    """An evaluated unseen-layout episode (``METHOD/seedK/LAYOUT/fpP/epI``, a row of ``results``/episodes.csv) made
    again and recorded (:func:`hnsdt.evaluation.evaluate.rerun_layout_episode`), checked against its row;
    ``(its row, its .rrd and .mcap bytes)``."""
    import pandas as pd

    from hnsdt import generalisation as gen
    from hnsdt.core.config import eval_epsilon, layout_executor
    from hnsdt.evaluation.evaluate import layout_episode_id, rerun_layout_episode

    table_path = Path(results) / "episodes.csv"
    if not table_path.is_file():
        raise FileNotFoundError(f"{table_path}: no unseen-layout results (run `dvc repro evaluate_generalisation`, "
                                "or `hnsdt generalisation evaluate --out` and point --results there)")
    table = pd.read_csv(table_path)
    ids = [layout_episode_id(*key) for key in zip(table.method, table.seed, table.layout, table.fail_prob,
                                                  table.episode)]
    if episode_id not in ids:
        raise ValueError(f"no episode {episode_id!r} in {table_path} (ids are METHOD/seedK/LAYOUT/fpP/epI of its "
                         f"columns, e.g. {ids[0]!r})")
    row = table.iloc[ids.index(episode_id)]
    fps = tuple(float(f) for f in params.need("evaluate").fail_probs)
    sources = tuple(gen.layout_splits(params, evaluated_only=True))
    outcome, files = rerun_layout_episode(sources, fps, params.need("generalisation").episodes, models,
                                          row["method"], int(row["seed"]), layout_executor(params, row["method"]),
                                          eval_epsilon(params, row["method"]), row["layout"],
                                          float(row["fail_prob"]), int(row["episode"]), threads,
                                          _provenance(params))
    outcome["reward"] = float(f"{outcome['reward']:.6g}")  # (as episodes.csv writes it)
    _check_outcome(episode_id, outcome, row, table_path)
    return row, files


def replay_evaluated(params: Params, models: Path, row, table_path: Path, threads: int = 1) -> dict:
    """An evaluated episode of the paper protocol (``row`` of ``table_path``, its episodes.csv) made again
    (:func:`hnsdt.evaluation.evaluate.rerun_episode`), checked against its row; its .rrd and .mcap bytes."""
    from hnsdt.core.config import env_spec, evaluate_settings, executor_config
    from hnsdt.core.methods import ARMS
    from hnsdt.evaluation.evaluate import Cell, rerun_episode

    settings = evaluate_settings(params)
    if row["env"] not in settings.envs:
        raise ValueError(f"{row['episode_id']}: env {row['env']} is not in train.envs of the params")
    outcome, files = rerun_episode(settings, {e: env_spec(params, e) for e in settings.envs},
                                   {arm: executor_config(params, arm) for arm in ARMS}, models,
                                   Cell(row["method"], row["env"], float(row["fail_prob"]), int(row["seed"])),
                                   int(row["episode"]), threads, _provenance(params))
    _check_outcome(row["episode_id"], outcome, row, table_path)
    return files


def _check_outcome(episode_id: str, outcome: dict, row, table_path: Path) -> None:
    """An episode made again must end as its row of the evaluation says."""
    listed = {key: type(value)(row[key]) for key, value in outcome.items()}
    if outcome != listed:
        raise ValueError(f"{episode_id} ran again to {outcome}, not to {listed} as in {table_path}: the models, "
                         "params, maps or code changed since that evaluation (`dvc status` says which, for the "
                         "pipeline's own)")


def run_unseen_experiment(params: Params, out: Path, compute=None, progress: bool = True):
    """Stage `unseen_experiment@NAME` (``params`` as :func:`hnsdt.core.config.unseen_experiment` gives them): the
    three stages above in one process — ``out``/dataset, ``out``/models/METHOD and ``out``/curves/METHOD for
    every learned method, ``out``/results — each part written whole."""
    out = Path(out)
    dataset = collect_unseen(params, out / "dataset", progress=progress)
    for method in params.need("generalisation").learned:
        train_unseen(params, method, dataset, out / "models" / method, out / "curves" / method, compute, progress)
    return evaluate_unseen(params, out / "models", out / "results", compute, progress)


def guarded(fn: Callable[..., object], *args, **kwargs) -> int:
    """``fn(*args, **kwargs)`` under the command line's error contract: 0, or 2 after one ``hnsdt: error:`` line
    naming the problem (the ``hnsdt`` command and every stage script use it)."""
    from hnsdt.envs import LayoutError

    try:
        fn(*args, **kwargs)
    except (LayoutError, ValueError, RuntimeError, OSError) as e:  # (a ParamsError is a ValueError)
        print("hnsdt: error: " + " ".join(str(e).split()), file=sys.stderr)  # always one line
        return 2
    return 0


def run(stage: Callable[..., object], params_path: str | Path = "params.yaml", experiment: str | None = None,
        **arguments) -> int:
    """What a stage script runs: ``stage(load_params(params_path), **arguments)``, :func:`guarded`; with
    ``experiment``, the params as that unseen-layout experiment sees them."""
    from hnsdt.core.config import unseen_experiment

    return guarded(lambda: stage(unseen_experiment(load_params(params_path), experiment), **arguments))
