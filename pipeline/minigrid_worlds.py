"""DVC stages `minigrid_reference` and `minigrid_collect` on one of MiniGrid's own worlds: the references (the exact
optimum, the symbolic agent, the BabyAI bot) and the learners' dataset (hnsdt.stages.minigrid_reference,
hnsdt.stages.minigrid_collect).

Usage: python pipeline/minigrid_worlds.py reference --env NAME --out minigrid/NAME/reference
           [--recordings minigrid/NAME/recordings]
       python pipeline/minigrid_worlds.py collect --env NAME --out minigrid/NAME/dataset
NAME is a key of params.yaml's minigrid.envs. (Not pipeline/minigrid.py: the script's folder comes first on
sys.path, and that name would hide the minigrid package.)
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
    parser.add_argument("step", choices=["reference", "collect"])
    parser.add_argument("--env", required=True)
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--recordings", type=Path, help="reference: one .rrd and .mcap per played reference and "
                        "fail_prob here")
    args = parser.parse_args()
    if args.step == "reference":  # (each stage imports its own module only: an edit to the other's reruns neither)
        from hnsdt.stages.minigrid_reference import minigrid_reference as stage
    else:
        from hnsdt.stages.minigrid_collect import minigrid_collect as stage
    extra = {"recorded": args.recordings} if args.step == "reference" else {}
    sys.exit(run(stage, env=args.env, out=args.out, **extra))
