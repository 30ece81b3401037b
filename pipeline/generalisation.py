"""DVC stages `collect_generalisation`, `train_generalisation`, `evaluate_generalisation` and
`unseen_experiment@NAME`: the unseen-layout experiments (hnsdt.compose.generalisation, through hnsdt.stages).

Usage: python pipeline/generalisation.py collect --out generalisation/dataset
       python pipeline/generalisation.py train --method METHOD --dataset generalisation/dataset
           --out generalisation/models/METHOD --curves plots/train/generalisation-METHOD
       python pipeline/generalisation.py evaluate --models generalisation/models --out generalisation/results
       python pipeline/generalisation.py all --experiment NAME --out generalisation/experiments/NAME
(--experiment NAME, on any action: the params as `unseen_experiments.NAME` changes them.)
"""

import argparse
import runpy
import sys
from pathlib import Path

# same bytes on any machine (hash seed, CPU kernels, threads): re-run pinned before NumPy loads (as hnsdt would)
runpy.run_path(str(Path(__file__).resolve().parents[1] / "hnsdt/core/reproducible.py"))["pin_process"]()

from hnsdt.stages.common import run  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    sub.add_parser("collect").add_argument("--out", required=True, type=Path)
    p = sub.add_parser("train")
    p.add_argument("--method", required=True)
    for name in ("--dataset", "--out", "--curves"):
        p.add_argument(name, required=True, type=Path)
    p = sub.add_parser("evaluate")
    for name in ("--models", "--out"):
        p.add_argument(name, required=True, type=Path)
    sub.add_parser("all").add_argument("--out", required=True, type=Path)
    for p in sub.choices.values():
        p.add_argument("--experiment", help="a name of unseen_experiments in params.yaml")
    args = vars(parser.parse_args())
    action = args.pop("action")  # (each action imports its own stage module: a stage depends on its code alone)
    if action == "collect":
        from hnsdt.stages.collect_unseen import collect_unseen as stage
    elif action == "train":
        from hnsdt.stages.train_unseen import train_unseen as stage
    elif action == "evaluate":
        from hnsdt.stages.evaluate_unseen import evaluate_unseen as stage
    else:
        from hnsdt.stages.unseen_experiment import run_unseen_experiment as stage
    sys.exit(run(stage, **args))
