"""Where does the offline learners' evaluation stop improving? Success and steps per budget in epochs.

Usage: python benchmarks/offline_budget.py [--env multikeydoor] [--epochs 1 2 4] [--seeds 0 1] [--episodes 100]
                                           [--methods pure_dt hnsdt lstm_hier gru hnsdt_paper pure_dt_paper]
                                           [--fail-probs 0.1 0.3] [--params params.yaml] [--validated]
                                           [--set train.formulation.hnsdt_paper=episode ...] [--decompose]
                                           [--loss-plateau SHARE PATIENCE]
Trains each method on the pipeline's dataset (data/datasets/ENV; run `dvc repro` first) with the knobs of
params.yaml but the budget: ``--epochs`` passes over its training data, no step cap. A decision transformer
trains once for max(--epochs) and is copied after each listed epoch (the model after e epochs of a longer run
is the model of an e-epoch run: no schedule depends on the total); a recurrent one trains once per budget.
With ``--validated`` each decision transformer trains instead to the plateau of the params' validation measure
and the epoch it kept is printed; with ``--loss-plateau SHARE PATIENCE`` each recurrent one (the LSTM, the GRU)
trains on all but SHARE of each behaviour's episodes to the plateau of those held-out episodes' loss, the rule
the transformers stop on (the params' epochs the cap), and the epoch it kept is printed. ``--set`` overrides a
params key (dotted, the value read as YAML) as ``dvc exp run -S`` would. ``--decompose`` also prints, per kind
of sub-goal, where a plan-following method's steps go: steps per episode against the minimum for the sub-goals
set, first actions right, sub-goals reached (as the report's decomposition table). Every model is evaluated on
the pipeline's cells at fail_prob 0.1 and 0.3 (--episodes each). Prints success and mean steps on success per
budget, with gradient steps, the loss and, for plan-following methods, the share of sub-goals reached within
their allowance. Runs go in parallel on the local executor, one thread each, as in the pipeline.
"""

from __future__ import annotations

import argparse
import copy
import time

from hnsdt.core.reproducible import pin_process

pin_process()

import numpy as np  # noqa: E402


def run(task):
    method, env, seed, epochs, keep, params_path, overrides, episodes, fail_probs, validated, loss_plateau = task
    from dataclasses import replace
    from pathlib import Path

    from hnsdt.compose.config import env_spec, load_params, method_executor
    from hnsdt.evaluation.paper import Cell, run_cell, segment_rows
    from hnsdt.evaluation.segments import layout_navigator
    from hnsdt.evaluation.runs import build_agent
    from hnsdt.core.methods import DT_METHODS
    from hnsdt.models.train import train_dt
    from hnsdt.compose.training import plan_runs

    params = load_params(params_path, overrides)
    (task,) = plan_runs(params, env, method, [seed], Path(f"data/datasets/{env}"))
    model_cfg, cfg, frames, facts = task.model_cfg, task.train_cfg, task.frames(), task.facts
    snaps = {}
    if validated:  # the params' own budget: stopped by its validation measure (train.validation > 0)
        from hnsdt.models.train import train_decision_transformer

        model, curve, usage = train_decision_transformer(frames, model_cfg, cfg, progress=False, measure=task.measure)
        snaps[usage.get("best_epoch", cfg.epochs)] = (usage["gradient_steps"], model)
    elif method in DT_METHODS:
        model, curve = train_dt(frames, model_cfg, replace(cfg, epochs=max(epochs), max_steps=0), progress=False,
                                on_epoch=lambda e, step, m: snaps.__setitem__(e, (step, copy.deepcopy(m)))
                                if e in keep else None)
    elif loss_plateau:  # a recurrent learner to the plateau of its held-out episodes' loss (the transformers' rule)
        from hnsdt.baselines.recurrent import train_recurrent

        share, patience = loss_plateau
        model, _, usage = train_recurrent(frames, model_cfg, replace(cfg, validation=share, patience=patience,
                                                                     max_steps=0), progress=False)
        snaps[usage["best_epoch"]] = (usage["gradient_steps"], model)
    else:
        from hnsdt.baselines.recurrent import train_recurrent

        for e in sorted(keep):
            model, _, usage = train_recurrent(frames, model_cfg, replace(cfg, epochs=e, max_steps=0, validation=0.0,
                                                                     patience=0), progress=False)
            snaps[e] = (usage["gradient_steps"], model)
    E, ex = env_spec(params, env), method_executor(params, method)
    rows = []
    for e, (step, m) in sorted(snaps.items()):
        m.eval()
        loss = [r["loss"] for r in curve if r["step"] <= step][-1] if method in DT_METHODS else float("nan")
        for fi, fp in enumerate(params.evaluate.fail_probs):
            if fp not in fail_probs:
                continue
            agent = build_agent(method, E.layout, ex, m, facts)
            eps = run_cell(Cell(method, env, fp, seed), fi, E.layout, E.max_steps, episodes, agent)
            ok = [x.length for x in eps if x.success]
            segments = [s.achieved for x in eps for s in x.segments]
            row = {"method": method, "seed": seed, "epochs": e, "steps": step, "loss": loss, "fail_prob": fp,
                   "success": len(ok) / len(eps), "mean_steps": float(np.mean(ok)) if ok else float("nan"),
                   "subgoals_reached": float(np.mean(segments)) if segments else float("nan"),
                   "episode_steps": float(np.mean([x.length for x in eps]))}
            seg = segment_rows(Cell(method, env, fp, seed), eps, layout_navigator(E.layout))
            rows.append(row | {"segments": [r | {"epochs": e, "n_episodes": len(eps)} for r in seg]})
    return rows


