"""DVC stage `collect@ENV`: exploration data for one environment as a LeRobot dataset.

Usage: python pipeline/collect.py --env ENV --out data/datasets/ENV   (`hnsdt collect --help` lists the options)
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["collect", *sys.argv[1:]]))
