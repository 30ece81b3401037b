"""Where an output came from: the git revision of the code and a digest of the params that made it (cited by
the report and stamped into every episode recording)."""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path


def git_revision(cwd: str | Path = ".") -> str:
    """The checked-out commit (12 hex digits), ``-dirty`` when tracked files differ from it."""
    try:
        rev = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=cwd, capture_output=True, text=True,
                             check=True).stdout.strip()
    except (subprocess.CalledProcessError, FileNotFoundError):
        return "unknown (not a git checkout with commits)"
    # what the pipeline itself writes into git does not count: `dvc repro` rewrites dvc.lock after every stage,
    # and the evaluate stage the small summaries under metrics/ (outputs with `cache: false`)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ":(top)",
                            ":(top,exclude)dvc.lock", ":(top,exclude)metrics"],
                           cwd=cwd, capture_output=True, text=True).stdout.strip()
    return rev + ("-dirty" if dirty else "")


def params_digest(params) -> str:
    """16 hex digits of the canonical JSON of the params file as written (:attr:`hnsdt.compose.params.Params.raw`)."""
    return hashlib.sha256(json.dumps(params.raw, sort_keys=True).encode()).hexdigest()[:16]


def cpu_name() -> str:
    """The CPU as a timing needs it: model name, family and model (one "AMD EPYC" name covers CPUs 2-3x apart), the
    cores and whether it has AVX-512."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "unknown CPU"
    fields = {}
    for line in info.splitlines():
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    cores = sum(line.startswith("processor") for line in info.splitlines())
    return (f"{fields.get('model name', '?')} (family {fields.get('cpu family', '?')}, model {fields.get('model', '?')}),"
            f" {cores} cores, " + ("AVX-512" if "avx512f" in fields.get("flags", "").split() else "no AVX-512"))
