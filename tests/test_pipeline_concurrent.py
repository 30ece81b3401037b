"""Two runs at once on the tiny pipeline's run (conftest's ``pipeline_run``; this file's own copy): in one
workspace the second `dvc repro` refuses with DVC's one error line (the output that is busy, then the PID and
command of the run holding it) and the first is unharmed; two clones sharing one DVC cache both finish with the
uninterrupted run's bytes."""

import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from tiny_repo import ENV, VARYING_OUTS, changed_stages, copy_run, lock_outs, ran_stages, run

pytestmark = pytest.mark.slow

STAGE = "train@keydoor-hnsdt"


def _training(repo: Path, log: str) -> bool:
    """The stage's progress bar has counted 5 gradient steps: the first run holds the workspace's lock."""
    done = [int(n) for n in re.findall(r"\| *(\d+)/\d+ \[", log.split(f"Running stage '{STAGE}'")[-1])]
    return f"Running stage '{STAGE}'" in log and bool(done) and max(done) >= 5


def _start(args: list[str], repo: Path, log: Path) -> subprocess.Popen:
    with open(log, "w") as f:
        return subprocess.Popen(args, cwd=repo, env=ENV, stdout=f, stderr=subprocess.STDOUT)


def test_a_second_run_in_one_workspace_refuses_and_the_first_is_unharmed(tmp_path, repo_copy, first_run):
    repo = repo_copy
    tiny = (repo / "params.yaml").read_text()
    params = yaml.safe_load(tiny)
    params["train"].update(epochs=10_000, max_steps=600, validation={})  # seconds of training, to overlap
    (repo / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    log = tmp_path / "first.log"
    first = _start(["dvc", "repro", "--single-item", STAGE], repo, log)
    deadline = time.monotonic() + 300
    while not _training(repo, log.read_text()):
        assert first.poll() is None, f"the first run ended before training:\n{log.read_text()[-2000:]}"
        assert time.monotonic() < deadline, "the first run never started training"
        time.sleep(0.05)
    second = subprocess.run(["dvc", "repro"], cwd=repo, env=ENV, capture_output=True, text=True)
    assert first.poll() is None, "the first run ended before the second tried: the test proves nothing"
    assert second.returncode != 0
    said = second.stdout + second.stderr  # DVC's read-write lock on the outputs: which one, and who holds it
    errors = [line for line in said.splitlines() if line.startswith("ERROR")]
    assert len(errors) == 1 and "is busy, it is being blocked by" in errors[0], said
    assert f"(PID {first.pid}): " in said and f"dvc repro --single-item {STAGE}" in said, said
    assert first.wait(timeout=300) == 0, log.read_text()[-2000:]
    assert ran_stages(log.read_text()) == {STAGE}
    lock = yaml.safe_load((repo / "dvc.lock").read_text())["stages"][STAGE]
    assert lock["params"]["params.yaml"]["train.max_steps"] == 600  # the first run's, recorded whole
    (repo / "params.yaml").write_text(tiny)
    run(["dvc", "repro"], repo)  # its knobs back (restored from DVC's run cache): the committed bytes again
    outs = lock_outs(repo)
    assert {k for k in outs if outs[k] != first_run[1][k]} <= VARYING_OUTS


def test_two_clones_sharing_one_cache_both_finish_with_the_run_s_bytes(tmp_path, pipeline_run, first_run):
    """Both clones run the same stages at the same time into one DVC cache (`dvc cache dir`): each ends with
    the uninterrupted run's outputs."""
    cache = tmp_path / "cache"
    clones = [copy_run(pipeline_run[0], tmp_path / name) for name in ("a", "b")]
    shutil.copytree(pipeline_run[0] / ".dvc/cache", cache)  # (the run's cache, now theirs)
    stages = ["collect@keydoor", STAGE]
    for clone in clones:
        run(["dvc", "cache", "dir", "--local", str(cache)], clone)
    runs = [_start(["dvc", "repro", "--force", "--single-item", *stages], clone, tmp_path / f"{clone.name}.log")
            for clone in clones]
    for clone, proc in zip(clones, runs):
        assert proc.wait(timeout=600) == 0, (tmp_path / f"{clone.name}.log").read_text()[-3000:]
        assert ran_stages((tmp_path / f"{clone.name}.log").read_text()) == set(stages)
        outs = lock_outs(clone)
        assert outs == first_run[1], {k for k in outs if outs[k] != first_run[1].get(k)}
        assert changed_stages(clone) == set()
