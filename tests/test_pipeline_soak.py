"""Kills anywhere: the tiny pipeline run from scratch, SIGKILLed at 20 seeded random moments across its stages and
resumed with `dvc repro` each time, ends with the bytes of the uninterrupted run (conftest's ``pipeline_run``).
Its own tier (`make soak`, which CI runs after `make test`): about three minutes of work."""

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO
from hnsdt.core.fileio import TMP_PREFIX
from tiny_repo import ENV, VARYING_OUTS, lock_outs, make_tiny_repo, run

pytestmark = [pytest.mark.slow, pytest.mark.soak]

KILLS = 20
SEED = 20261205


def _stages_started(log: str) -> list[str]:
    return [line.split("'")[1] for line in log.splitlines() if line.startswith("Running stage '")]


def _damaged_lock(log: str) -> str | None:
    """DVC rewrites two files in place, not atomically: a kill while it writes one leaves it cut short, and the
    next `dvc repro` stops on it. dvc.lock: "'./dvc.lock' is invalid" (not YAML) or "'./dvc.lock' validation
    failed" (YAML, but a stage cut off before its keys); .dvc/tmp/rwlock (which running process holds which
    output): "Unable to read RWLock-file". Which file, or None."""
    if "dvc.lock' is invalid" in log or "dvc.lock' validation failed" in log:
        return "dvc.lock"
    if "Unable to read RWLock-file" in log:
        return ".dvc/tmp/rwlock"
    return None


def _recovered(returncode: int, said: str, repo) -> bool:
    """After a `dvc repro` that ran to its end: False if it succeeded; if it stopped on a lock file an earlier kill
    cut short (its only allowed failure), what docs/reproducibility.md (and `make pipeline`'s one line) tells a
    user to do then — the committed dvc.lock back (here none is committed: no lock; the stages finished since come
    back from DVC's run cache), or the rwlock removed (no dvc runs now) — and True."""
    if returncode == 0:
        return False
    damaged = _damaged_lock(said)
    assert damaged, said[-3000:]
    assert subprocess.run([sys.executable, str(Path(REPO, "tools/check_locks.py"))], cwd=repo).returncode == 2
    tracked = subprocess.run(["git", "ls-files", "--error-unmatch", "dvc.lock"], cwd=repo, capture_output=True)
    if damaged == "dvc.lock" and tracked.returncode == 0:
        run(["git", "checkout", "dvc.lock"], repo)
    else:
        (repo / damaged).unlink()
    return True


def _obsolete_kept(path) -> bool:
    """A killed stage's kept results (hnsdt.core.fileio.finished_tasks) beside an output that is complete: DVC
    restored that stage from its run cache instead of running it, so nothing of ours ran to remove them (they are
    ignored by git and DVC, and documented: docs/reproducibility.md)."""
    name = path.name[len(TMP_PREFIX):]
    return name.endswith("-finished") and (path.parent / name[:-len("-finished")]).exists()


def test_twenty_kills_anywhere_end_in_the_uninterrupted_run_s_bytes(tmp_path, first_run):
    """Each run is killed once it has started its first or second stage (at random) and a random 0–3 s more:
    inside a stage's imports, training or writing, or in DVC's bookkeeping between stages. A run that finishes
    before its kill leaves the pipeline up to date; the next one then forces a random stage and everything
    downstream of it, so that all twenty kills land. A kill while DVC rewrites dvc.lock or its rwlock leaves it cut
    short (DVC writes both in place): the next run stops on it, and the documented recovery follows (:func:`_recovered`).
    Finding these was this test's first results (clean-clone CI runs, 2026-12-05: dvc.lock, then the rwlock)."""
    repo = make_tiny_repo(tmp_path / "repo")
    order = _stages_started(first_run[0])  # the pipeline's stages, in the order the uninterrupted run ran them
    rng = random.Random(SEED)
    killed_in, runs, up_to_date, recovered = [], 0, False, 0
    while len(killed_in) < KILLS:
        runs += 1
        assert runs <= 3 * KILLS, f"only {len(killed_in)} kills in {runs - 1} runs: {killed_in}"
        args = ["dvc", "repro"] if not up_to_date else ["dvc", "repro", "--force", "--downstream", rng.choice(order)]
        nth, delay = rng.choice([1, 2]), rng.uniform(0.0, 3.0)
        log = tmp_path / f"run{runs}.log"
        with open(log, "w") as f:
            proc = subprocess.Popen(args, cwd=repo, env=ENV, stdout=f, stderr=subprocess.STDOUT,
                                    start_new_session=True)
        deadline = time.monotonic() + 300
        while len(_stages_started(log.read_text())) < nth and proc.poll() is None:
            assert time.monotonic() < deadline, f"run {runs} started no stage:\n{log.read_text()[-2000:]}"
            time.sleep(0.02)
        time.sleep(delay)
        if proc.poll() is not None:  # it finished first, or stopped on a lock file an earlier kill cut short
            recovered += _recovered(proc.returncode, log.read_text(), repo)
            up_to_date = proc.returncode == 0
            continue
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        killed_in.append(_stages_started(log.read_text())[-1])
        up_to_date = False
    assert len(set(killed_in)) >= 8, killed_in  # spread across the stages, not one stage twenty times
    last = subprocess.run(["dvc", "repro"], cwd=repo, env=ENV, capture_output=True, text=True)  # to the end
    if _recovered(last.returncode, last.stdout + last.stderr, repo):
        recovered += 1
        run(["dvc", "repro"], repo)
    assert not [p for p in repo.rglob(f"{TMP_PREFIX}*") if not _obsolete_kept(p)], \
        "temporaries of killed writes were not cleaned up"
    outs, reference = lock_outs(repo), first_run[1]
    assert outs.keys() == reference.keys()
    assert {k for k in outs if outs[k] != reference[k]} <= VARYING_OUTS, killed_in
    print(f"{KILLS} kills in {runs} runs, in {len(set(killed_in))} stages, {recovered} lock files recovered: "
          f"{killed_in}")
