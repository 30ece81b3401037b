"""The ``hnsdt`` command: inspect environments and plans, export PDDL, and run each pipeline stage (collect,
train, evaluate, report) or replay an episode.

Every subcommand reads its knobs from params.yaml (``--params``); bad input ends with one ``hnsdt: error:``
line and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hnsdt.core.methods import LEARNED


def _resolve_env(args) -> tuple[str, object, int]:
    """--env is a params env name (keydoor), or a registered id; --layout overrides the layout."""
    from hnsdt.compose.config import env_spec, load_params
    from hnsdt.envs import ENV_IDS, load_layout

    if args.env in ENV_IDS:
        kwargs = ENV_IDS[args.env][1]
        env_id, layout, max_steps = args.env, load_layout(kwargs["layout"]), kwargs["max_steps"]
    else:
        env = env_spec(load_params(args.params), args.env)
        env_id, layout, max_steps = env.id, env.layout, env.max_steps
    if getattr(args, "layout", None):
        layout = load_layout(args.layout)
    return env_id, layout, max_steps


def cmd_envs(args) -> None:
    from hnsdt.envs import BUILTIN_LAYOUTS, ENV_IDS, load_layout

    for env_id, (cls, kwargs) in ENV_IDS.items():
        print(f"{env_id}  ({cls.__name__}, layout={kwargs['layout']}, max_steps={kwargs['max_steps']})")
    for name in BUILTIN_LAYOUTS:
        lay = load_layout(name)
        print(f"\nlayout {name} ({lay.shape[0]}x{lay.shape[1]}):\n{lay.text}", end="")


def cmd_plan(args) -> None:
    import numpy as np

    from hnsdt.symbolic import SymbolicState, plan, plan_cost, psi

    env_id, layout, _ = _resolve_env(args)
    if args.state:
        obs = np.array([int(v) for v in args.state.split(",")], dtype=np.int64)
        if len(obs) != layout.state_size:
            raise ValueError(f"--state needs {layout.state_size} comma-separated integers "
                             f"({', '.join(layout.state_names)})")
        start = SymbolicState.from_observation(layout, obs)
    else:
        start = SymbolicState.initial(layout)
    ops = plan(layout, start, args.mode, args.operators)
    print(f"{env_id} on layout {layout.name}, planner mode {args.mode} over {args.operators} operators, "
          f"from {sorted(start.predicates(layout))}")
    print(layout.text)
    print(f"{'#':>2}  {'operator':<20} {'sub-goal id':>11}  {'target':>7}  {'cost':>4}")
    for i, op in enumerate(ops, 1):
        g = psi(op)
        print(f"{i:>2}  {op.name:<20} {g.id:>11}  {str(g.target):>7}  {op.cost:>4}")
    print(f"{len(ops)} operators, cost {plan_cost(ops)} steps without move failures")


def cmd_pddl(args) -> None:
    from hnsdt.symbolic.pddl import write_pddl

    _, layout, _ = _resolve_env(args)
    domain, problem = write_pddl(layout, args.out, operators=args.operators)
    print(f"wrote {domain} and {problem}")


def cmd_collect(args) -> None:
    from hnsdt.compose.config import load_params
    from hnsdt.stages.collect import collect

    collect(load_params(args.params), args.env, Path(args.out or f"data/datasets/{args.env}"), args.repo_id,
                   progress=not args.quiet)


def cmd_dataset_push(args) -> None:
    """Upload a collected dataset to the Hugging Face Hub (or, with --dry-run, list what would go)."""
    import os

    os.environ.setdefault("HF_HUB_OFFLINE", "0")  # the library reads datasets offline; pushing needs the Hub
    from hnsdt.data.hub import push_dataset, push_plan

    root = Path(args.root or f"data/datasets/{args.env}")
    if "/" not in args.repo_id:
        raise ValueError(f"--repo-id must be OWNER/NAME, got {args.repo_id!r}")
    if args.dry_run:
        files, card = push_plan(root, args.repo_id)
        print(f"would upload {len(files)} files from {root} to https://huggingface.co/datasets/{args.repo_id}"
              f"{' (private)' if args.private else ''}, tagged with the LeRobot codebase version:")
        print("\n".join(f"  {f}" for f in files))
        print(f"with the card (README.md, {len(card.splitlines())} lines) that {root / 'README.md'} holds")
        return
    push_dataset(root, args.repo_id, private=args.private)
    print(f"pushed {root} -> https://huggingface.co/datasets/{args.repo_id}")


def cmd_train(args) -> None:
    """Train one method on one env for every seed (train.seeds, or --seed): one task per seed on the
    executor of ``compute`` (or --executor/--workers)."""
    from hnsdt.compose.config import compute_settings, load_params
    from hnsdt.stages.train import train

    params = load_params(args.params)
    train(params, args.env, args.method, Path(args.dataset or f"data/datasets/{args.env}"),
                 Path(args.out or f"models/{args.env}/{args.method}"),
                 Path(args.curves or f"plots/train/{args.env}-{args.method}"), seeds=args.seed,
                 compute=compute_settings(params, args.executor, args.workers), progress=not args.quiet)


def cmd_evaluate(args) -> None:
    from hnsdt.compose.config import compute_settings, load_params
    from hnsdt.stages.evaluate import evaluate

    params = load_params(args.params)
    evaluate(params, Path(args.models), Path(args.datasets), Path(args.out),
                    Path(args.recordings) if args.recordings else None,
                    compute=compute_settings(params, args.executor, args.workers), progress=not args.quiet)


def cmd_report(args) -> None:
    from hnsdt.compose.config import load_params
    from hnsdt.stages.report import report

    report(load_params(args.params), Path(args.results), Path(args.out),
                  generalisation=Path(args.generalisation) if args.generalisation else None,
                  headline=Path(args.headline) if args.headline else None,
                  ablations=Path(args.ablations) if args.ablations else None,
                  experiments=Path(args.experiments) if args.experiments else None)


def cmd_replay(args) -> None:
    import pandas as pd

    if args.dataset is not None:
        from hnsdt.logs import record_from_dataset, write_mcap, write_rrd

        rec = record_from_dataset(args.dataset, args.episode)
        out = Path(args.out or f"{Path(args.dataset).name}-ep{args.episode}.rrd")
        write_rrd(out, rec, episode_index=args.episode)
        write_mcap(out.with_suffix(".mcap"), rec)
        print(f"episode {args.episode} of {args.dataset}: {rec.length} frames, success={rec.success}, "
              f"sub-goals: {' -> '.join(s[0] for s in rec.segments) or 'none'}")
        print(f"  {out}\n  {out.with_suffix('.mcap')}")
        print(f"open with: rerun {out}   (or load {out.with_suffix('.mcap')} in Foxglove)")
        if args.open:
            _open_in_rerun([out])
        return
    table_path = Path(args.results) / "episodes.csv"
    if not table_path.is_file():
        raise FileNotFoundError(f"{table_path}: no evaluation results (run `dvc repro evaluate`)")
    table = pd.read_csv(table_path, keep_default_na=False)
    pattern = args.episode_id
    rows = table[table.episode_id == pattern]
    if rows.empty and any(c in pattern for c in "*?["):  # several episodes, to compare side by side
        import fnmatch

        rows = table[[fnmatch.fnmatchcase(i, pattern) for i in table.episode_id]]
        if rows.empty:
            raise ValueError(f"no episode matches {pattern!r} in {table_path} (ids look like "
                             f"{table.episode_id.iloc[0]!r})")
        again = int((rows.rrd == "").sum())
        if again > MAX_MADE_AGAIN:
            raise ValueError(f"{pattern!r} matches {len(rows)} episodes, {again} of them not recorded: at most "
                             f"{MAX_MADE_AGAIN} are made again at once (name one cell's episode, e.g. "
                             "'*/keydoor/fp0.1/seed3/ep5')")
    elif rows.empty:
        raise ValueError(f"no episode {pattern!r} in {table_path} (ids look like {table.episode_id.iloc[0]!r}; a "
                         "pattern such as '*/keydoor/fp0.1/seed0/ep0' selects several)")
    for row in rows.itertuples():
        print(f"{row.episode_id}: success={row.success}, steps={row.steps}, reward={row.reward}, "
              f"replans={row.replans}")
    base = Path(args.results).parent
    rrds = []
    for _, row in rows.iterrows():
        if row["rrd"]:
            rrds.append(base / row["rrd"])
            print(f"  {rrds[-1]}\n  {base / row['mcap']}")
        else:  # made again: to --out (a file for one episode, a folder for several), by default here
            name = row["episode_id"].replace("/", "-") + ".rrd"
            out = Path(args.out or name) if len(rows) == 1 else Path(args.out or ".") / name
            rrds.append(_record_again(args, row, table_path, out))
    layout = base / "recordings" / "foxglove_layout.json"
    print(f"open with: rerun {' '.join(map(str, rrds))}   (or load the .mcap in Foxglove"
          + (f", with the layout {layout})" if layout.is_file() else ")"))
    if args.open:
        _open_in_rerun(rrds)


MAX_MADE_AGAIN = 20  # episodes one `hnsdt replay` makes again (each a run of its method x env x seed)


def _record_again(args, row, table_path: Path, out: Path) -> Path:
    """An episode `evaluate` did not record (``logs.episodes_per_cell``), made again and checked against its row
    (:func:`hnsdt.stages.replay.replay_evaluated`), written to ``out`` (outside every pipeline output)."""
    from hnsdt.compose.config import compute_settings, load_params
    from hnsdt.stages.replay import replay_evaluated

    params = load_params(args.params)
    print(f"  not recorded: running {row['method']} on {row['env']} with seed {row['seed']} again, as `evaluate` "
          "ran it", flush=True)
    files = replay_evaluated(params, Path(args.models), row, table_path, compute_settings(params).threads)
    return _write_recording(files, out)


def _write_recording(files: dict[str, bytes], out: Path) -> Path:
    """An episode made again: its ``.rrd`` at ``out`` and its ``.mcap`` beside it."""
    from hnsdt.core.fileio import atomic_file

    for path, data in ((out, files[".rrd"]), (out.with_suffix(".mcap"), files[".mcap"])):
        with atomic_file(path) as tmp:
            tmp.write_bytes(data)
    print(f"  {out}\n  {out.with_suffix('.mcap')}\n  (the same steps as evaluated)")
    return out


def _open_in_rerun(rrds: list[Path]) -> None:
    """One viewer holding every recording (each has its own recording id, so they sit side by side)."""
    import shutil
    import subprocess

    viewer = shutil.which("rerun")
    if viewer is None:
        raise FileNotFoundError("the rerun viewer is not on PATH (it ships with rerun-sdk in .venv/bin)")
    subprocess.Popen([viewer, *map(str, rrds)])



def cmd_generalisation(args) -> None:
    """The unseen-layout experiment's stages (hnsdt.compose.generalisation): collect, train one method, evaluate."""
    from hnsdt.compose.config import compute_settings, load_params, unseen_experiment

    params = unseen_experiment(load_params(args.params), args.experiment)  # (an unknown name: one line)
    if args.drawn:  # a folder of the user's maps in place of the experiment's drawn maps
        if args.action not in ("evaluate", "replay"):
            raise ValueError("--drawn is an option of generalisation evaluate and replay")
        section = f"unseen_experiments.{args.experiment}" if args.experiment else "generalisation"
        drawn = [f"{section}.drawn=" + json.dumps({"folder": args.drawn, "max_steps": args.drawn_max_steps})]
        params = unseen_experiment(load_params(args.params, drawn), args.experiment)
    if (args.splits or args.methods) and args.action != "evaluate":
        raise ValueError("--splits and --methods are options of generalisation evaluate")
    params.need("generalisation")  # "missing key generalisation" before any work
    ran = Path("generalisation", *(("experiments", args.experiment) if args.experiment else ()))  # the pipeline's
    args.models, args.results = args.models or ran / "models", args.results or ran / "results"   # outputs
    if args.action == "replay":
        if not args.episode:
            raise ValueError("generalisation replay needs --episode METHOD/seedK/LAYOUT/fpP/epI")
        from hnsdt.stages.replay import replay_unseen

        row, files = replay_unseen(params, Path(args.models), Path(args.results), args.episode,
                                          compute_settings(params).threads)
        print(f"{args.episode} ({row['split']}): success={row['success']}, steps={row['steps']} (the optimum's "
              f"{row['optimal_steps']:g}), reward={row['reward']}")
        name = f"{row['method']}-seed{row['seed']}-{Path(row['layout']).stem}-fp{row['fail_prob']:g}-ep{row['episode']}"
        rrd = _write_recording(files, Path(args.out or name + ".rrd"))
        print(f"open with: rerun {rrd}   (or load {rrd.with_suffix('.mcap')} in Foxglove)")
        if args.open:
            _open_in_rerun([rrd])
        return
    if not args.out:
        raise ValueError(f"generalisation {args.action} needs --out")
    if args.action == "collect":
        from hnsdt.stages.collect_unseen import collect_unseen

        collect_unseen(params, Path(args.out), progress=not args.quiet)
        return
    compute = compute_settings(params, args.executor, args.workers)
    if args.action == "train":
        if not args.method or not args.curves:
            raise ValueError("generalisation train needs --method and --curves")
        from hnsdt.stages.train_unseen import train_unseen

        train_unseen(params, args.method, Path(args.dataset), Path(args.out), Path(args.curves), compute,
                            progress=not args.quiet)
        return
    from hnsdt.stages.evaluate_unseen import evaluate_unseen

    evaluate_unseen(params, Path(args.models), Path(args.out), compute, progress=not args.quiet,
                           splits=args.splits, methods=args.methods)


