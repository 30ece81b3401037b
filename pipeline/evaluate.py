"""DVC stage `evaluate`: every method x env x fail_prob x seed; metrics, per-episode table, recordings.

Usage: python pipeline/evaluate.py   (writes results/)
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["evaluate", "--models", "models", "--out", "results"]))
