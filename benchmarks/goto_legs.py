"""Where an executor of GoTo sub-goals fails on maps it never saw: each GoTo leg of the planner's plan from a map's
start — its shortest path against its Manhattan distance to the target (the detour, 2 × the steps that lead away
from the target) — beside how often the executor achieved it, in a kept run of the unseen-layout experiment.

A leg counts the episodes that reached it along the planner's first plan (every sub-goal before it achieved at
the first attempt, so that the leg starts where the plan says) and how many of them then achieved it at once.
Achievement rates are grouped by detour over every map of each split, and listed per leg for the hand-drawn maps.

Run: python benchmarks/goto_legs.py DIR [--method hnsdt]
where DIR is `python benchmarks/generalisation.py --set operators=goto ... --keep DIR`'s folder: its
results/segments.csv, and its params.yaml, from which the run's layouts (hnsdt.compose.generalisation.layout_splits) and
planner mode come. The last table row gives how the GoTo legs of the run's training maps, planned from their starts,
fall into the same detour groups: what the executor was shown.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from hnsdt.compose import generalisation as gen
from hnsdt.compose.config import load_params
from hnsdt.symbolic.abstraction import SymbolicState
from hnsdt.symbolic.operators import GOTO_KINDS, MOVE, apply
from hnsdt.symbolic.planner import plan

BUCKETS = [(0, 0, "0 (straight)"), (1, 4, "2-4"), (5, 10, "6-10"), (11, 30, "12-30"), (31, 10_000, "over 30")]


def legs(layout, mode: str) -> list[dict]:
    """The planner's plan from the layout's start, as rows: every operator, and for a GoTo its geometry."""
    state, rows = SymbolicState.initial(layout), []
    for op in plan(layout, state, mode=mode, operators="goto"):
        row = {"operator": op.name, "goto": op.kind in GOTO_KINDS and op.kind != MOVE}
        if row["goto"]:
            manhattan = abs(op.target[0] - state.cell[0]) + abs(op.target[1] - state.cell[1])
            row.update(source=state.cell, target=op.target, shortest=op.cost, manhattan=manhattan,
                       detour=op.cost - manhattan)
        rows.append(row)
        state = apply(op, state)
    return rows


def bucket(detour: int) -> str:
    return next(label for lo, hi, label in BUCKETS if lo <= detour <= hi)


def first_attempts(segments: pd.DataFrame) -> pd.DataFrame:
    """Per episode, its segments up to and including the first that was not achieved, numbered from 0: the
    segments that followed the first plan from the layout's start."""
    segments = segments.sort_values(["seed", "split", "layout", "fail_prob", "episode", "start"], kind="stable")
    keys = ["seed", "split", "layout", "fail_prob", "episode"]
    failed_before = segments.groupby(keys, sort=False).achieved.transform(
        lambda a: (~a.astype(bool)).cumsum().shift(fill_value=0))
    out = segments[failed_before == 0].copy()
    out["leg"] = out.groupby(keys, sort=False).cumcount()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="a folder kept by benchmarks/generalisation.py --keep")
    ap.add_argument("--method", default="hnsdt")
    args = ap.parse_args()
    params = load_params(args.dir / "params.yaml")
    mode = params.planner.mode
    layouts = {src.name: src for src in gen.layout_splits(params)}  # (every training map too: the last row)
    segments = pd.read_csv(args.dir / "results/segments.csv")
    segments = segments[segments.method == args.method]
    if segments.empty:
        raise SystemExit(f"error: no segments of {args.method!r} in {args.dir / 'results/segments.csv'}")
    tried = first_attempts(segments)
    by_leg = dict(tuple(tried.groupby(["layout", "leg"], sort=False)))  # (layout, leg) -> its segments
    rows = []
    for name, split in tried[["layout", "split"]].drop_duplicates().itertuples(index=False):
        for leg, info in enumerate(legs(layouts[name].layout, mode)):
            mine = by_leg.get((name, leg), tried.iloc[:0])
            if len(mine) and set(mine.operator) != {info["operator"]}:
                raise SystemExit(f"error: {name} leg {leg}: the run's {sorted(set(mine.operator))} is not the "
                                 f"plan's {info['operator']}")
            rows.append(dict(info, split=split, layout=name, leg=leg, reached=len(mine),
                             achieved=int(mine.achieved.astype(bool).sum())))
    table = pd.DataFrame(rows)
    goto = table[table.goto & (table.reached > 0)].copy()
    goto[["shortest", "manhattan", "detour"]] = goto[["shortest", "manhattan", "detour"]].astype(int)
    goto["bucket"] = goto.detour.map(bucket)
    print(f"{args.method}'s GoTo legs at the first attempt, by detour (shortest path − Manhattan distance, in steps); "
          "achieved share of the episodes that reached them:")
    print("| split | " + " | ".join(b for *_, b in BUCKETS) + " |\n|---|" + "---|" * len(BUCKETS))
    for split, part in goto.groupby("split", sort=False):
        cells = []
        for *_, label in BUCKETS:
            b = part[part.bucket == label]
            cells.append(f"{b.achieved.sum() / b.reached.sum():.2f} of {b.reached.sum()} ({len(b)} legs)"
                         if b.reached.sum() else "–")
        print(f"| {split} | " + " | ".join(cells) + " |")
    training = [src.layout for src in layouts.values() if src.split == "train"]
    shown = pd.Series([bucket(leg["detour"]) for layout in training for leg in legs(layout, mode) if leg["goto"]])
    print(f"| the {len(training)} training maps (share of their {len(shown)} legs) | " + " | ".join(
        f"{(shown == label).mean():.3f}" for *_, label in BUCKETS) + " |")
    drawn = goto[goto.split == "drawn"]
    if len(drawn):
        print("\nthe hand-drawn maps' GoTo legs (first plan from the start):")
        print("| map | leg | from → to | shortest | Manhattan | detour | achieved / reached |\n|---|---|---|---|---|---|---|")
        for r in drawn.itertuples():
            print(f"| `{Path(r.layout).stem}` | {r.operator} | {r.source} → {r.target} | {r.shortest} | {r.manhattan} | "
                  f"{r.detour} | {r.achieved} / {r.reached} ({r.achieved / r.reached:.2f}) |")


if __name__ == "__main__":
    main()