def main() -> None:
    import pandas as pd

    from hnsdt.core.compute import Compute, run_tasks

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="multikeydoor")
    ap.add_argument("--epochs", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--methods", nargs="+", default=["pure_dt", "hnsdt"])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--fail-probs", type=float, nargs="+", default=[0.1, 0.3])
    ap.add_argument("--params", default="params.yaml")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a params key (dotted; the value read as YAML), e.g. train.epochs=5")
    ap.add_argument("--decompose", action="store_true",
                    help="also print where each plan-following method's steps go, per kind of sub-goal")
    ap.add_argument("--validated", action="store_true",
                    help="decision transformers: train to the plateau of the params' validation measure "
                         "(train.validation > 0; --epochs ignored) and report the epoch it kept")
    ap.add_argument("--loss-plateau", type=float, nargs=2, metavar=("SHARE", "PATIENCE"),
                    help="recurrent learners: hold out SHARE of each behaviour's episodes and train to the plateau "
                         "of their loss (PATIENCE epochs; the params' epochs the cap); report the epoch kept")
    args = ap.parse_args()
    t = time.perf_counter()
    plateau = (args.loss_plateau[0], int(args.loss_plateau[1])) if args.loss_plateau else None
    tasks = [(m, args.env, s, args.epochs, set(args.epochs), args.params, tuple(args.set), args.episodes,
              args.fail_probs, args.validated, plateau)
             for m in args.methods for s in args.seeds]
    rows = [r for part in run_tasks(run, tasks, Compute(), desc="budgets") for r in part]
    segments = pd.DataFrame([seg for r in rows for seg in r.pop("segments")])
    table = pd.DataFrame(rows)
    if args.validated or plateau:  # (each seed's epoch kept, and its success at each fail_prob)
        print(table.pivot_table(index=["method", "seed", "epochs", "steps"], columns="fail_prob",
                                values="success").to_string(float_format=lambda v: f"{v:.3f}"))
        table["epochs"] = "validated"
    out = table.groupby(["method", "epochs", "fail_prob"]).agg(
        gradient_steps=("steps", "first"), loss=("loss", "mean"), success=("success", "mean"),
        success_min=("success", "min"), mean_steps=("mean_steps", "mean"),
        subgoals_reached=("subgoals_reached", "mean")).reset_index()
    print(f"\n{args.env}, seeds {args.seeds}, {args.episodes} episodes per cell ({time.perf_counter() - t:.0f} s)")
    print(out.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    if args.decompose and not segments.empty:
        if args.validated or plateau:
            segments["epochs"] = "validated"
        from hnsdt.report.paper_arm import step_decomposition

        by = ["method", "epochs", "fail_prob"]
        episodes = segments.groupby([*by, "seed"]).n_episodes.first().groupby(by).sum()
        d = step_decomposition(segments, by).reset_index()
        n = d.set_index(by).index.map(episodes)
        d = d.assign(right=d.right / d.steps, segments=d.n / n, steps=d.steps / n, minimum=d.optimal / n).rename(
            columns={"first": "first_right"})[[*by, "kind", "segments", "steps", "minimum", "first_right", "right",
                                                "reached"]]
        print("\nwhere the steps go (per episode; minimum: 1 / (1 - fail_prob) per Move, 1 per pick / open):")
        print(d.to_string(index=False, float_format=lambda v: f"{v:.3f}"))


if __name__ == "__main__":
    main()
