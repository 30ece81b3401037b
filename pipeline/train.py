"""DVC stages `train`, `train_offline` and `train_online`: one learned method on one env, every seed of
train.seeds in this one process (hnsdt.stages.train).

Usage: python pipeline/train.py --env ENV --method METHOD [--dataset data/datasets/ENV] --out models/ENV/METHOD
       --curves plots/train/ENV-METHOD
Writes OUT/seedK/{model.safetensors,config.json} and CURVES/seedK.csv.
"""

import argparse
import runpy
import sys
from pathlib import Path

# same bytes on any machine (hash seed, CPU kernels, threads): re-run pinned before NumPy loads (as hnsdt would)
runpy.run_path(str(Path(__file__).resolve().parents[1] / "hnsdt/core/reproducible.py"))["pin_process"]()

from hnsdt.stages.common import run  # noqa: E402
from hnsdt.stages.train import train  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True)
    parser.add_argument("--method", required=True)
    parser.add_argument("--dataset", type=Path, help="offline methods: the dataset (default: data/datasets/ENV)")
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--curves", required=True, type=Path)
    args = parser.parse_args()
    dataset = args.dataset or Path("data/datasets") / args.env
    sys.exit(run(train, env=args.env, method=args.method, dataset=dataset, out=args.out,
                        curves=args.curves))
