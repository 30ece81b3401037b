"""Every unseen-layout learner's knobs on validation: the sweep of the paper maps' online learners (online_sweep.py),
the same size, for the learners of the unseen-layout experiment — those that train on its dataset (the LSTM, the
GRU, the pure DT) and those that act in its training layouts (DQN, option-critic, PPO).

Usage: python benchmarks/unseen_sweep.py [--methods lstm_hier gru pure_dt] [--seeds 100 101]
                                         [--dataset generalisation/dataset]
                                         [--out benchmarks/results/offline_sweep.csv]
       python benchmarks/unseen_sweep.py --methods dqn options ppo --out benchmarks/results/unseen_online_sweep.csv
       python benchmarks/unseen_sweep.py --table benchmarks/results/offline_sweep.csv [MORE.csv ...]

For each learner, six settings of two knobs — its learning rate (×½, ×1, ×2 of its current value) and, offline,
its batch size (×1, ×2) or, online, its exploration (as on the paper's maps: DQN's and option-critic's ε decay over
a quarter or half of the cap, PPO's entropy bonus 0.01 or 0.05) — each trained from seeds the pipeline never
reports (100, 101: the tables' seeds are 0–4) exactly as `train_generalisation(_baselines)` trains it (params.yaml's
every other knob; the offline learners on the default run's dataset: `dvc repro collect_generalisation` first),
but that the LSTM and the GRU measure after every epoch what the decision transformers and the online learners
stop on: the greedy steps to the exit from the validation layouts' starts at fail_prob 0 (a failure counting the
step limit). Their patience is as long as their epochs, so they train every epoch, as the default does. Never a
test map: a run's score is the measure of the model the default would keep, over the validation layouts' optimum
(1.00 = the optimum) — the last epoch's for the LSTM and the GRU (they train a fixed number of epochs), the
plateau's best for the others — the mean over seeds; the lowest wins, fewer epochs (env steps, online) to the
run's best breaking ties, and the current setting wins a tie with others. Writes every run's row to ``--out``
and prints each learner's choice; ``--table CSV [CSV ...]`` prints the choices of runs written before (more
seeds of the same grid, in the same table or another, count too), without training. Runs go two at a time on
the two cores.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

from online_sweep import choose, explore_knob, grid_around, online_usage, write  # (benchmarks/, this script's folder)


def train_config(params, method: str):
    """``method``'s training config in the unseen-layout experiment (its budget over its own knobs)."""
    from hnsdt.compose.training import layout_network_configs
    from hnsdt.compose import generalisation as gen

    return layout_network_configs(params, method, 0, gen.training_layouts(params)[0].layout)[1]


def online(method: str) -> bool:
    """Whether ``method`` learns by acting (DQN, option-critic, PPO) rather than from the dataset."""
    from hnsdt.core.methods import method as lookup_method

    return lookup_method(method).training == "online"


def knobs(method: str) -> tuple[str, str]:
    """The two knobs swept: the learning rate and the batch size (offline) or the exploration (online)."""
    return ("lr", explore_knob(method)) if online(method) else ("lr", "batch_size")


def grid(now: dict, method: str) -> list[dict]:
    """The six settings: the learning rate halved, kept, doubled; the batch size kept, doubled (offline) or the
    exploration's two values (online)."""
    if online(method):
        return grid_around(now["lr"], method)
    return [{"lr": lr, "batch_size": b} for lr, b in
            itertools.product([now["lr"] / 2, now["lr"], now["lr"] * 2], [now["batch_size"], now["batch_size"] * 2])]


def main() -> None:
    from hnsdt.core.reproducible import pin_process

    pin_process()  # (re-runs this script under the pinned variables, before torch is imported)
    import pandas as pd

    from hnsdt.compose.config import compute_settings, load_params
    from hnsdt.compose.training import train_run
    from hnsdt.core.compute import run_tasks
    from hnsdt.stages.train_unseen import plan_unseen

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=["lstm_hier", "gru", "pure_dt"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[100, 101])
    parser.add_argument("--dataset", type=Path, default=Path("generalisation/dataset"))
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/offline_sweep.csv"))
    parser.add_argument("--table", type=Path, nargs="+", help="print the choices of the runs in these CSVs")
    args = parser.parse_args()
    if args.table:
        return report(pd.concat([pd.read_csv(t, float_precision="round_trip") for t in args.table]))
    base = load_params("params.yaml", [])
    g = base.need("generalisation")
    jobs = []
    for method in args.methods:
        cfg, budget = train_config(base, method), dict(g.budgets.get(method, {}))
        if method in base.baselines.offline:  # (an RNN: measure every epoch, never stop early)
            budget["patience"] = cfg.epochs
        now = {k: getattr(cfg, k) for k in knobs(method)}
        for setting in grid(now, method):
            budgets = {**g.budgets, method: {**budget, **setting}}
            params = load_params("params.yaml", [f"generalisation.budgets={budgets!r}",
                                                 f"generalisation.method_seeds.{method}={args.seeds!r}"])
            for task in plan_unseen(params, method, args.dataset):
                jobs.append(((method, {**setting, "current": setting == now}, task.seed), task))
    print(f"{len(jobs)} runs", flush=True)
    start = time.perf_counter()
    results = run_tasks(train_run, [task for _, task in jobs], compute_settings(base), desc="sweep")
    rows = []
    for ((method, setting, seed), _), (_, facts, _) in zip(jobs, results):
        usage = facts["usage"]
        history = usage["validation_steps"]
        floor = usage.get("validation_floor", float("nan"))
        best = min(h["value"] for h in history)
        trained = (online_usage(usage) if online(method)
                   else {"best_epoch": usage["best_epoch"], "epochs": len(history)})
        rows.append({"method": method, "seed": seed, **setting, "best_steps": best, "last_steps": history[-1]["value"],
                     "floor": floor, "ratio": best / floor, "last_ratio": history[-1]["value"] / floor, **trained})
    report(write(rows, args.out, f"{time.perf_counter() - start:.0f} s for {len(jobs)} runs"))


def report(table) -> None:
    """Each learner's choice: by the last epoch's measure for a fixed-epoch learner, the best's for the others;
    the setting the grid was made around (the ``current`` column) wins a tie."""
    from hnsdt.core.methods import method as lookup_method

    for method, part in table.groupby("method", sort=False):
        fixed = lookup_method(method).stage == "train_offline"  # (the LSTM, the GRU: the default keeps the last epoch)
        score, tie = ("last_ratio" if fixed else "ratio"), ("best_step" if online(method) else "best_epoch")
        print(f"\n{method}: steps over the optimum's of the {'last' if fixed else 'best'} "
              f"{'evaluation' if online(method) else 'epoch'} ({score}; lower is better), the "
              f"{'env step' if online(method) else 'epoch'} of the run's best")
        choose(part, list(knobs(method)), score, tie, ("ratio", "last_ratio"))


if __name__ == "__main__":
    main()
