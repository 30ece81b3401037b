"""Atomic outputs: build a file or folder beside its destination, move it into place only when complete.

Temporaries are named ``.hnsdt-tmp-<name>-<pid>-<random>``; ``.gitignore`` and ``.dvcignore`` ignore that
pattern everywhere, so a process killed mid-write never leaves anything git or DVC could pick up, and the next
write to the same destination removes what a dead process left behind. A write the file system cannot hold
(``ENOSPC``, whichever library met it) removes its temporary and raises :class:`DiskFullError`, naming the
destination, the space it needed and the space that was free.
"""

from __future__ import annotations

import contextlib
import errno
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


@contextlib.contextmanager
def finished_tasks(out: str | Path):
    """Yield where a stage keeps its finished tasks' results while it computes ``out`` (``run_tasks``' ``keep``:
    :mod:`hnsdt.core.compute`): a hidden folder beside it, ignored by git and DVC like every temporary. Only a
    killed (or interrupted: Ctrl-C) run leaves it, for the next run to take from; it is removed when the block
    ends, with ``out`` written or with an error."""
    out = Path(out)
    keep = out.parent / f"{TMP_PREFIX}{out.name}-finished"
    try:
        yield keep
    except Exception:
        shutil.rmtree(keep, ignore_errors=True)
        raise
    shutil.rmtree(keep, ignore_errors=True)


class DiskFullError(OSError):
    """A write stopped by a full file system (its temporary removed); the message names its destination and
    the space it needed: more than is free there once the temporary is gone (and, where the writer knew its
    size beforehand, at least ``needed`` bytes)."""

    needed: int = 0


def disk_full(error: BaseException | None) -> bool:
    """Whether ``error`` or what it was raised from is a full disk or quota: an ``OSError``'s errno, or the
    message of a library that wraps it (pyarrow's ``OSError`` without an errno, safetensors' own error)."""
    while error is not None:
        if isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        if any(words in str(error) for words in ("No space left on device", "os error 28", "Disk quota exceeded")):
            return True
        error = error.__cause__ or error.__context__
    return False


def require_space(path: Path, needed: int) -> None:
    """Raise the :class:`DiskFullError` a write of ``needed`` bytes into ``path``'s folder would meet, before
    writing any of it."""
    if shutil.disk_usage(path.parent).free < needed:
        raise _full(path, needed)


def _full(out: Path, needed: int = 0) -> DiskFullError:
    free = shutil.disk_usage(out.parent).free
    least = f" (at least {_size(needed)})" if needed > free else ""
    full = DiskFullError(f"no space left on device writing {out}: it needs more than the {_size(free)} free on its "
                         f"file system{least}; free space and run again")
    full.errno, full.needed = errno.ENOSPC, needed
    return full


def _disk_full_error(out: Path, work: Path, error: BaseException) -> DiskFullError:
    """What a write to ``out`` that filled the disk raises, once its temporary ``work`` is gone."""
    shutil.rmtree(work, ignore_errors=True) if work.is_dir() else work.unlink(missing_ok=True)
    inner = error
    while inner is not None and not isinstance(inner, DiskFullError):
        inner = inner.__cause__ or inner.__context__
    return _full(out, inner.needed if inner is not None else 0)  # (a nested write's size: part of this one's)


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB"):
        if n < 1024:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"


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
    except Exception as e:
        if disk_full(e):  # (a nested write's DiskFullError too: this one names the outer destination)
            raise _disk_full_error(out, work, e) from e
        raise
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
    except Exception as e:
        if disk_full(e):
            raise _disk_full_error(out, tmp, e) from e
        raise
    finally:
        tmp.unlink(missing_ok=True)


def write_folder(out: str | Path, files: dict[str, bytes]) -> None:
    """A folder of named files as one output (recordings): built beside ``out``, moved into place when complete."""
    with atomic_dir(out) as work:
        work.mkdir(parents=True)
        for name, data in files.items():
            (work / name).write_bytes(data)


def write_files(files: dict[Path, bytes]) -> None:
    """Several files as one output (a recording's ``.rrd`` and ``.mcap``): each written to a temporary beside it,
    then all renamed into place; a failure while writing any of them leaves none."""
    with contextlib.ExitStack() as stack:
        temps = {out: stack.enter_context(atomic_file(out)) for out in files}
        for out, data in files.items():
            temps[out].write_bytes(data)
