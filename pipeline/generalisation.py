"""DVC stages `collect_generalisation`, `train_generalisation` and `evaluate_generalisation`: the unseen-layout
experiment (hnsdt.generalisation).

Usage: python pipeline/generalisation.py collect --out generalisation/dataset
       python pipeline/generalisation.py train --method METHOD --dataset generalisation/dataset
           --out generalisation/models/METHOD --curves plots/train/generalisation-METHOD
       python pipeline/generalisation.py evaluate --models generalisation/models --out generalisation/results
(`hnsdt generalisation --help` lists the options.)
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["generalisation", *sys.argv[1:]]))
