"""The unseen-layout experiment (hnsdt.compose.generalisation) outside the pipeline: other families, sizes, budgets.

Runs the three stages' functions — collect on the training layouts, train each method on views, evaluate on
the training, held-out, MiniGrid and hand-drawn layouts — in a temporary folder, with params.yaml's `generalisation`
section changed from the command line, and prints the table the report shows (success and steps / optimal per
method and split, averaged over the failure probabilities) and the time each part took.

Run: python benchmarks/generalisation.py [--family multikeydoor] [--train-layouts 40] [--heldout-layouts 10]
     [--seeds 0 1 2] [--methods hnsdt pure_dt] [--episodes 10] [--no-minigrid] [--no-drawn] [--set KEY=VALUE ...]
(`--set` takes a `generalisation` key as YAML, e.g. `--set max_steps=250 --set 'budgets={gru: {epochs: 20}}'`;
`--set 'validation_families=[keydoor, keydoor_maze, keydoor_obstacles]' --set max_steps=150` measures every
training family on one validation split of three shapes, with one step limit. `--relabel N` adds rounds of the
learner's own states labelled by the planner (hnsdt.data.relabel, DAgger): after a decision transformer
trains, it acts N episodes per training layout, each step is labelled with the controller's action (towards
HNSDT's own sub-goal; for the pure DT, the planner's first from that state), and it trains again on the dataset
plus those frames; `--relabel-rounds R` repeats it R times.
`--record NAME --ingredient I` adds the run's table to benchmarks/results/generalisation.csv as the variant NAME
(hnsdt.evaluation.ablations: the report's ablation table and scaling figure), with the command, revision and
digests that made it.) `--keep DIR` keeps the run's dataset, models and results (per fail_prob, episode and
sub-goal segment: the stage's summary.csv, episodes.csv and segments.csv) and its params in DIR, which must not
exist; any evaluated episode can then be made again and recorded: `hnsdt --params DIR/params.yaml generalisation
replay --models DIR/models --results DIR/results --episode ID`.
"""

import argparse
import copy
import hashlib
import shlex
import shutil
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

from hnsdt.core.reproducible import pin_process

pin_process()

from hnsdt.compose import generalisation as gen  # noqa: E402
from hnsdt.stages.collect_unseen import collect_unseen  # noqa: E402
from hnsdt.stages.evaluate_unseen import evaluate_unseen  # noqa: E402
from hnsdt.stages.train_unseen import plan_unseen  # noqa: E402
from hnsdt.compose.config import compute_settings, load_params  # noqa: E402
from hnsdt.compose.params import validate  # noqa: E402
from hnsdt.evaluation import ablations  # noqa: E402
from hnsdt.core.methods import DT_METHODS  # noqa: E402
from hnsdt.report.common import SPLIT_LABELS  # noqa: E402
from hnsdt.report.unseen import drawn_lines, generalisation_table  # noqa: E402
from hnsdt.models.checkpoint import load_checkpoint  # noqa: E402
from hnsdt.compose.training import train_all  # noqa: E402

