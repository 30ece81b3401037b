"""DVC stage `collect@ENV`: exploration data for one environment as a LeRobot dataset.

Usage: python pipeline/collect.py ENV   (ENV is a key of `envs` in params.yaml)
"""

import sys

from hnsdt.cli import ensure_deterministic_hashing

ensure_deterministic_hashing()

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python pipeline/collect.py ENV")
    env = sys.argv[1]
    sys.exit(main(["collect", "--env", env, "--out", f"data/datasets/{env}", "--repo-id", f"local/{env}"]))
