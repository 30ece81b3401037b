"""DVC stage `report`: figures and report.md traced to the git revision, params and input md5s.

Usage: python pipeline/report.py   (writes report/)
"""

import sys

from hnsdt.cli import ensure_deterministic_hashing

ensure_deterministic_hashing()

from hnsdt.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["report", "--results", "results", "--out", "report"]))
