"""The online learners' knobs chosen on validation: a small sweep, the same size for each, on the paper's two maps.

Usage: python benchmarks/online_sweep.py [--methods dqn options ppo] [--envs keydoor multikeydoor]
                                         [--seeds 100 101] [--out benchmarks/results/online_sweep.csv]

For each online learner, six settings of two knobs — its learning rate (×½, ×1, ×2 of params.yaml's) and its
exploration (DQN's and option-critic's ε decay over a quarter or half of the cap; PPO's entropy bonus 0.01 or
0.05) — each trained on each map from seeds that the pipeline never reports (100, 101: the tables' seeds are
0–4) to its validated plateau or its cap, exactly as `train_online` trains (params.yaml's every other knob). The
measure is the one the plateau uses, never a test episode: greedy steps from the map's start to the exit at
fail_prob 0 (a failure counting the step limit), the best evaluation of the run, over the exact optimum's steps
(1.00 = the optimum). A setting's score is the mean of that ratio over maps and seeds; the lowest wins, fewer
env steps to the kept evaluation breaking ties, and the current setting wins a tie with others. Prints every
run and each learner's choice, and writes every run's row to ``--out``. Each setting's seeds train as one stack
(as the stage trains a learner's seeds), the stacks two at a time on the two cores.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path


def grid(params, method: str) -> list[dict]:
    """The six settings of ``method``: {knob: value} overrides of ``baselines.<method>``."""
    cfg = getattr(params.baselines, method)
    lrs = [cfg["lr"] / 2, cfg["lr"], cfg["lr"] * 2]
    explore = ({"ent_coef": [0.01, 0.05]} if method == "ppo" else {"exploration_fraction": [0.25, 0.5]})
    (knob, values), = explore.items()
    return [{"lr": lr, knob: v} for lr, v in itertools.product(lrs, values)]


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
    args = parser.parse_args()
    base = load_params("params.yaml", [])
    current = {m: {k: getattr(base.baselines, m)[k] for k in grid(base, m)[0]} for m in args.methods}
    jobs = []
    for method in args.methods:
        for setting in grid(base, method):
            overrides = [f"baselines.{method}.{k}={v!r}" for k, v in setting.items()]
            params = load_params("params.yaml", overrides)
            for env in args.envs:
                runs = plan_runs(params, env, method, args.seeds, Path("unused"))
                jobs.append(((method, env, setting), SeedStack(tuple(runs))))
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
                         "ratio": best / usage["validation_floor"], "best_step": usage["best_step"],
                         "env_steps": usage["env_steps"], "train_exits": usage["exits"]})
    table = pd.DataFrame(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out, index=False)
    print(table.to_string(index=False))
    print(f"\n{time.perf_counter() - start:.0f} s for {len(jobs)} stacks; written {args.out}")
    for method, part in table.groupby("method", sort=False):
        knobs = [k for k in ("lr", "exploration_fraction", "ent_coef") if part[k].notna().any()]
        print(f"\n{method}: mean steps over the optimum's (lower is better), mean env steps to the kept evaluation")
        choose(part, knobs, current[method], "ratio", "best_step")


def choose(runs, knobs: list[str], current: dict, score: str, tie: str, shown: tuple[str, ...] = ()):
    """One learner's setting: the lowest mean ``score`` over its runs, then the lowest mean ``tie``, the current
    setting winning a tie with others. Prints every setting's means (with ``shown``'s) and the choice."""
    columns = dict.fromkeys((score, tie, *shown))
    scores = runs.groupby(knobs).agg(**{c: (c, "mean") for c in columns}).reset_index()
    scores["current"] = [all(row[k] == current[k] for k in knobs) for _, row in scores.iterrows()]
    scores = scores.sort_values([score, tie, "current"], ascending=[True, True, False])
    print(scores.to_string(index=False))
    chosen = scores.iloc[0]
    print(f"chosen: {', '.join(f'{k} {chosen[k]:g}' for k in knobs)}"
          f"{' (the current setting)' if chosen['current'] else ''}")
    return chosen


if __name__ == "__main__":
    main()
