"""The ``hnsdt`` command: inspect environments and plans, export PDDL, collect datasets.

Every subcommand reads its knobs from params.yaml (``--params``); bad input ends with one ``hnsdt: error:``
line and exit status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path


def ensure_deterministic_hashing() -> None:
    """Same seed, same files: lerobot orders task lists through Python sets, whose order depends on the
    per-process string hash seed. Re-run this process once with a fixed seed, before heavy imports."""
    if os.environ.get("PYTHONHASHSEED") != "0":
        os.environ["PYTHONHASHSEED"] = "0"
        os.execv(sys.executable, [sys.executable, *sys.argv])


def _resolve_env(args) -> tuple[str, object, int]:
    """--env is a params env name (keydoor), or a registered id; --layout overrides the layout."""
    from hnsdt.config import env_settings, load_params
    from hnsdt.envs import ENV_IDS, load_layout

    if args.env in ENV_IDS:
        kwargs = ENV_IDS[args.env][1]
        env_id, layout, max_steps = args.env, load_layout(kwargs["layout"]), kwargs["max_steps"]
    else:
        env = env_settings(load_params(args.params), args.env)
        env_id, layout, max_steps = env["id"], env["layout"], env["max_steps"]
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
        if len(obs) != 2 + layout.n_flags:
            raise ValueError(f"--state needs {2 + layout.n_flags} comma-separated integers "
                             f"({', '.join(layout.state_names)})")
        start = SymbolicState.from_observation(layout, obs)
    else:
        start = SymbolicState.initial(layout)
    ops = plan(layout, start, args.mode)
    print(f"{env_id} on layout {layout.name}, planner mode {args.mode}, from {sorted(start.predicates(layout))}")
    print(layout.text)
    print(f"{'#':>2}  {'operator':<16} {'sub-goal id':>11}  {'target':>7}  {'cost':>4}")
    for i, op in enumerate(ops, 1):
        g = psi(op)
        print(f"{i:>2}  {op.name:<16} {g.id:>11}  {str(g.target):>7}  {op.cost:>4}")
    print(f"{len(ops)} operators, cost {plan_cost(ops)} steps without move failures")


def cmd_pddl(args) -> None:
    from hnsdt.symbolic.pddl import write_pddl

    _, layout, _ = _resolve_env(args)
    domain, problem = write_pddl(layout, args.out)
    print(f"wrote {domain} and {problem}")


def cmd_collect(args) -> None:
    from hnsdt.config import collect_config, load_params
    from hnsdt.data.collect import collect_dataset

    cfg = collect_config(load_params(args.params), args.env)
    out = Path(args.out or f"data/datasets/{args.env}")
    root = collect_dataset(cfg, out, args.repo_id or f"local/{args.env}", progress=not args.quiet)
    print(f"wrote LeRobot dataset {root} (card: {root / 'README.md'})")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hnsdt", description="Hierarchical Neuro-Symbolic Decision Transformer: environments, symbolic "
        "planner, datasets. The full pipeline runs with `dvc repro`; these commands run its parts.")
    parser.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("envs", help="list registered environments and built-in layouts")
    p.set_defaults(func=cmd_envs)

    p = sub.add_parser("plan", help="print the symbolic plan and its sub-goals for an environment")
    p.add_argument("--env", required=True, help="env name from params.yaml (keydoor) or a gymnasium id")
    p.add_argument("--layout", help="override the layout: built-in name, file path or grid text")
    p.add_argument("--mode", choices=["bfs", "cost"], default="bfs",
                   help="bfs: fewest operators (the paper's planner); cost: fewest steps (default: bfs)")
    p.add_argument("--state", help="plan from this observation, e.g. 4,0,1,0 (row,col,flags...)")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("pddl", help="export the environment's domain and problem as PDDL")
    p.add_argument("--env", required=True, help="env name from params.yaml or a gymnasium id")
    p.add_argument("--layout", help="override the layout")
    p.add_argument("--out", required=True, help="output folder for domain.pddl and problem.pddl")
    p.set_defaults(func=cmd_pddl)

    p = sub.add_parser("collect", help="collect exploration data into a LeRobot dataset (the `collect` stage)")
    p.add_argument("--env", required=True, help="env name from params.yaml (e.g. keydoor)")
    p.add_argument("--out", help="dataset folder (default: data/datasets/ENV)")
    p.add_argument("--repo-id", help="LeRobot repo id recorded in the dataset (default: local/ENV)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_collect)
    return parser


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        ensure_deterministic_hashing()
    args = build_parser().parse_args(argv)
    from hnsdt.config import ParamsError
    from hnsdt.envs import LayoutError

    try:
        args.func(args)
    except (ParamsError, LayoutError, ValueError, RuntimeError, OSError) as e:
        print(f"hnsdt: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
