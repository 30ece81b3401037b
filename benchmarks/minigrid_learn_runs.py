"""What one run of each MiniGrid learner costs, as `minigrid_learn` runs it: its training and its test play timed apart.

Usage: python benchmarks/minigrid_learn_runs.py [--world doorkey8] [--methods hnsdt ppo] [--seed 0] [--stage OUT]
Plans the stage's runs (params.yaml's `minigrid.learn`, the stage's dataset `minigrid/<world>/dataset`: run
`dvc repro minigrid_collect@<world>` first) and, for each chosen method's run of training seed ``--seed``, prints
the seconds of training (to its plateau or cap, with the validation measurements) and of playing every test world
and fail_prob, on one pinned thread (`compute.threads`), nothing else in this process. Run two at once only on
different cores. With ``--stage OUT``: runs the whole stage for the chosen methods instead (every seed of
`minigrid.learn.seeds`, on the stage's workers) into OUT, and prints its summary.csv and the stage's seconds — the
way to measure a learner kept out of the default run. ``--record FILE`` (with ``--stage``) then adds the chosen
methods' rows to FILE (benchmarks/results/minigrid_learners.csv, which the report sets beside the default run's
learners: hnsdt.evaluation.minigrid_learners); where OUT already holds a finished stage of these methods it is
recorded as it is, not run again (``--seconds``: the seconds it took then).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def main() -> None:
    from hnsdt.core.reproducible import pin_process

    pin_process()  # (re-runs this script under the pinned variables, before torch is imported)
    import torch

    from hnsdt.agents.minigrid_play import play
    from hnsdt.compose import minigrid as compose
    from hnsdt.compose.config import load_params

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="doorkey8")
    parser.add_argument("--methods", nargs="+", default=None, help="default: minigrid.learn.methods; any MiniGrid learner")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--stage", type=Path, help="run the whole stage for these methods into this folder")
    parser.add_argument("--record", type=Path, help="with --stage: add its rows to this file")
    parser.add_argument("--seconds", type=float, help="with --record of a stage already run: its seconds then")
    args = parser.parse_args()
    if (args.record or args.seconds) and not args.stage:
        parser.error("--record and --seconds go with --stage")
    # (any MiniGrid learner, in minigrid.learn.methods or not)
    params = load_params("params.yaml", [f"minigrid.learn.methods={args.methods}"] if args.methods else [])
    if args.stage:
        from hnsdt.stages.minigrid_learn import minigrid_learn

        methods = params.minigrid.learn.methods
        seconds = args.seconds
        if not (args.record and _finished(args.stage, methods)):
            start = time.perf_counter()
            minigrid_learn(params, args.world, Path(f"minigrid/{args.world}/dataset"), args.stage)
            seconds = time.perf_counter() - start
            print((args.stage / "summary.csv").read_text())
            print(f"{seconds:.0f} s for the stage")
        if args.record:
            _record(args, params, methods, seconds)
        return
    torch.set_num_threads(1)
    runs = [r for r in compose.learn_runs(params, args.world, f"minigrid/{args.world}/dataset")
            if r.seed == args.seed]
    if not runs:
        raise SystemExit(f"no run of seed {args.seed} for {args.methods} in minigrid.learn")
    print(f"{'method':<10} {'train s':>8} {'play s':>7} {'episodes':>8}  used")
    for run in runs:
        start = time.perf_counter()
        trained = compose.train(run)
        middle = time.perf_counter()
        episodes = play(trained[0], run.env_id, list(run.test), run.target_return)
        end = time.perf_counter()
        print(f"{run.method:<10} {middle - start:8.1f} {end - middle:7.1f} {len(episodes):8d}  {trained[3]}",
              flush=True)


def _finished(out: Path, methods: list[str]) -> bool:
    """Whether ``out`` holds a finished stage with rows of every one of ``methods``."""
    from hnsdt.evaluation.minigrid import read_csv

    summary = out / "summary.csv"
    return summary.is_file() and set(methods) <= {r["method"] for r in read_csv(summary.read_text())}


def _record(args, params, methods: list[str], seconds: float | None) -> None:
    import math
    import shlex
    import sys

    from hnsdt.core.provenance import cpu_name
    from hnsdt.evaluation import minigrid_learners

    rows = minigrid_learners.stage_rows(args.stage, methods, params.minigrid.learn.validation_max_steps,
                                        command=shlex.join(["python", *sys.argv]), cpu=cpu_name(),
                                        seconds=round(seconds) if seconds is not None else math.nan)
    minigrid_learners.record(args.record, rows)
    print(f"recorded {', '.join(methods)} on {args.world} in {args.record}")


if __name__ == "__main__":
    main()
