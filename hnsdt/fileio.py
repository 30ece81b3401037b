"""Atomic outputs: build a folder next to its destination, move it into place only when complete."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_dir(out: str | Path):
    """Yield a path that does not exist yet; write the output there. On success it replaces ``out``; on any
    error it is removed and ``out`` is left as it was, so no half-written output is ever visible."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    staging = work / out.name
    try:
        yield staging
        if out.exists():
            shutil.rmtree(out)
        os.replace(staging, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
