"""DVC stages `train`, `train_offline` and `train_online`: one learned method on one env, every seed of
train.seeds in this one process.

Usage: python pipeline/train.py --env ENV --method METHOD [--dataset data/datasets/ENV] --out models/ENV/METHOD
       --curves plots/train/ENV-METHOD   (`hnsdt train --help` lists the options)
Writes OUT/seedK/{model.safetensors,config.json} and CURVES/seedK.csv.
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["train", *sys.argv[1:]]))
