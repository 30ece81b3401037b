"""The offline learners' knobs on validation: the online learners' sweep (online_sweep.py), the same size, for the
learners that train on the unseen-layout experiment's dataset.

Usage: python benchmarks/offline_sweep.py [--methods lstm_hier gru pure_dt] [--seeds 100 101]
                                          [--dataset generalisation/dataset]
                                          [--out benchmarks/results/offline_sweep.csv]
       python benchmarks/offline_sweep.py --table benchmarks/results/offline_sweep.csv

For each learner, six settings of two knobs — its learning rate (×½, ×1, ×2 of its current value) and its batch
size (×1, ×2) — each trained from seeds the pipeline never reports (100, 101: the tables' seeds are 0–4) on the
default run's dataset (`dvc repro collect_generalisation` first), exactly as `train_generalisation(_baselines)`
trains it (params.yaml's every other knob), but that the LSTM and the GRU measure after every epoch what the
decision transformers stop on: the greedy steps to the exit from the validation layouts' starts at fail_prob 0 (a
failure counting the step limit). Their patience is as long as their epochs, so they train every epoch, as the
default does. Never a test map: a run's score is the measure of the model the default would keep, over the
validation layouts' optimum (1.00 = the optimum) — the last epoch's for the LSTM and the GRU (they train a fixed
number of epochs), the plateau's best for the transformers — the mean over seeds; the lowest wins, fewer epochs
to the run's best breaking ties, and the current setting wins a tie with others (each run's best epoch is printed
too). Writes every run's row to ``--out`` and prints each learner's choice; ``--table CSV`` prints the choices of
runs written before (seeds appended from another run count too), without training. Runs go two at a time on the
two cores.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

from online_sweep import choose  # (benchmarks/, this script's folder)

KNOBS = ("lr", "batch_size")


def train_config(params, method: str):
    """``method``'s training config in the unseen-layout experiment (its budget over its own knobs)."""
    from hnsdt.compose.training import layout_network_configs
    from hnsdt.compose import generalisation as gen

    return layout_network_configs(params, method, 0, gen.training_layouts(params)[0].layout)[1]


def centre(runs) -> dict:
    """The setting a table's grid was made around (its middle learning rate, its smaller batch): the current one
    when the sweep ran."""
    return {"lr": sorted(runs["lr"].unique())[1], "batch_size": runs["batch_size"].min()}


def grid(now: dict) -> list[dict]:
    """The six settings: the learning rate halved, kept, doubled; the batch size kept, doubled."""
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
    parser.add_argument("--table", type=Path, help="print the choices of the runs in this CSV (written before)")
    args = parser.parse_args()
    if args.table:
        return report(pd.read_csv(args.table))
    base = load_params("params.yaml", [])
    g = base.need("generalisation")
    jobs = []
    for method in args.methods:
        cfg, budget = train_config(base, method), dict(g.budgets.get(method, {}))
        if method in base.baselines.offline:  # (an RNN: measure every epoch, never stop early)
            budget["patience"] = cfg.epochs
        for setting in grid({k: getattr(cfg, k) for k in KNOBS}):
            budgets = {**g.budgets, method: {**budget, **setting}}
            params = load_params("params.yaml", [f"generalisation.budgets={budgets!r}",
                                                 f"generalisation.method_seeds.{method}={args.seeds!r}"])
            for task in plan_unseen(params, method, args.dataset):
                jobs.append(((method, setting, task.seed), task))
    print(f"{len(jobs)} runs", flush=True)
    start = time.perf_counter()
    results = run_tasks(train_run, [task for _, task in jobs], compute_settings(base), desc="sweep")
    rows = []
    for ((method, setting, seed), _), (_, facts, _) in zip(jobs, results):
        usage = facts["usage"]
        history = usage["validation_steps"]
        floor = usage.get("validation_floor", float("nan"))
        best = min(h["value"] for h in history)
        rows.append({"method": method, "seed": seed, **setting, "best_steps": best, "last_steps": history[-1]["value"],
                     "floor": floor, "ratio": best / floor, "last_ratio": history[-1]["value"] / floor,
                     "best_epoch": usage["best_epoch"], "epochs": len(history)})
    table = pd.DataFrame(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out, index=False)
    print(table.to_string(index=False))
    print(f"\n{time.perf_counter() - start:.0f} s for {len(jobs)} runs; written {args.out}")
    report(table)


def report(table) -> None:
    """Each learner's choice: by the last epoch's measure for a fixed-epoch learner, the best's for the others;
    the setting the grid was made around (:func:`centre`) wins a tie."""
    from hnsdt.core.methods import method as lookup_method

    for method, part in table.groupby("method", sort=False):
        fixed = lookup_method(method).stage != "train"  # (the LSTM, the GRU: the default keeps the last epoch)
        score = "last_ratio" if fixed else "ratio"
        print(f"\n{method}: steps over the optimum's of the {'last' if fixed else 'best'} epoch ({score}; lower is "
              "better), the epoch of the run's best")
        choose(part, list(KNOBS), centre(part), score, "best_epoch", ("ratio", "last_ratio"))


if __name__ == "__main__":
    main()
