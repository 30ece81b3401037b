"""DVC stage `evaluate`: every method x env x fail_prob x seed; metrics, per-episode table, recordings
(hnsdt.stages.evaluate).

Usage: python pipeline/evaluate.py --models models --datasets data/datasets --out results --recordings recordings
       --metrics metrics
Writes the tables to OUT, the .rrd / .mcap episodes to RECORDINGS, and copies OUT's summary.csv and
metrics.json to METRICS: small and kept in git, so the README's results table is generated from them and
`dvc plots show` works on a fresh clone.
"""

import argparse
import runpy
import sys
from pathlib import Path

# same bytes on any machine (hash seed, CPU kernels, threads): re-run pinned before NumPy loads (as hnsdt would)
runpy.run_path(str(Path(__file__).resolve().parents[1] / "hnsdt/core/reproducible.py"))["pin_process"]()

from hnsdt.stages.common import run  # noqa: E402
from hnsdt.stages.evaluate import evaluate  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("--models", "--datasets", "--out", "--recordings", "--metrics"):
        parser.add_argument(name, required=True, type=Path)
    args = parser.parse_args()
    sys.exit(run(evaluate, models=args.models, datasets=args.datasets, out=args.out,
                        recordings=args.recordings, metrics=args.metrics))
