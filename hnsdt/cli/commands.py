"""What each ``hnsdt`` subcommand does: inspect environments and plans, export PDDL, run a pipeline stage
(:mod:`hnsdt.stages`), share a dataset, or replay an episode; each reads its knobs from params.yaml."""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

DRAWN_MAX_STEPS = 250  # the episode limit on a user's --drawn maps where the experiment draws none of its own


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


def _minigrid_world(args):
    """A MiniGrid id's world for ``--seed`` (stepped by MiniGrid: hnsdt.minigrid), or None for our envs."""
    if not args.env.startswith("MiniGrid-"):
        return None
    from hnsdt.minigrid import world_of

    return world_of(args.env, args.seed)


def _plan_minigrid(world, mode: str) -> None:
    from hnsdt.minigrid.abstraction import phi
    from hnsdt.minigrid.operators import PlanState
    from hnsdt.minigrid.planner import plan

    ops = plan(world, PlanState.of(world.start), mode)
    print(f"{world.name} (stepped by MiniGrid), planner mode {mode}, from {sorted(phi(world, world.start))}")
    print(f"{'#':>2}  {'operator':<24} {'cell':>8}  {'cost':>4}")
    for i, op in enumerate(ops, 1):
        print(f"{i:>2}  {op.name(world):<24} {str(op.cell):>8}  {op.cost:>4}")
    print(f"{len(ops)} operators, {sum(op.cost for op in ops)} cells walked or acted on (turns not counted)")


def cmd_plan(args) -> None:
    import numpy as np

    if (world := _minigrid_world(args)) is not None:
        if args.operators != "goto" or args.state or args.layout:
            raise ValueError("a MiniGrid world plans over its own operators from its start: no --operators move, "
                             "--state or --layout")
        return _plan_minigrid(world, args.mode)

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

    if (world := _minigrid_world(args)) is not None:
        from hnsdt.minigrid.pddl import write_pddl as write_minigrid_pddl

        domain, problem = write_minigrid_pddl(world, args.out)
        print(f"wrote {domain} and {problem}")
        return
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
    """An evaluated episode of either experiment by its id (or several by a pattern), or a dataset's episode:
    the recording the evaluation kept, or the episode made again (hnsdt.stages.replay)."""
    from hnsdt.compose.config import compute_settings

    if args.dataset is not None:
        return _replay_dataset(args)
    from hnsdt.stages.replay import check_recording, find_episodes, record_again

    params = _params_with_drawn(args)
    found = find_episodes(params, args.episode_id, args.experiment, Path(args.results) if args.results else None,
                          Path(args.models) if args.models else None)
    for f in found:
        row = f.row
        print(f"{row['episode_id']} ({f.experiment}{', ' + row['split'] if 'split' in row else ''}): "
              f"success={row['success']}, steps={row['steps']}, reward={row['reward']}")
    rrds = []
    for f in found:
        if f.recorded is not None:
            check_recording(f.recorded)
            rrds.append(f.recorded)
            print(f"  {f.recorded}\n  {f.recorded.with_suffix('.mcap')}")
            continue
        name = f.row["episode_id"].replace("/", "-") + ".rrd"  # made again: to --out (a file for one episode, a
        out = Path(args.out or name) if len(found) == 1 else Path(args.out or ".") / name  # folder for several)
        print(f"  not recorded: running {f.row['method']} with seed {f.row['seed']} again, as the evaluation ran it",
              flush=True)
        rrds.append(_write_recording(record_again(params, f, compute_settings(params).threads), out))
    layout = Path(args.results or "results").parent / "recordings" / "foxglove_layout.json"
    print(f"open with: rerun {' '.join(map(str, rrds))}   (or load the .mcap in Foxglove"
          + (f", with the layout {layout})" if layout.is_file() else ")"))
    if args.open:
        _open_in_rerun(rrds)


def _replay_dataset(args) -> None:
    from hnsdt.core.fileio import write_files
    from hnsdt.logs import record_from_dataset, recording_files

    rec = record_from_dataset(args.dataset, args.episode)
    out = Path(args.out or f"{Path(args.dataset).name}-ep{args.episode}.rrd")
    files = recording_files(rec, episode_index=args.episode)
    write_files({out: files[".rrd"], out.with_suffix(".mcap"): files[".mcap"]})
    print(f"episode {args.episode} of {args.dataset}: {rec.length} frames, success={rec.success}, "
          f"sub-goals: {' -> '.join(s[0] for s in rec.segments) or 'none'}")
    print(f"  {out}\n  {out.with_suffix('.mcap')}")
    print(f"open with: rerun {out}   (or load {out.with_suffix('.mcap')} in Foxglove)")
    if args.open:
        _open_in_rerun([out])


