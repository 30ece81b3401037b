"""DVC stage `report`: figures and report.md traced to the git revision, params and input md5s.

Usage: python pipeline/report.py --results results --out report   (`hnsdt report --help`)
"""

import sys

from hnsdt.reproducible import pin_process

pin_process()  # same bytes on any machine: hash seed, CPU kernels, threads

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["report", *sys.argv[1:]]))
