"""The real DVC pipeline, end to end, on a tiny params override in a temporary copy of the repo."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml

from hnsdt.fileio import TMP_PREFIX
from hnsdt.methods import LEARNED, METHODS
from tiny_repo import lock_outs, make_tiny_repo, ran_stages, run

pytestmark = pytest.mark.slow
BIN = Path(sys.executable).parent
STAGES = {m: METHODS[m].stage for m in LEARNED}  # learned method -> its DVC stage


def _set(repo: Path, section: str, key: str, value) -> None:
    params = yaml.safe_load((repo / "params.yaml").read_text())
    node = params
    for part in section.split("."):
        node = node[part]
    node[key] = value
    (repo / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))


@pytest.fixture(scope="module")
def repo_copies(tmp_path_factory):
    """Two identical copies, made together: one runs uninterrupted, the other is killed and resumed."""
    root = tmp_path_factory.mktemp("pipeline")
    return make_tiny_repo(root / "repo"), make_tiny_repo(root / "killed")


@pytest.fixture(scope="module")
def repo_copy(repo_copies):
    return repo_copies[0]


@pytest.fixture(scope="module")
def first_run(repo_copy):
    """The uninterrupted run: its log and the md5 of every output in its dvc.lock."""
    log = run(["dvc", "repro"], repo_copy)
    return log, lock_outs(repo_copy)


def test_repro_runs_everything_then_nothing_then_only_what_changed(repo_copy, first_run):
    from hnsdt.data.lerobot_io import open_dataset

    ran = ran_stages(first_run[0])
    assert ran == {"collect@keydoor", "collect@multikeydoor", "evaluate", "report"} | {
        f"{STAGES[m]}@{env}-{m}" for env in ("keydoor", "multikeydoor") for m in STAGES}
    for env in ("keydoor", "multikeydoor"):
        assert open_dataset(repo_copy / "data/datasets" / env).meta.total_episodes == 9
        for method in STAGES:
            assert (repo_copy / f"models/{env}/{method}/seed0/model.safetensors").is_file()
            assert (repo_copy / f"plots/train/{env}-{method}/seed0.csv").is_file()
    table = pd.read_csv(repo_copy / "results/episodes.csv", keep_default_na=False)
    assert len(table) == 7 * 2 * 2 * 1 * 4  # methods x envs x fail_probs x seeds x episodes
    metrics = json.loads((repo_copy / "results/metrics.json").read_text())
    assert metrics["keydoor"]["symbolic"]["fail_0"]["success_mean"] == 1.0
    assert set(metrics["multikeydoor"]) == set(STAGES) | {"symbolic"}
    shown = json.loads(run(["dvc", "metrics", "show", "--json"], repo_copy))  # declared as DVC metrics
    assert json.dumps(shown).count("success_mean") >= 7 * 2 * 2
    usage = pd.read_csv(repo_copy / "results/training_usage.csv")
    assert set(usage[usage.training == "online"].env_steps) == {400}
    assert (usage[usage.training == "dataset"].dataset_frames > 0).all()
    recorded = table[table.rrd != ""]
    assert len(recorded) == 7 * 2 * 2 and all((repo_copy / p).is_file() for p in recorded.mcap)
    report = (repo_copy / "report/report.md").read_text()
    lock = yaml.safe_load((repo_copy / "dvc.lock").read_text())
    dataset_md5 = lock["stages"]["collect@keydoor"]["outs"][0]["md5"]
    rev = run(["git", "rev-parse", "--short=12", "HEAD"], repo_copy).strip()
    assert dataset_md5 in report and "figures/comparison.png" in report and f"`{rev}" in report
    assert (repo_copy / "report/figures/success_heatmap.png").stat().st_size > 10_000
    assert "figures/paradigms.png" in report and "Agreement with the paper's claims" in report

    assert ran_stages(run(["dvc", "repro"], repo_copy)) == set()  # nothing changed: nothing reruns
    # a run leaves nothing for git to pick up but its lock file
    status = run(["git", "status", "--porcelain", "--untracked-files=all"], repo_copy).splitlines()
    assert {line[3:] for line in status} == {"dvc.lock"}, status

    _set(repo_copy, "evaluate", "episodes", 5)
    assert ran_stages(run(["dvc", "repro"], repo_copy)) == {"evaluate", "report"}

    _set(repo_copy, "baselines.dqn", "lr", 0.001)  # one method's knob: only its instances retrain
    # (the report reruns only if the evaluation's tables changed: they are the same bytes when 400 env steps
    # of DQN at another learning rate still act the same in the few evaluated episodes)
    assert ran_stages(run(["dvc", "repro"], repo_copy)) - {"report"} == {
        "train_online@keydoor-dqn", "train_online@multikeydoor-dqn", "evaluate"}

    _set(repo_copy, "envs.keydoor", "max_steps", 60)
    assert ran_stages(run(["dvc", "repro"], repo_copy)) == {"collect@keydoor", "evaluate", "report"} | {
        f"{STAGES[m]}@keydoor-{m}" for m in STAGES}


def test_replay_points_to_an_evaluated_episode(repo_copy):
    out = subprocess.run([sys.executable, "-m", "hnsdt.cli", "replay", "hnsdt/keydoor/fp0.2/seed0/ep0"],
                         cwd=repo_copy, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "recordings/hnsdt/keydoor/fp0.2/seed0/ep0.rrd" in out.stdout and ".mcap" in out.stdout
    missing = subprocess.run([sys.executable, "-m", "hnsdt.cli", "replay", "hnsdt/keydoor/fp0.2/seed0/ep3"],
                             cwd=repo_copy, capture_output=True, text=True)
    assert missing.returncode == 2 and "was not recorded" in missing.stderr


def _tmp_under(folder: Path) -> bool:
    return folder.is_dir() and any(p.name.startswith(TMP_PREFIX) for p in folder.iterdir())


def _inside_training(repo: Path, log: str) -> bool:
    """A `train@` stage has started; a second later its process is importing or training, not yet saving."""
    if "Running stage 'train@" not in log:
        return False
    time.sleep(1.0)
    return True


# (what to wait for before SIGKILL, the final output that must then not exist half-written)
KILL_POINTS = {
    "collect": (lambda repo, log: _tmp_under(repo / "data/datasets"), "data/datasets/keydoor"),
    "train": (_inside_training, None),
    "evaluate": (lambda repo, log: _tmp_under(repo), "results"),
}


def test_killed_runs_resume_to_the_same_outputs(tmp_path, repo_copies, first_run):
    """SIGKILL `dvc repro` during collect, during a training stage and during evaluate; each next run picks
    up cleanly, no half-written output is ever at its final path, and the outputs equal the uninterrupted
    run's, byte for byte (the .rrd recordings excepted: rerun's row ids are time-based)."""
    repo = repo_copies[1]
    env = dict(os.environ, PATH=f"{BIN}:{os.environ['PATH']}", PYTHONUNBUFFERED="1")  # the log as it happens
    for stage, (ready, final) in KILL_POINTS.items():
        log_path = tmp_path / f"{stage}.log"
        with open(log_path, "w") as log:
            proc = subprocess.Popen(["dvc", "repro"], cwd=repo, env=env, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True)
        deadline = time.monotonic() + 300
        while not ready(repo, log_path.read_text()):
            assert proc.poll() is None, f"dvc repro ended before reaching {stage}:\n{log_path.read_text()[-2000:]}"
            assert time.monotonic() < deadline, f"never reached {stage}"
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        assert f"Running stage '{stage}" in log_path.read_text()
        if final:
            assert not (repo / final).exists(), f"half-written {final} after a kill during {stage}"
    run(["dvc", "repro"], repo)
    assert not list(repo.rglob(f"{TMP_PREFIX}*")), "temporaries of killed writes were not cleaned up"
    status = run(["git", "status", "--porcelain", "--untracked-files=all"], repo).splitlines()
    assert {line[3:] for line in status} == {"dvc.lock"}, status
    outs, reference = lock_outs(repo), first_run[1]
    assert outs.keys() == reference.keys()
    assert {k for k in outs if outs[k] != reference[k]} <= {"evaluate:recordings"}
