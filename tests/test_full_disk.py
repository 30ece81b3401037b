"""A full disk, for real: each command that writes, its output on a file system too small for it (a tmpfs,
mounted here: root only, as in CI), ends with one error line naming the output and the space it needed, and
leaves neither a partial output nor a temporary; with room again, the same command writes the bytes of a run
that never met a full disk."""

from __future__ import annotations

import contextlib
import os
import subprocess
from pathlib import Path

import pytest
import yaml

from hnsdt.core.fileio import TMP_PREFIX
from test_bad_input import assert_one_error_line, hnsdt, small_params

pytestmark = pytest.mark.slow


def _can_mount() -> bool:
    if os.geteuid() != 0:
        return False
    probe = Path(f"/tmp/hnsdt-mount-probe-{os.getpid()}")
    probe.mkdir(exist_ok=True)
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4k", "tmpfs", str(probe)],
                             capture_output=True).returncode == 0
    if mounted:
        subprocess.run(["umount", str(probe)], check=True)
    probe.rmdir()
    return mounted


if not _can_mount():
    pytest.skip("mounting a tmpfs needs root (CI runs as root)", allow_module_level=True)


@contextlib.contextmanager
def _disk(path: Path, kib: int):
    """A file system of ``kib`` KiB at ``path`` while the block runs."""
    path.mkdir(parents=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kib}k", "tmpfs", str(path)], check=True)
    try:
        yield path
    finally:
        busy = subprocess.run(["umount", str(path)], capture_output=True, text=True)
        assert busy.returncode == 0, f"a file on the full disk is still open: {busy.stderr}"


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """Small params (the unseen-layout experiment at a tiny size too), a dataset, a trained HNSDT and results."""
    root = tmp_path_factory.mktemp("full-disk")
    params = small_params()
    params["generalisation"].update(train_layouts=2, evaluated_train_layouts=1, heldout_layouts=1,
                                    validation_layouts=1, validation_families=[], episodes_per_layout=2, seeds=[0],
                                    method_seeds={}, minigrid=[], drawn=None)
    (root / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    for args in (["collect", "--env", "keydoor", "--out", "data/datasets/keydoor"],
                 ["train", "--env", "keydoor", "--method", "hnsdt", "--out", "models/keydoor/hnsdt", "--curves", "c"],
                 ["evaluate", "--out", "results", "--recordings", "recordings"],
                 ["generalisation", "collect", "--out", "unseen/dataset"],
                 ["generalisation", "train", "--method", "hnsdt", "--dataset", "unseen/dataset", "--out",
                  "unseen/models/hnsdt", "--curves", "unseen/curves"]):
        out = hnsdt(*args, "--quiet", cwd=root)
        assert out.returncode == 0, out.stderr[-2000:]
    return root


# command -> its arguments, writing under ``out`` (each is run from the work folder)
COMMANDS = {
    "collect": lambda out: ["collect", "--env", "keydoor", "--out", out / "dataset", "--quiet"],
    "train": lambda out: ["train", "--env", "keydoor", "--method", "hnsdt", "--out", out / "models", "--curves",
                          out / "curves", "--quiet"],
    "evaluate": lambda out: ["evaluate", "--out", out / "results", "--recordings", out / "recordings", "--quiet"],
    "report": lambda out: ["report", "--results", "results", "--out", out / "report"],
    "replay": lambda out: ["replay", "--dataset", "data/datasets/keydoor", "--episode", "1", "--out",
                           out / "episode.rrd"],
    "generalisation collect": lambda out: ["generalisation", "collect", "--out", out / "dataset", "--quiet"],
    "generalisation train": lambda out: ["generalisation", "train", "--method", "hnsdt", "--dataset", "unseen/dataset",
                                         "--out", out / "models", "--curves", out / "curves", "--quiet"],
    "generalisation evaluate": lambda out: ["generalisation", "evaluate", "--models", "unseen/models", "--methods",
                                            "hnsdt", "--out", out / "results", "--quiet"],
}


def _files(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` by its path, but rerun's (their row ids are time-based)."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.suffix != ".rrd"}


@pytest.mark.parametrize("command", COMMANDS)
def test_a_full_disk_ends_in_one_line_leaves_nothing_and_the_retry_writes_the_same_bytes(work, tmp_path, command):
    args = COMMANDS[command]
    reference = tmp_path / "reference"
    out = hnsdt(*args(reference), cwd=work)
    assert out.returncode == 0, out.stderr[-2000:]
    size = sum(p.stat().st_size for p in reference.rglob("*") if p.is_file())
    with _disk(tmp_path / "full", max(4, size // 2048)) as full:  # half what the output takes
        out = hnsdt(*args(full), cwd=work)
        assert_one_error_line(out, f"no space left on device writing {full}/")
        assert "free on its file system" in out.stderr and "free space and run again" in out.stderr
        assert TMP_PREFIX not in out.stderr  # it names the output, not a temporary of it
        left = [p.relative_to(full).as_posix() for p in full.rglob("*") if not p.is_dir()]
        assert left == [], f"{command} left {left} on the full disk"
    with _disk(tmp_path / "roomy", 2 * size // 1024 + 64) as roomy:  # space again: the same bytes
        out = hnsdt(*args(roomy), cwd=work)
        assert out.returncode == 0, out.stderr[-2000:]
        assert _files(roomy) == _files(reference)


def _used_kib(root: Path) -> int:
    """What the files under ``root`` take on disk, in KiB."""
    return sum(p.stat().st_blocks * 512 for p in root.rglob("*") if p.is_file() and not p.is_symlink()) // 1024


@pytest.mark.soak
def test_a_pipeline_that_fills_its_disk_finishes_with_the_uninterrupted_bytes_once_there_is_room(
        tmp_path, pipeline_run):
    """The tiny pipeline in a repo on a file system of half the space its run takes (workspace, DVC cache and
    git): `dvc repro` stops at the stage that meets the full disk with one line naming the output, leaving no
    temporary; once the file system is grown (a remount, the repo still on it), `dvc repro` finishes with the
    bytes of the run that never met a full disk. Its own tier (`make soak`): a second run of the tiny pipeline."""
    from tiny_repo import ENV, VARYING_OUTS, lock_outs, make_tiny_repo

    first_repo, _, reference = pipeline_run
    needed = _used_kib(first_repo)
    with _disk(tmp_path / "disk", needed // 2) as disk:
        repo = make_tiny_repo(disk / "repo")
        full = subprocess.run(["dvc", "repro"], cwd=repo, env=ENV, capture_output=True, text=True)
        said = full.stdout + full.stderr
        assert full.returncode != 0, said[-3000:]
        errors = [line for line in said.splitlines() if line.startswith("hnsdt: error:")]
        assert len(errors) == 1 and "no space left on device writing" in errors[0], said[-3000:]
        assert "Traceback" not in said, said[-3000:]
        assert not list(repo.rglob(f"{TMP_PREFIX}*")), "a temporary of the write that met the full disk is left"
        subprocess.run(["mount", "-o", f"remount,size={2 * needed}k", str(disk)], check=True)
        again = subprocess.run(["dvc", "repro"], cwd=repo, env=ENV, capture_output=True, text=True)
        assert again.returncode == 0, (again.stdout + again.stderr)[-3000:]
        outs = lock_outs(repo)
        assert outs.keys() == reference.keys()
        assert {k for k in outs if outs[k] != reference[k]} <= VARYING_OUTS
        print(f"full at {needed // 2} KiB: {errors[0]}")
