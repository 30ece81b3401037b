"""DVC stage `evaluate`: every method x env x fail_prob x seed; metrics, per-episode table, recordings.

Usage: python pipeline/evaluate.py   (writes results/)
"""

import sys

from hnsdt.cli import ensure_deterministic_hashing

ensure_deterministic_hashing()

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["evaluate", "--models", "models", "--out", "results"]))