MAX_STEPS = {"keydoor": 100, "multikeydoor": 250, "keydoor_obstacles": 150, "keydoor_maze": 150,
             "keydoor_mixed": 150, "keydoor_perfect": 150, "keydoor_mazes": 150}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", default="params.yaml")
    ap.add_argument("--family", choices=list(MAX_STEPS))
    ap.add_argument("--train-layouts", type=int)
    ap.add_argument("--heldout-layouts", type=int)
    ap.add_argument("--seeds", type=int, nargs="+")
    ap.add_argument("--methods", nargs="+")
    ap.add_argument("--episodes", type=int, help="evaluation episodes per layout and fail_prob")
    ap.add_argument("--no-minigrid", action="store_true", help="no MiniGrid split (a family whose flags differ)")
    ap.add_argument("--no-drawn", action="store_true", help="no hand-drawn split (a family whose flags differ)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--relabel", type=int, default=0, metavar="N",
                    help="learner episodes per training layout labelled by the planner, then train again (DAgger)")
    ap.add_argument("--relabel-rounds", type=int, default=1, metavar="R")
    ap.add_argument("--record", metavar="NAME", help="add the results to --results as the variant NAME")
    ap.add_argument("--ingredient", choices=ablations.INGREDIENTS, help="what --record's variant changes")
    ap.add_argument("--results", type=Path, default=Path("benchmarks/results/generalisation.csv"))
    ap.add_argument("--keep", type=Path, metavar="DIR", help="keep the dataset, models and results in DIR (new)")
    args = ap.parse_args()
    if bool(args.record) != bool(args.ingredient):
        ap.error("--record and --ingredient go together")
    if args.keep and args.keep.exists():
        ap.error(f"--keep {args.keep} exists: name a new folder")
    raw = copy.deepcopy(load_params(args.params).raw)
    g = raw["generalisation"]
    if args.family:
        g.update(family=args.family, max_steps=MAX_STEPS[args.family])
        raw["models"].setdefault(args.family, raw["models"]["keydoor"])  # (the DTs' size: Case 1's if not set)
    for key, value in (("train_layouts", args.train_layouts), ("heldout_layouts", args.heldout_layouts),
                       ("seeds", args.seeds), ("episodes", args.episodes)):
        if value is not None:
            g[key] = value
    g["method_seeds"] = {}  # every variant's methods at the same seeds (--seeds; --set method_seeds=... to differ)
    if args.methods:  # split like params.yaml: decision transformers, then the other learned methods
        g["methods"] = [m for m in args.methods if m in DT_METHODS]
        g["baselines"] = [m for m in args.methods if m not in DT_METHODS]
    if args.no_minigrid or args.family == "multikeydoor":
        g["minigrid"] = []
    if args.no_drawn or args.family == "multikeydoor":
        g["drawn"] = None
    for item in args.set:
        key, _, value = item.partition("=")
        g[key] = yaml.safe_load(value)
    g["evaluated_train_layouts"] = min(g["evaluated_train_layouts"], g["train_layouts"])
    params = validate(raw, f"{args.params} with the command line's changes")
    compute = compute_settings(params)
    times, validation, best, rounds = {}, [], {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        dataset = collect_unseen(params, tmp / "dataset", progress=False)
        times["collect"] = time.perf_counter() - t0
        for method in g["methods"] + g["baselines"]:
            t0 = time.perf_counter()
            runs = plan_unseen(params, method, dataset)
            train_all(runs, g["family"], tmp / "models" / method, tmp / "curves" / method, compute, progress=False)
            times[f"train {method}"] = time.perf_counter() - t0
            kept = kept_validation(tmp / "models" / method, params.generalisation.seeds_of(method))
            validation += validation_lines(kept, method, "")
            best[method] = mean_validation(kept)
            rounds[method] = args.relabel_rounds if args.relabel and method in DT_METHODS else 0
            for r in range(rounds[method]):
                t0 = time.perf_counter()
                runs = [relabelled_run(params, run, tmp / "models" / method, args.relabel) for run in runs]
                times[f"relabel {method} round {r + 1}"] = time.perf_counter() - t0
                t0 = time.perf_counter()
                train_all(runs, g["family"], tmp / "models" / method, tmp / "curves" / method, compute,
                          progress=False)
                times[f"train {method} round {r + 1}"] = time.perf_counter() - t0
                kept = kept_validation(tmp / "models" / method, params.generalisation.seeds_of(method))
                validation += validation_lines(kept, method, f" (relabel round {r + 1})")
                best[method] = mean_validation(kept)
        t0 = time.perf_counter()
        evaluate_unseen(params, tmp / "models", tmp / "results", compute, progress=False)
        times["evaluate"] = time.perf_counter() - t0
        summary = pd.read_csv(tmp / "results/summary.csv")
        table = generalisation_table(summary)
        per_map = drawn_lines(pd.read_csv(tmp / "results/episodes.csv"))
        if args.record:
            rows = variant_rows(args, params, table, best, rounds, folder_digest(tmp / "dataset"), sum(times.values()))
            ablations.record(args.results, rows)
        if args.keep:  # (copied whole, then renamed: no half-kept folder under the name asked for)
            staging = args.keep.with_name(f".{args.keep.name}.partial")
            shutil.rmtree(staging, ignore_errors=True)
            for part in ("dataset", "models", "curves", "results"):
                shutil.copytree(tmp / part, staging / part)
            (staging / "params.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))  # (for `hnsdt --params`)
            staging.rename(args.keep)
    print(f"\n{g['family']}: {g['train_layouts']} training layouts ({g['evaluated_train_layouts']} evaluated), "
          f"{g['heldout_layouts']} held-out, MiniGrid {[(m['id'], m['layouts']) for m in g['minigrid']]}; seeds "
          f"{g['seeds']}, {g['episodes']} episodes per layout and fail_prob, budgets {g.get('budgets', {})}\n")
    print("| method | split | success | steps / optimal |\n|---|---|---|---|")
    for r in table.itertuples():
        print(f"| {r.method} | {SPLIT_LABELS.get(r.split, r.split)} | {r.success:.3f} ± {r.success_std:.3f} | "
              f"{r.steps_ratio:.2f} |")
    print("\nper fail_prob (success, steps / optimal; mean of seeds):")
    for (method, split), rows in summary.groupby(["method", "split"], sort=False):
        print(f"  {method} {SPLIT_LABELS.get(split, split)}: " + ", ".join(
            f"{r.fail_prob:g} {r.success_mean:.3f} at {r.steps_ratio_mean:.2f}×" for r in rows.itertuples()))
    if per_map:
        print("\nper hand-drawn map (success):\n" + per_map)
    if validation:
        families = ", ".join(g.get("validation_families") or [g["family"]])
        print(f"\nvalidation layouts ({g['validation_layouts']} of {families}), mean steps to the exit at fail_prob 0 "
              "of the epoch kept: " + "; ".join(validation))
    print("\n" + ", ".join(f"{k} {v:.0f} s" for k, v in times.items()) + f"; total {sum(times.values()):.0f} s")
    if args.record:
        print(f"recorded variant {args.record!r} ({args.ingredient}) in {args.results}")
    if args.keep:
        print(f"kept the dataset, models, results and params in {args.keep}")


def kept_validation(models: Path, seeds: list[int]) -> dict[int, dict]:
    """Each seed's budget measure on the validation layouts at the epoch kept (choices are made on it):
    ``{seed: {"value": steps, "epoch": epoch}}``, for the seeds trained with it."""
    kept = {}
    for seed in seeds:
        usage = load_checkpoint(models / f"seed{seed}")[1].get("usage", {})
        if usage.get("validation_steps"):
            history = usage["validation_steps"]
            kept[seed] = min(history, key=lambda h: h["value"]) | {"history": [h["value"] for h in history]}
    return kept


def validation_lines(kept: dict[int, dict], method: str, label: str) -> list[str]:
    """One line per seed: its kept value of the validation measure, when (an epoch, or an online learner's env
    step), and every value."""
    lines = []
    for seed, h in kept.items():
        at, per = (f"epoch {h['epoch']}", "epoch") if "epoch" in h else (f"env step {h['step']}", "evaluation")
        lines.append(f"{method}{label} seed {seed}: {h['value']:.2f} steps at {at} (per {per}: "
                     + " ".join(f"{v:.1f}" for v in h["history"]) + ")")
    return lines


def mean_validation(kept: dict[int, dict]) -> float:
    """The mean over seeds of :func:`kept_validation` (NaN for a method trained without it)."""
    return sum(h["value"] for h in kept.values()) / len(kept) if kept else float("nan")


def folder_digest(folder: Path) -> str:
    """16 hex digits of the sha256 over a folder's files (relative path and bytes, in path order)."""
    h = hashlib.sha256()
    for f in sorted(p for p in folder.rglob("*") if p.is_file()):
        h.update(f.relative_to(folder).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def variant_rows(args, params, table: pd.DataFrame, best: dict, rounds: dict, dataset_digest: str, seconds: float) -> pd.DataFrame:
    """The benchmark's table as rows of hnsdt.evaluation.ablations' file."""
    from hnsdt.core.provenance import cpu_name, git_revision, params_digest

    g = params.generalisation
    side = 2 * g.view_radius + 1
    encoder = f"{side}×{side} " + (f"+ VI {g.value_iterations}" if g.value_iterations else
                                   f"+ {g.conv_layers} conv" if g.conv_layers else "flattened") + (
        " + whole-map planner" if g.whole_map else "")
    return table.assign(
        variant=args.record, ingredient=args.ingredient, family=g.family, train_layouts=g.train_layouts,
        episodes_per_map=2 * g.episodes_per_layout + g.random_episodes_per_layout, encoder=encoder,
        relabel_rounds=table.method.map(rounds).fillna(0).astype(int),
        seeds=table.method.map(lambda m: " ".join(map(str, g.seeds_of(m)))),
        validation_steps=table.method.map(best), command=shlex.join(["python", *sys.argv]),
        revision=git_revision(), params_digest=params_digest(params), dataset_digest=dataset_digest,
        cpu=cpu_name(), seconds=round(seconds))


def relabelled_run(params, run, models: Path, episodes: int):
    """``run`` with its seed's trained model's own episodes on the training layouts, labelled by the planner,
    added to its data (and to the behaviours it learns from)."""
    from dataclasses import replace

    from hnsdt.compose.config import layout_executor
    from hnsdt.data.relabel import RELABELLED, join_frames, learner_frames

    g = params.need("generalisation")
    model, meta = load_checkpoint(models / f"seed{run.seed}")
    frames = learner_frames(model, run.method, meta, [s.layout for s in gen.training_layouts(params)],
                            layout_executor(params, run.method), g.view_radius, g.max_steps,
                            [float(f) for f in params.collect.fail_probs], episodes, run.seed)
    print(f"relabelled {run.method} seed {run.seed}: {frames.episode.max() + 1} episodes, {len(frames)} frames",
          flush=True)
    behaviours = tuple(run.train_cfg.behaviours) + (RELABELLED,)
    return replace(run, data=join_frames(run.frames(), frames), train_cfg=replace(run.train_cfg, behaviours=behaviours))


if __name__ == "__main__":
    main()
