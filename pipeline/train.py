"""DVC stage `train@ENV-METHOD`: one decision transformer per seed for a learned method on one environment.

Usage: python pipeline/train.py ENV METHOD   (METHOD: hnsdt or pure_dt)
Writes models/ENV/METHOD/seed{k}/{model.safetensors,config.json} and plots/train/ENV-METHOD.csv.
"""

import sys

from hnsdt.cli import ensure_deterministic_hashing

ensure_deterministic_hashing()

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python pipeline/train.py ENV METHOD")
    sys.exit(main(["train", "--env", sys.argv[1], "--method", sys.argv[2]]))
