"""The online learners' knobs chosen on validation: a small sweep, the same size for each, on the paper's two maps.

Usage: python benchmarks/online_sweep.py [--methods dqn options ppo] [--envs keydoor multikeydoor]
                                         [--seeds 100 101] [--out benchmarks/results/online_sweep.csv]
       python benchmarks/online_sweep.py --table benchmarks/results/online_sweep.csv [MORE.csv ...]

For each online learner, six settings of two knobs — its learning rate (×½, ×1, ×2 of params.yaml's) and its
exploration (DQN's and option-critic's ε decay over a quarter or half of the cap; PPO's entropy bonus 0.01 or
0.05) — each trained on each map from seeds that the pipeline never reports (100, 101: the tables' seeds are
0–4) to its validated plateau or its cap, exactly as `train_online` trains (params.yaml's every other knob). The
measure is the one the plateau uses, never a test episode: greedy steps from the map's start to the exit at
fail_prob 0 (a failure counting the step limit), the best evaluation of the run, over the exact optimum's steps
(1.00 = the optimum). A setting's score is the mean of that ratio over maps and seeds; the lowest wins, fewer
env steps to the kept evaluation breaking ties, and the current setting wins a tie with others. Prints every
run and each learner's choice, and writes every run's row to ``--out`` (its ``current`` column: the setting the
grid was made around). Each setting's seeds train as one stack (as the stage trains a learner's seeds), the
stacks two at a time on the two cores. ``--table`` prints the choices of runs written before, from one table or
several (more seeds of the same grid), without training.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path


def explore_knob(method: str) -> str:
    """The exploration knob an online learner's sweep varies: PPO's entropy bonus, the others' ε decay."""
    return "ent_coef" if method == "ppo" else "exploration_fraction"


def grid_around(lr: float, method: str) -> list[dict]:
    """The six settings of an online learner whose learning rate is ``lr``: {knob: value} overrides."""
    values = [0.01, 0.05] if method == "ppo" else [0.25, 0.5]
    return [{"lr": r, explore_knob(method): v} for r, v in itertools.product([lr / 2, lr, lr * 2], values)]


def grid(params, method: str) -> list[dict]:
    """The six settings of ``method`` on the paper's maps: overrides of ``baselines.<method>``."""
    return grid_around(getattr(params.baselines, method)["lr"], method)


def main() -> None:
    from hnsdt.core.reproducible import pin_process

    pin_process()  # (re-runs this script under the pinned variables, before torch is imported)
    import pandas as pd

    from hnsdt.compose.config import compute_settings, load_params
    from hnsdt.compose.training import SeedStack, plan_runs, train_run
    from hnsdt.core.compute import run_tasks

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["dqn", "options", "ppo"])
    parser.add_argument("--envs", nargs="+", default=["keydoor", "multikeydoor"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[100, 101])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/online_sweep.csv"))
    parser.add_argument("--table", type=Path, nargs="+", help="print the choices of the runs in these CSVs")
    args = parser.parse_args()
    if args.table:
        return report(pd.concat([pd.read_csv(t, float_precision="round_trip") for t in args.table]))
    base = load_params("params.yaml", [])
    jobs = []
    for method in args.methods:
        now = {k: getattr(base.baselines, method)[k] for k in grid(base, method)[0]}
        for setting in grid(base, method):
            overrides = [f"baselines.{method}.{k}={v!r}" for k, v in setting.items()]
            params = load_params("params.yaml", overrides)
            for env in args.envs:
                runs = plan_runs(params, env, method, args.seeds, Path("unused"))
                jobs.append(((method, env, {**setting, "current": setting == now}), SeedStack(tuple(runs))))
    print(f"{len(jobs)} stacks of {len(args.seeds)} seeds", flush=True)
    start = time.perf_counter()
    results = run_tasks(train_run, [task for _, task in jobs], compute_settings(base), desc="sweep")
    rows = []
    for ((method, env, setting), _), stack in zip(jobs, results):
        for seed, (_, facts, _) in zip(args.seeds, stack):
            usage = facts["usage"]
            best = min(h["value"] for h in usage["validation_steps"])
            rows.append({"method": method, "env": env, "seed": seed, **{k: setting.get(k) for k in
                         ("lr", "exploration_fraction", "ent_coef")},
                         "best_steps": best, "floor": usage["validation_floor"],
                         "ratio": best / usage["validation_floor"], **online_usage(usage),
                         "current": setting["current"]})
    report(write(rows, args.out, f"{time.perf_counter() - start:.0f} s for {len(jobs)} stacks"))


def online_usage(usage: dict) -> dict:
    """An online run's row fields from its checkpoint's usage: the env step of the kept evaluation, the env steps
    trained, the training episodes that reached the exit."""
    return {"best_step": usage["best_step"], "env_steps": usage["env_steps"], "train_exits": usage["exits"]}


def write(rows: list[dict], out: Path, took: str):
    """A sweep's runs as a table, written to ``out`` and printed (with ``took``); the table."""
    import pandas as pd

    table = pd.DataFrame(rows)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False)
    print(table.to_string(index=False))
    print(f"\n{took}; written {out}")
    return table


def report(table) -> None:
    """Each learner's choice over both maps: mean steps over the optimum's, then env steps to the kept evaluation."""
    for method, part in table.groupby("method", sort=False):
        print(f"\n{method}: mean steps over the optimum's (lower is better), mean env steps to the kept evaluation")
        choose(part, ["lr", explore_knob(method)], "ratio", "best_step")


def choose(runs, knobs: list[str], score: str, tie: str, shown: tuple[str, ...] = ()):
    """One learner's setting: the lowest mean ``score`` over its runs, then the lowest mean ``tie``, the current
    setting (the runs' ``current`` column: the one the grid was made around) winning a tie with others. Prints
    every setting's means (with ``shown``'s) and the choice."""
    columns = dict.fromkeys((score, tie, *shown))
    scores = runs.groupby(knobs).agg(**{c: (c, "mean") for c in columns}, current=("current", "any")).reset_index()
    scores = scores.sort_values([score, tie, "current"], ascending=[True, True, False])
    print(scores.to_string(index=False))
    chosen = scores.iloc[0]
    print(f"chosen: {', '.join(f'{k} {chosen[k]:g}' for k in knobs)}"
          f"{' (the current setting)' if chosen['current'] else ''}")
    return chosen


if __name__ == "__main__":
    main()
