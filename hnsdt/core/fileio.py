"""Atomic outputs: build a file or folder beside its destination, move it into place only when complete.

Temporaries are named ``.hnsdt-tmp-<name>-<pid>-<random>``; ``.gitignore`` and ``.dvcignore`` ignore that
pattern everywhere, so a process killed mid-write never leaves anything git or DVC could pick up, and the next
write to the same destination removes what a dead process left behind.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

TMP_PREFIX = ".hnsdt-tmp-"
_UMASK = os.umask(0o022)  # (reading the umask sets it: put it back)
os.umask(_UMASK)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temporaries(out: Path) -> None:
    """Remove temporaries for ``out`` left by processes that no longer run (e.g. killed by SIGKILL)."""
    for p in out.parent.glob(f"{TMP_PREFIX}{out.name}-*"):
        pid = p.name[len(TMP_PREFIX) + len(out.name) + 1:].split("-")[0]
        if pid.isdigit() and not _pid_alive(int(pid)):
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)


def _temp_prefix(out: Path) -> str:
    return f"{TMP_PREFIX}{out.name}-{os.getpid()}-"


@contextlib.contextmanager
def atomic_dir(out: str | Path):
    """Yield a path that does not exist yet; write the output there. On success it replaces ``out``; on any
    error it is removed and ``out`` is left as it was, so no half-written output is ever visible."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out)
    work = Path(tempfile.mkdtemp(prefix=_temp_prefix(out), dir=out.parent))
    staging = work / out.name
    try:
        yield staging
        if out.exists():
            os.replace(out, work / "previous")  # out is complete until the very rename below
        os.replace(staging, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(out: str | Path):
    """Yield a temporary path beside ``out``; when the block succeeds it is renamed onto ``out``."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(out)
    fd, name = tempfile.mkstemp(prefix=_temp_prefix(out), dir=out.parent)
    os.fchmod(fd, 0o666 & ~_UMASK)  # the mode a plain open() gives (mkstemp's is 0600: only its owner could read)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
