"""DVC stage `evaluate`: every method x env x fail_prob x seed; metrics, per-episode table, recordings.

Usage: python pipeline/evaluate.py --models models --datasets data/datasets --out results --recordings recordings
       --metrics metrics   (`hnsdt evaluate --help` lists the other options)
Writes the tables to OUT, the .rrd / .mcap episodes to RECORDINGS, and copies OUT's summary.csv and
metrics.json to METRICS: small and kept in git, so the README's results table is generated from them and
`dvc metrics show` / `dvc plots show` work on a fresh clone.
"""

import argparse
import shutil
import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402
from hnsdt.fileio import atomic_file  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--metrics", required=True)
    parser.add_argument("--out", required=True)
    ours, rest = parser.parse_known_args()
    status = main(["evaluate", "--out", ours.out, *rest])
    if not status:
        for name in ("summary.csv", "metrics.json"):
            with atomic_file(f"{ours.metrics}/{name}") as tmp:
                shutil.copyfile(f"{ours.out}/{name}", tmp)
    sys.exit(status)
