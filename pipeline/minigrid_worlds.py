"""DVC stages `minigrid_reference`, `minigrid_collect` and `minigrid_learn` on one of MiniGrid's own worlds: the
references (the exact optimum, the symbolic agent, the BabyAI bot), the learners' dataset, and the decision
transformers trained on it and played (hnsdt.stages.minigrid_reference, .minigrid_collect, .minigrid_learn).

Usage: python pipeline/minigrid_worlds.py reference --env NAME --out minigrid/NAME/reference
           [--recordings minigrid/NAME/recordings]
       python pipeline/minigrid_worlds.py collect --env NAME --out minigrid/NAME/dataset
       python pipeline/minigrid_worlds.py learn --env NAME --dataset minigrid/NAME/dataset --out minigrid/NAME/learned
           [--recordings minigrid/NAME/learned_recordings]
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
    parser.add_argument("step", choices=["reference", "collect", "learn"])
    parser.add_argument("--env", required=True)
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--dataset", type=Path, help="learn: the world's dataset (minigrid_collect's)")
    parser.add_argument("--recordings", type=Path, help="reference, learn: one .rrd and .mcap per played method "
                        "and fail_prob here")
    args = parser.parse_args()
    extra = {}
    if args.step == "reference":  # (each stage imports its own module only: an edit to another's reruns none)
        from hnsdt.stages.minigrid_reference import minigrid_reference as stage
        extra = {"recorded": args.recordings}
    elif args.step == "collect":
        from hnsdt.stages.minigrid_collect import minigrid_collect as stage
    else:
        from hnsdt.stages.minigrid_learn import minigrid_learn as stage
        if args.dataset is None:
            parser.error("learn needs --dataset")
        extra = {"dataset": args.dataset, "recorded": args.recordings}
    sys.exit(run(stage, env=args.env, out=args.out, **extra))
