"""Does the planning module over the whole map (hnsdt.models.plan.MapPlanner) learn to plan? Trained alone on a few
generated mazes' demonstrations, or read from a trained DT (`--model`), and scored on validation mazes it never saw
(hnsdt.evaluation.planning): the share of cells from which its action is a shortest way to the exit, over all cells
and over the cells whose shortest way starts by walking away from the exit, beside the same weights with the
backups cut. `--drawn` scores the hand-drawn maps too: test maps, a diagnosis only, never for a choice.

Run: python benchmarks/plan_module.py [--family keydoor_maze] [--maps 8] [--steps 2000] [--lr 1e-2] [--batch 64]
     [--backup moves|kernel] [--goal target|learned] [--seed 0]
     [--layouts 5] [--model CHECKPOINT_DIR] [--drawn] [--per-map] [--legs] [--no-block]
Prints the training loss every 250 steps, then per split `all cells planned P (cut C); walk-away cells planned …`,
and the time.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hnsdt.core.reproducible import pin_process

pin_process()

from hnsdt.compose.generalisation import VALIDATION_SEED  # noqa: E402
from hnsdt.envs.generate import generate  # noqa: E402
from hnsdt.envs.layout import load_layout  # noqa: E402
from hnsdt.evaluation.planning import LEGS, shortest_way_shares, train_alone  # noqa: E402
from hnsdt.models.checkpoint import load_checkpoint  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="keydoor_maze")
    ap.add_argument("--maps", type=int, default=8)
    ap.add_argument("--layouts", type=int, default=5, help="validation layouts scored (the family's seeds 200000..)")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--lr", type=float, default=1e-2)
    ap.add_argument("--backup", default="moves", help="moves or kernel (hnsdt.models.plan.BACKUPS)")
    ap.add_argument("--goal", default="target", help="target or learned (hnsdt.models.plan.GOALS)")
    ap.add_argument("--seed", type=int, default=0, help="the module's initial weights and batches")
    ap.add_argument("--model", type=Path, help="score this trained DT's module (a checkpoint folder) instead")
    ap.add_argument("--drawn", action="store_true", help="also score the hand-drawn maps (a diagnosis: test maps)")
    ap.add_argument("--per-map", action="store_true", help="also print each hand-drawn map's scores")
    ap.add_argument("--legs", action="store_true",
                    help="also score the key and door legs (maps with one key and one door), not only the exit")
    ap.add_argument("--no-block", action="store_true",
                    help="score with every cell relaying values (MapPlanner.block off: a wall as dear as its cost)")
    args = ap.parse_args()
    start = time.time()
    if args.model:
        model, _ = load_checkpoint(args.model)
        module = model.view.map_plan
    else:
        module = train_alone(args.family, args.maps, args.steps, args.batch, args.lr, args.backup, args.seed,
                             log=print, goal=args.goal)
    module.eval()
    module.block = not args.no_block
    splits = {"validation mazes": [generate(args.family, s) for s in range(VALIDATION_SEED,
                                                                           VALIDATION_SEED + args.layouts)]}
    if args.drawn:
        splits["hand-drawn maps"] = [load_layout(f) for d in ("drawn", "drawn_later")
                                     for f in sorted((REPO / "layouts" / d).glob("*.txt"))]
    for name, layouts in splits.items():
        planned, cut = shortest_way_shares(module, layouts), shortest_way_shares(module, layouts, 0)
        print(f"{name}: all cells planned {planned[0]:.3f} (cut {cut[0]:.3f}); walk-away cells planned "
              f"{planned[1]:.3f} (cut {cut[1]:.3f})")
        legs = [leg for leg in LEGS if leg == "exit" or args.legs]
        if args.legs:
            one = [layout for layout in layouts if len(layout.keys) == len(layout.doors) == 1]
            print("  " + "; ".join(f"{leg} {' / '.join(f'{x:.3f}' for x in shortest_way_shares(module, one, leg=leg))}"
                                   for leg in legs) + f" ({len(one)} maps with one key and one door)")
        if args.per_map and name == "hand-drawn maps":
            for layout in layouts:
                mine = [leg for leg in legs if leg == "exit" or len(layout.keys) == len(layout.doors) == 1]
                print(f"  {Path(layout.name).stem}: " + "; ".join(
                    f"{leg} " + " / ".join(f"{x:.2f}" for x in shortest_way_shares(module, [layout], leg=leg))
                    for leg in mine))
    print(f"{time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
