"""DVC stage `collect@ENV`: exploration data for one environment as a LeRobot dataset.

Usage: python pipeline/collect.py ENV   (ENV is a key of `envs` in params.yaml)
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python pipeline/collect.py ENV")
    env = sys.argv[1]
    sys.exit(main(["collect", "--env", env, "--out", f"data/datasets/{env}", "--repo-id", f"local/{env}"]))
