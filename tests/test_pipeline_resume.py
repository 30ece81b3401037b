"""Killed pipeline runs resume to the same outputs: on a copy of the tiny pipeline's first run (conftest's
``pipeline_run``, shared with test_pipeline.py; ``repo_copy`` is this file's own), so that the two files run
on two pytest-xdist workers at once."""

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from hnsdt.core.fileio import TMP_PREFIX
from tiny_repo import ENV, VARYING_OUTS, kept_in_git, lock_outs, ran_stages, run

pytestmark = pytest.mark.slow


def _tmp_under(folder: Path) -> bool:
    return folder.is_dir() and any(p.name.startswith(TMP_PREFIX) for p in folder.iterdir())


def _inside_training(repo: Path, log: str) -> bool:
    """A `train@` stage's progress bar has counted gradient steps: it is training, between its first step and
    its save (its budget is :data:`LONG_TRAINING`'s while it is killed)."""
    if "Running stage 'train@" not in log:
        return False
    done = [int(n) for n in re.findall(r"\| *(\d+)/\d+ \[", log.split("Running stage 'train@")[-1])]
    return bool(done) and max(done) >= 5


# while a training stage is killed: a fixed budget it cannot finish first (the tiny params' 3 steps end at once)
LONG_TRAINING = {"epochs": 10_000, "max_steps": 100_000, "validation": {}}


# stage run again and SIGKILLed: (what to wait for before the kill, the output that must then not exist);
# downstream first, so each forced run still finds its inputs
KILL_POINTS = {
    "evaluate": (lambda repo, log: _tmp_under(repo), "results"),
    "train@keydoor-hnsdt": (_inside_training, "models/keydoor/hnsdt"),
    "collect@keydoor": (lambda repo, log: _tmp_under(repo / "data/datasets"), "data/datasets/keydoor"),
}


def test_killed_runs_resume_to_the_same_outputs(tmp_path, repo_copy, first_run):
    """SIGKILL `dvc repro --force` of the evaluate, a training (after its 5th gradient step) and a collect stage
    while they run; no half-written output is ever at its final path, and the next run of each (forced: `dvc
    repro` alone would restore the outputs from DVC's cache instead of computing them) cleans up after the
    killed one and writes the uninterrupted run's outputs, byte for byte (the .rrd recordings excepted: rerun's
    row ids are time-based)."""
    repo = repo_copy
    tiny = (repo / "params.yaml").read_text()
    for stage, (ready, final) in KILL_POINTS.items():
        if stage.startswith("train@"):  # killed mid-training: a budget it cannot finish before the kill
            params = yaml.safe_load(tiny)
            params["train"].update(LONG_TRAINING)
            (repo / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
        log_path = tmp_path / f"{stage}.log"
        with open(log_path, "w") as log:
            proc = subprocess.Popen(["dvc", "repro", "--force", "--single-item", stage], cwd=repo, env=ENV,
                                    stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + 300
        while not ready(repo, log_path.read_text()):
            assert proc.poll() is None, f"dvc repro ended before reaching {stage}:\n{log_path.read_text()[-2000:]}"
            assert time.monotonic() < deadline, f"never reached {stage}"
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        assert f"Running stage '{stage}" in log_path.read_text()
        (repo / "params.yaml").write_text(tiny)
        assert not (repo / final).exists(), f"half-written {final} after a kill during {stage}"
    again = list(reversed(KILL_POINTS))  # upstream first, in one `dvc repro` (one DVC start-up, not three)
    assert ran_stages(run(["dvc", "repro", "--force", "--single-item", *again], repo)) == set(again)
    assert not list(repo.rglob(f"{TMP_PREFIX}*")), "temporaries of killed writes were not cleaned up"
    status = run(["git", "status", "--porcelain", "--untracked-files=all"], repo).splitlines()
    assert all(kept_in_git(line[3:]) for line in status), status
    outs, reference = lock_outs(repo), first_run[1]
    assert outs.keys() == reference.keys()
    assert {k for k in outs if outs[k] != reference[k]} <= VARYING_OUTS
