"""``python -m hnsdt.cli``: the ``hnsdt`` command."""

import sys

from hnsdt.cli import main

sys.exit(main())
