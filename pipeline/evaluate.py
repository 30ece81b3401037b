"""DVC stage `evaluate`: every method x env x fail_prob x seed; metrics, per-episode table, recordings.

Usage: python pipeline/evaluate.py
Reads models/ and data/datasets/; writes results/ (tables), recordings/ (.rrd, .mcap) and metrics/ (a copy of
results/summary.csv and results/metrics.json, small and kept in git: the README's results table is generated
from it, and `dvc metrics show` / `dvc plots show` work on a fresh clone).
"""

import shutil
import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402
from hnsdt.fileio import atomic_file  # noqa: E402

if __name__ == "__main__":
    status = main(["evaluate", "--models", "models", "--out", "results"])
    if not status:
        for name in ("summary.csv", "metrics.json"):
            with atomic_file(f"metrics/{name}") as tmp:
                shutil.copyfile(f"results/{name}", tmp)
    sys.exit(status)