def _further_experiment(args) -> str | None:
    """``--experiment`` when it names one of ``unseen_experiments`` (None: the main unseen-layout experiment)."""
    from hnsdt.stages.replay import PAPER, UNSEEN

    return args.experiment if args.experiment not in (None, PAPER, UNSEEN) else None


def _params_with_drawn(args):
    """The params, with ``--drawn FOLDER`` (a folder of the user's maps) in place of the experiment's drawn maps."""
    from hnsdt.compose.config import load_params, unseen_experiment

    params = load_params(args.params)
    experiment = _further_experiment(args)
    unseen_experiment(params, experiment)  # (an unknown name: one line, before the override)
    if not getattr(args, "drawn", None):
        return params
    section = f"unseen_experiments.{experiment}" if experiment else "generalisation"
    drawn = [f"{section}.drawn=" + json.dumps({"folder": args.drawn, "max_steps": drawn_max_steps(args, params)})]
    return load_params(args.params, drawn)


def drawn_max_steps(args, params) -> int:
    """``--drawn-max-steps``, or the step limit of the experiment's own drawn maps (its long detours may need more
    than the main experiment's), or :data:`DRAWN_MAX_STEPS` where it has none."""
    from hnsdt.compose.config import unseen_experiment

    if args.drawn_max_steps is not None:
        return args.drawn_max_steps
    experiment = _further_experiment(args)
    drawn = unseen_experiment(params, experiment).need("generalisation").drawn
    return drawn.max_steps if drawn is not None else DRAWN_MAX_STEPS


@contextmanager
def _step_limit_hint(args, params):
    """A map of ``--drawn`` that even the optimum cannot finish within the limit: say which option raises it."""
    from hnsdt.envs.layout import LayoutError

    try:
        yield
    except LayoutError as e:
        if not args.drawn or "(drawn)" not in str(e) or "within" not in str(e):
            raise
        raise LayoutError(f"{e} — --drawn-max-steps (now {drawn_max_steps(args, params)}) sets the limit on your "
                          "maps") from e


def _write_recording(files: dict[str, bytes], out: Path) -> Path:
    """An episode made again: its ``.rrd`` at ``out`` and its ``.mcap`` beside it."""
    from hnsdt.core.fileio import write_files

    write_files({out: files[".rrd"], out.with_suffix(".mcap"): files[".mcap"]})
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
    from hnsdt.compose.config import compute_settings, unseen_experiment

    if args.drawn and args.action != "evaluate":
        raise ValueError("--drawn is an option of generalisation evaluate (and of replay)")
    params = unseen_experiment(_params_with_drawn(args), args.experiment)  # (an unknown name: one line)
    if (args.splits or args.methods) and args.action != "evaluate":
        raise ValueError("--splits and --methods are options of generalisation evaluate")
    params.need("generalisation")  # "missing key generalisation" before any work
    if not args.out:
        raise ValueError(f"generalisation {args.action} needs --out")
    compute = compute_settings(params, args.executor, args.workers)
    if args.action == "collect":
        from hnsdt.stages.collect_unseen import collect_unseen

        collect_unseen(params, Path(args.out), progress=not args.quiet, compute=compute)
        return
    if args.action == "train":
        if not args.method or not args.curves:
            raise ValueError("generalisation train needs --method and --curves")
        from hnsdt.stages.train_unseen import train_unseen

        train_unseen(params, args.method, Path(args.dataset), Path(args.out), Path(args.curves), compute,
                     progress=not args.quiet)
        return
    from hnsdt.stages.evaluate_unseen import evaluate_unseen

    ran = Path("generalisation", *(("experiments", args.experiment) if args.experiment else ()))
    with _step_limit_hint(args, params):
        evaluate_unseen(params, Path(args.models or ran / "models"), Path(args.out), compute, progress=not args.quiet,
                        splits=args.splits, methods=args.methods)
