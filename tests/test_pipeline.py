"""The real DVC pipeline, end to end, on a tiny params override in a temporary copy of the repo."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from conftest import REPO

pytestmark = pytest.mark.slow
BIN = Path(sys.executable).parent
STAGES = {"hnsdt": "train", "pure_dt": "train", "lstm_hier": "train_offline", "gru": "train_offline",
          "dqn": "train_online", "options": "train_online"}  # learned method -> its DVC stage


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
    params["train"].update(seeds=[0], epochs=1, max_steps=3)
    for method in params["baselines"]["offline"]:
        params["baselines"][method].update(epochs=1, max_steps=2)
    for method in params["baselines"]["online"]:
        params["baselines"][method].update(env_steps=400, learning_starts=200)
    params["evaluate"].update(episodes=4, fail_probs=[0.0, 0.2])
    path.write_text(yaml.safe_dump(params, sort_keys=False))


def _run(args, cwd):
    env = dict(os.environ, PATH=f"{BIN}:{os.environ['PATH']}")
    out = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    return out.stdout + out.stderr


def _ran(log: str) -> set[str]:
    return {line.split("'")[1] for line in log.splitlines() if line.startswith("Running stage '")}


def _set(repo: Path, section: str, key: str, value) -> None:
    params = yaml.safe_load((repo / "params.yaml").read_text())
    node = params
    for part in section.split("."):
        node = node[part]
    node[key] = value
    (repo / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))


@pytest.fixture(scope="module")
def repo_copy(tmp_path_factory):
    dst = tmp_path_factory.mktemp("pipeline") / "repo"
    dst.mkdir()
    _copy_repo(dst)
    _tiny_params(dst / "params.yaml")
    _run(["git", "init", "-q"], dst)
    _run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "add", "-A"], dst)
    _run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "copy"], dst)
    return dst


def test_repro_runs_everything_then_nothing_then_only_what_changed(repo_copy):
    from hnsdt.data.lerobot_io import open_dataset

    ran = _ran(_run(["dvc", "repro"], repo_copy))
    assert ran == {"collect@keydoor", "collect@multikeydoor", "evaluate", "report"} | {
        f"{STAGES[m]}@{env}-{m}-0" for env in ("keydoor", "multikeydoor") for m in STAGES}
    for env in ("keydoor", "multikeydoor"):
        assert open_dataset(repo_copy / "data/datasets" / env).meta.total_episodes == 9
        for method in STAGES:
            assert (repo_copy / f"models/{env}/{method}/seed0/model.safetensors").is_file()
            assert (repo_copy / f"plots/train/{env}-{method}-seed0.csv").is_file()
    table = pd.read_csv(repo_copy / "results/episodes.csv", keep_default_na=False)
    assert len(table) == 7 * 2 * 2 * 1 * 4  # methods x envs x fail_probs x seeds x episodes
    metrics = json.loads((repo_copy / "results/metrics.json").read_text())
    assert metrics["keydoor"]["symbolic"]["fail_0"]["success_mean"] == 1.0
    assert set(metrics["multikeydoor"]) == set(STAGES) | {"symbolic"}
    usage = pd.read_csv(repo_copy / "results/training_usage.csv")
    assert set(usage[usage.training == "online"].env_steps) == {400}
    assert (usage[usage.training == "dataset"].dataset_frames > 0).all()
    recorded = table[table.rrd != ""]
    assert len(recorded) == 7 * 2 * 2 and all((repo_copy / p).is_file() for p in recorded.mcap)
    report = (repo_copy / "report/report.md").read_text()
    lock = yaml.safe_load((repo_copy / "dvc.lock").read_text())
    dataset_md5 = lock["stages"]["collect@keydoor"]["outs"][0]["md5"]
    rev = _run(["git", "rev-parse", "--short=12", "HEAD"], repo_copy).strip()
    assert dataset_md5 in report and "figures/comparison.png" in report and f"`{rev}" in report
    assert (repo_copy / "report/figures/success_heatmap.png").stat().st_size > 10_000
    assert "figures/paradigms.png" in report and "Agreement with the paper's claims" in report

    assert _ran(_run(["dvc", "repro"], repo_copy)) == set()  # nothing changed: nothing reruns

    _set(repo_copy, "evaluate", "episodes", 5)
    assert _ran(_run(["dvc", "repro"], repo_copy)) == {"evaluate", "report"}

    _set(repo_copy, "baselines.dqn", "lr", 0.001)  # one method's knob: only its instances retrain
    assert _ran(_run(["dvc", "repro"], repo_copy)) == {
        "train_online@keydoor-dqn-0", "train_online@multikeydoor-dqn-0", "evaluate", "report"}

    _set(repo_copy, "envs.keydoor", "max_steps", 60)
    assert _ran(_run(["dvc", "repro"], repo_copy)) == {"collect@keydoor", "evaluate", "report"} | {
        f"{STAGES[m]}@keydoor-{m}-0" for m in STAGES}


def test_replay_points_to_an_evaluated_episode(repo_copy):
    out = subprocess.run([sys.executable, "-m", "hnsdt.cli", "replay", "hnsdt/keydoor/fp0.2/seed0/ep0"],
                         cwd=repo_copy, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "results/logs/hnsdt/keydoor/fp0.2/seed0/ep0.rrd" in out.stdout and ".mcap" in out.stdout
    missing = subprocess.run([sys.executable, "-m", "hnsdt.cli", "replay", "hnsdt/keydoor/fp0.2/seed0/ep3"],
                             cwd=repo_copy, capture_output=True, text=True)
    assert missing.returncode == 2 and "was not recorded" in missing.stderr
