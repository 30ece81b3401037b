"""What every stage shares: the provenance its outputs cite, and the command line's error contract (one
``hnsdt: error:`` line and exit status 2 for bad input; ``HNSDT_DEBUG=1`` shows the traceback behind it)."""

from __future__ import annotations

import os
import sys
import traceback
from pathlib import Path
from typing import Callable

from hnsdt.compose.config import Params, load_params

DEBUG_VARIABLE = "HNSDT_DEBUG"  # set to 1: a one-line error is followed by the traceback that raised it


def provenance(params: Params) -> dict:
    """What the outputs cite: the code's git revision and the params' digest."""
    from hnsdt.core.provenance import git_revision, params_digest

    return {"git_revision": git_revision(), "params_digest": params_digest(params)}


def guarded(fn: Callable[..., object], *args, **kwargs) -> int:
    """``fn(*args, **kwargs)`` under the command line's error contract: 0, or 2 after one ``hnsdt: error:`` line
    naming the problem (the ``hnsdt`` command and every stage script use it); with ``HNSDT_DEBUG=1`` the
    traceback follows it."""
    from hnsdt.core.fileio import disk_full
    from hnsdt.envs import LayoutError

    try:
        fn(*args, **kwargs)
    except Exception as e:
        if not isinstance(e, (LayoutError, ValueError, RuntimeError, OSError)) and not disk_full(e):
            raise  # a bug: its traceback (a ParamsError is a ValueError; a full disk in any library is bad luck)
        print("hnsdt: error: " + " ".join(str(e).split()), file=sys.stderr)  # always one line
        if os.environ.get(DEBUG_VARIABLE, "") not in ("", "0"):
            traceback.print_exc()
        return 2
    return 0


def run(stage: Callable[..., object], params_path: str | Path = "params.yaml", experiment: str | None = None,
        **arguments) -> int:
    """What a stage script runs: ``stage(load_params(params_path), **arguments)``, :func:`guarded`; with
    ``experiment``, the params as that unseen-layout experiment sees them."""
    from hnsdt.compose.config import unseen_experiment

    return guarded(lambda: stage(unseen_experiment(load_params(params_path), experiment), **arguments))