def _run_arguments(p: argparse.ArgumentParser, func) -> None:
    """The tail of every command that runs tasks: --quiet, where they run, and what runs them."""
    from hnsdt.core.compute import EXECUTORS

    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--executor", choices=EXECUTORS, help="where the runs execute (default: compute.executor); "
                   "ray connects to RAY_ADDRESS or starts a local instance. The outputs do not depend on it")
    p.add_argument("--workers", type=int, help="local executor: runs at once (default: compute.workers; 0 = "
                   "one per core)")
    p.set_defaults(func=func)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hnsdt", description="Hierarchical Neuro-Symbolic Decision Transformer: environments, symbolic "
        "planner, datasets, training, evaluation, report and episode replay. The full pipeline runs with "
        "`dvc repro`; these commands run its parts.")
    parser.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("envs", help="list registered environments and built-in layouts")
    p.set_defaults(func=cmd_envs)

    p = sub.add_parser("plan", help="print the symbolic plan and its sub-goals for an environment")
    p.add_argument("--env", required=True, help="env name from params.yaml (keydoor) or a gymnasium id")
    p.add_argument("--layout", help="override the layout: built-in name, file path or grid text")
    p.add_argument("--mode", choices=["bfs", "cost"], default="bfs",
                   help="bfs: fewest operators (the paper's planner); cost: fewest steps (default: bfs)")
    p.add_argument("--operators", choices=["goto", "move"], default="goto",
                   help="goto: GoTo macro-operators (ours); move: the paper's one-cell Move operators "
                   "(default: goto)")
    p.add_argument("--state", help="plan from this observation, e.g. 4,0,1,0 (row,col,flags...)")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("pddl", help="export the environment's domain and problem as PDDL")
    p.add_argument("--env", required=True, help="env name from params.yaml or a gymnasium id")
    p.add_argument("--layout", help="override the layout")
    p.add_argument("--out", required=True, help="output folder for domain.pddl and problem.pddl")
    p.add_argument("--operators", choices=["goto", "move"], default="goto",
                   help="goto: GoTo macro-operators (ours); move: the paper's one-cell Move operators")
    p.set_defaults(func=cmd_pddl)

    p = sub.add_parser("collect", help="collect exploration data into a LeRobot dataset (the `collect` stage)")
    p.add_argument("--env", required=True, help="env name from params.yaml (e.g. keydoor)")
    p.add_argument("--out", help="dataset folder (default: data/datasets/ENV)")
    p.add_argument("--repo-id", help="LeRobot repo id recorded in the dataset (default: local/ENV)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_collect)

    p = sub.add_parser("train", help="train one learned method on one env, every seed (the `train`, "
                       "`train_offline` and `train_online` stages)")
    p.add_argument("--env", required=True, help="env name from train.envs")
    p.add_argument("--method", required=True, choices=LEARNED, help="a learned method of the registry "
                   "(hnsdt.core.methods)")
    p.add_argument("--seed", type=int, nargs="+", help="training seeds (default: train.seeds of params.yaml)")
    p.add_argument("--dataset", help="offline methods: LeRobot dataset folder (default: data/datasets/ENV)")
    p.add_argument("--out", help="checkpoints folder, one seedK/ per seed (default: models/ENV/METHOD)")
    p.add_argument("--curves", help="training-curve folder, one seedK.csv per seed (default: "
                   "plots/train/ENV-METHOD)")
    _run_arguments(p, cmd_train)

    p = sub.add_parser("dataset", help="share a collected dataset")
    dsub = p.add_subparsers(dest="dataset_command", required=True, metavar="ACTION")
    q = dsub.add_parser("push", help="upload a dataset to the Hugging Face Hub with LeRobot's push_to_hub")
    q.add_argument("env", help="env name; the dataset is data/datasets/ENV unless --root")
    q.add_argument("--repo-id", required=True, help="OWNER/NAME on the Hub")
    q.add_argument("--private", action="store_true", help="create the Hub repository private")
    q.add_argument("--root", help="dataset folder (default: data/datasets/ENV)")
    q.add_argument("--dry-run", action="store_true", help="list the files and the card that would be "
                   "uploaded; no network")
    q.set_defaults(func=cmd_dataset_push)

    p = sub.add_parser("evaluate", help="evaluate every method x env x fail_prob x seed (the `evaluate` stage)")
    p.add_argument("--models", default="models", help="checkpoint root (default: models)")
    p.add_argument("--datasets", default="data/datasets", help="root of the collected datasets, one folder per "
                   "env (default: data/datasets; read for the training segment counts of Theorem 2)")
    p.add_argument("--out", default="results", help="results folder (default: results)")
    p.add_argument("--recordings", help="episode recordings folder (default: recordings beside --out)")
    _run_arguments(p, cmd_evaluate)

    p = sub.add_parser("generalisation", help="the unseen-layout experiment: collect on generated layouts, "
                       "train a method on views, evaluate on training / held-out / MiniGrid layouts (the "
                       "`*_generalisation` stages)")
    p.add_argument("action", choices=["collect", "train", "evaluate", "replay"])
    p.add_argument("--out", help="collect: dataset folder; train: checkpoints folder (one seedK/ per seed); "
                   "evaluate: results folder; replay: the .rrd to write (an .mcap beside it; default: named after "
                   "the episode, here)")
    p.add_argument("--method", choices=LEARNED, help="train: the method")
    p.add_argument("--dataset", default="generalisation/dataset", help="train: the collected dataset")
    p.add_argument("--curves", help="train: training-curve folder")
    p.add_argument("--models", help="evaluate, replay: checkpoint root, one folder per method (default: the "
                   "pipeline's, generalisation/models, or generalisation/experiments/NAME/models with --experiment)")
    p.add_argument("--episode", help="replay: an evaluated episode, METHOD/seedK/LAYOUT/fpP/epI of the columns of "
                   "episodes.csv (e.g. hnsdt/seed0/layouts/drawn/spiral_9x9.txt/fp0.1/ep3), made again from its "
                   "checkpoint and seeds, checked against its row and recorded (.rrd for rerun, .mcap for Foxglove)")
    p.add_argument("--results", help="replay: the evaluation's results folder (default: the pipeline's, as for "
                   "--models; with --drawn: where `generalisation evaluate --drawn` wrote)")
    p.add_argument("--open", action="store_true", help="replay: start the rerun viewer on the recording")
    p.add_argument("--drawn", help="evaluate, replay: a folder of layout files (*.txt, maps of any shape with the "
                   "family's keys and doors), the split `drawn` in place of generalisation.drawn's folder")
    p.add_argument("--drawn-max-steps", type=int, default=250, help="evaluate, replay: the episode step limit on the "
                   "--drawn maps (default: 250)")
    p.add_argument("--splits", nargs="+", metavar="SPLIT", help="evaluate: only these splits (train, heldout, "
                   "minigrid, minigrid_16x16, drawn, ... as the experiment names them; default: every one), e.g. "
                   "`--drawn FOLDER --splits drawn` for your maps alone")
    p.add_argument("--methods", nargs="+", metavar="METHOD", help="evaluate: only these learned methods (the "
                   "symbolic reference runs always; default: every one), e.g. --methods hnsdt pure_dt")
    p.add_argument("--experiment", help="a name of unseen_experiments in params.yaml: its changes to the "
                   "generalisation section apply")
    _run_arguments(p, cmd_generalisation)

    p = sub.add_parser("report", help="figures and report.md from the evaluation (the `report` stage)")
    p.add_argument("--results", default="results")
    p.add_argument("--generalisation", help="results of the unseen-layout experiment (e.g. generalisation/results); "
                   "without it the report has no such section")
    p.add_argument("--out", default="report")
    p.add_argument("--headline", help="also write the headline metrics (success per method and split, HNSDT's "
                   "steps / optimum) as JSON here, e.g. metrics/headline.json")
    p.add_argument("--ablations", help="measured variants of the unseen-layout experiment (e.g. "
                   "benchmarks/results/generalisation.csv, written by benchmarks/generalisation.py --record): "
                   "the report's ablation table and scaling figure")
    p.add_argument("--experiments", help="the folder of the further unseen-layout experiments' outputs (e.g. "
                   "generalisation/experiments, one folder per name of unseen_experiments)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("replay", help="find or render the recording of an episode (.rrd for rerun, .mcap for "
                       "Foxglove)")
    p.add_argument("episode_id", nargs="?", help="an evaluated episode id from results/episodes.csv, e.g. "
                   "hnsdt/keydoor/fp0.1/seed0/ep0, or a pattern for several, e.g. '*/keydoor/fp0.1/seed0/ep0' "
                   "(every method's recorded episode of one env x fail_prob, to compare side by side)")
    p.add_argument("--results", default="results")
    p.add_argument("--dataset", help="instead, render an episode of this collected LeRobot dataset folder")
    p.add_argument("--episode", type=int, default=0, help="with --dataset: the episode index")
    p.add_argument("--models", default="models", help="an episode that was not recorded is run again from these "
                   "checkpoints and recorded (default: models)")
    p.add_argument("--out", help="with --dataset, or an episode that was not recorded: the .rrd to write (an .mcap "
                   "is written beside it; default: the episode's id as a file name, here)")
    p.add_argument("--open", action="store_true", help="start the rerun viewer on the recording")
    p.set_defaults(func=cmd_replay)
    return parser


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        from hnsdt.core.reproducible import pin_process

        pin_process()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "replay" and not args.episode_id and args.dataset is None:
        parser.error("replay needs an EPISODE_ID or --dataset")
    from hnsdt.stages.common import guarded

    return guarded(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
