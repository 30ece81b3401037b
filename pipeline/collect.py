"""DVC stage `collect@ENV`: exploration data for one environment as a LeRobot dataset (hnsdt.stages.collect).

Usage: python pipeline/collect.py --env ENV --out data/datasets/ENV
"""

import argparse
import runpy
import sys
from pathlib import Path

# same bytes on any machine (hash seed, CPU kernels, threads): re-run pinned before NumPy loads (as hnsdt would)
runpy.run_path(str(Path(__file__).resolve().parents[1] / "hnsdt/core/reproducible.py"))["pin_process"]()

from hnsdt.stages.common import run  # noqa: E402
from hnsdt.stages.collect import collect  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True)
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args()
    sys.exit(run(collect, env=args.env, out=args.out))
