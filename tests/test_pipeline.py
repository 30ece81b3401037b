"""The real DVC pipeline, end to end, on a tiny params override in a temporary copy of the repo."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import REPO

pytestmark = pytest.mark.slow
BIN = Path(sys.executable).parent


def _copy_repo(dst: Path) -> None:
    tracked = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=REPO, capture_output=True,
                             text=True, check=True).stdout.split()
    for rel in tracked:
        if rel.startswith(("data/", ".dvc/cache")) or rel == "dvc.lock" or not os.path.isfile(f"{REPO}/{rel}"):
            continue
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(f"{REPO}/{rel}", dst / rel)


def _tiny_params(path: Path) -> None:
    params = yaml.safe_load(path.read_text())
    params["collect"]["fail_probs"] = [0.1]
    for b in params["collect"]["behaviours"]:
        b["episodes"] = 3
    path.write_text(yaml.safe_dump(params, sort_keys=False))


def _run(args, cwd):
    env = dict(os.environ, PATH=f"{BIN}:{os.environ['PATH']}")
    out = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out.stdout + out.stderr


@pytest.fixture(scope="module")
def repo_copy(tmp_path_factory):
    dst = tmp_path_factory.mktemp("pipeline") / "repo"
    dst.mkdir()
    _copy_repo(dst)
    _tiny_params(dst / "params.yaml")
    _run(["git", "init", "-q"], dst)
    return dst


def test_repro_builds_every_dataset_then_reruns_only_what_changed(repo_copy):
    from hnsdt.data.lerobot_io import open_dataset

    log = _run(["dvc", "repro"], repo_copy)
    assert "Running stage 'collect@keydoor'" in log and "Running stage 'collect@multikeydoor'" in log
    for env in ("keydoor", "multikeydoor"):
        ds = open_dataset(repo_copy / "data/datasets" / env)
        assert ds.meta.total_episodes == 9
    assert "Running stage" not in _run(["dvc", "repro"], repo_copy)  # nothing changed: nothing reruns

    params = yaml.safe_load((repo_copy / "params.yaml").read_text())
    params["envs"]["keydoor"]["max_steps"] = 50
    (repo_copy / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    log = _run(["dvc", "repro"], repo_copy)
    assert "Running stage 'collect@keydoor'" in log and "collect@multikeydoor" not in log.replace(
        "Stage 'collect@multikeydoor' didn't change", "")
