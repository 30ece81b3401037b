"""DVC stage `report`: figures and report.md traced to the git revision, params and input md5s, and the headline
metrics (hnsdt.stages.report).

Usage: python pipeline/report.py --results results --generalisation generalisation/results --out report
       --headline metrics/headline --ablations benchmarks/results/generalisation.csv
       --experiments generalisation/experiments --minigrid minigrid
       --minigrid-learners benchmarks/results/minigrid_learners.csv
"""

import argparse
import runpy
import sys
from pathlib import Path

# same bytes on any machine (hash seed, CPU kernels, threads): re-run pinned before NumPy loads (as hnsdt would)
runpy.run_path(str(Path(__file__).resolve().parents[1] / "hnsdt/core/reproducible.py"))["pin_process"]()

from hnsdt.stages.common import run  # noqa: E402
from hnsdt.stages.report import report  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name in ("--results", "--generalisation", "--out", "--headline", "--ablations", "--experiments", "--minigrid",
                 "--minigrid-learners"):
        parser.add_argument(name, required=True, type=Path)
    args = parser.parse_args()
    sys.exit(run(report, results=args.results, out=args.out, generalisation=args.generalisation,
                        headline=args.headline, ablations=args.ablations, experiments=args.experiments,
                        minigrid=args.minigrid, minigrid_learners=args.minigrid_learners))
