"""DVC stages `train`, `train_offline` and `train_online`: one learned method on one env, every seed of
train.seeds in this one process.

Usage: python pipeline/train.py ENV METHOD
Writes models/ENV/METHOD/seedK/{model.safetensors,config.json} and plots/train/ENV-METHOD/seedK.csv.
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python pipeline/train.py ENV METHOD")
    env, method = sys.argv[1:]
    sys.exit(main(["train", "--env", env, "--method", method, "--out", f"models/{env}/{method}",
                   "--curves", f"plots/train/{env}-{method}"]))
