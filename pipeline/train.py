"""DVC stages `train`, `train_offline` and `train_online`: one learned method on one env with one seed.

Usage: python pipeline/train.py ENV METHOD SEED
Writes models/ENV/METHOD/seedSEED/{model.safetensors,config.json} and plots/train/ENV-METHOD-seedSEED.csv.
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit("usage: python pipeline/train.py ENV METHOD SEED")
    sys.exit(main(["train", "--env", sys.argv[1], "--method", sys.argv[2], "--seed", sys.argv[3]]))
