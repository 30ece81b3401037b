"""A temporary copy of this repository with a tiny params override, as a git repo DVC can run in.

Used by the end-to-end tests and by ``benchmarks/determinism.py``; nothing here is a test itself."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

from hnsdt.core.methods import LEARNED, METHODS, MINIGRID_LEARNERS, ONLINE_BASELINES

REPO = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent
ENV = dict(os.environ, PATH=f"{BIN}:{os.environ['PATH']}", PYTHONUNBUFFERED="1")  # DVC from the venv; logs as they happen
STAGES = {m: METHODS[m].stage for m in LEARNED}  # learned method of the paper protocol -> its DVC stage
_GENERALISATION = yaml.safe_load((REPO / "params.yaml").read_text())["generalisation"]
UNSEEN = _GENERALISATION["methods"] + _GENERALISATION["baselines"]  # learned methods of the unseen-layout experiment
VARYING_OUTS = {"evaluate:recordings",  # outputs whose bytes differ from run to run (rerun's row ids are time-based)
                "minigrid_reference@doorkey8:minigrid/doorkey8/recordings",
                "minigrid_learn@doorkey8:minigrid/doorkey8/learned_recordings"}
GIT_TRACKED_OUTS = {"metrics/summary.csv", "metrics/metrics.json", "metrics/headline"}  # outputs with
# `cache: false`: in git, and changed by a run with other params


def kept_in_git(path: str) -> bool:
    """Whether a path `git status` names is the lock file or one of :data:`GIT_TRACKED_OUTS` (or in one)."""
    return path == "dvc.lock" or any(path == out or path.startswith(out + "/") for out in GIT_TRACKED_OUTS)


def copy_repo(dst: Path) -> None:
    """Copy the tracked and untracked-not-ignored files, without data, DVC cache or lock file."""
    tracked = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=REPO, capture_output=True,
                             text=True, check=True).stdout.split()
    for rel in tracked:
        data = rel.startswith(("data/", ".dvc/cache")) and not rel.endswith(".gitignore")
        if data or rel == "dvc.lock" or not (REPO / rel).is_file():
            continue
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, dst / rel)


def tiny_online(knobs: dict, **tiny) -> None:
    """An online learner's ``knobs`` given those of ``tiny`` it has (replay learners: learning_starts; PPO:
    rollout_steps)."""
    knobs.update({k: v for k, v in tiny.items() if k in knobs or k == "env_steps"})


def tiny_params(path: Path) -> None:
    """Every stage kind runs, each in seconds: Case 1 only (Case 2 runs the same stages with another layout),
    9 episodes, 1 seed, a few gradient / env steps, one process per stage."""
    params = yaml.safe_load(path.read_text())
    params["envs"] = {"keydoor": params["envs"]["keydoor"]}
    params["train"]["envs"] = ["keydoor"]
    params["collect"]["fail_probs"] = [0.1]
    for b in params["collect"]["behaviours"]:
        b["episodes"] = 3
    params["train"].update(seeds=[0], epochs=1, max_steps=3)
    for method in params["baselines"]["offline"]:
        params["baselines"][method].update(epochs=1, max_steps=2)
    for method in params["baselines"]["online"]:
        tiny_online(params["baselines"][method], env_steps=400, learning_starts=200, rollout_steps=25)
    params["evaluate"].update(episodes=4, fail_probs=[0.0, 0.2])
    params["compute"]["workers"] = 1  # every stage in its own process: a pool's workers would each import torch
    # (≈ 2.5 s) for seconds of work, on cores the other test worker uses (pools: tests/test_train_cli.py)
    params["generalisation"].update(train_layouts=3, evaluated_train_layouts=1, heldout_layouts=1, seeds=[0],
                                    method_seeds={}, episodes_per_layout=2, episodes=2,
                                    budgets={m: {"validation": 0.0, "patience": 0} for m in ("lstm_hier", "gru")})
    # (the tiny knobs above; the RNNs at fixed epochs, as in the default)
    params["generalisation"]["minigrid"] = [{"id": "MiniGrid-DoorKey-8x8-v0", "layouts": 1, "max_steps": 100}]
    params["generalisation"]["drawn"]["max_steps"] = 150  # untrained learners walk to the limit: every drawn map
    # validates at 150 (the optimum's 0.99 at fail_prob 0.2), not at 120 (the zigzag)
    params["generalisation"]["validation_layouts"] = 1
    first_world = list(params["minigrid"]["envs"])[:1]  # one of MiniGrid's worlds, one test seed, one fail_prob
    params["minigrid"].update(envs={n: params["minigrid"]["envs"][n] for n in first_world},
                              test_seeds={"first": params["minigrid"]["test_seeds"]["first"], "count": 1},
                              fail_probs=[0.2], episodes=1)
    params["minigrid"]["collect"].update(train_seeds={"first": 0, "count": 2})
    params["minigrid"]["learn"].update(seeds=[0], max_epochs=1, validation_seeds={"first": 50000, "count": 1},
                                       methods=list(MINIGRID_LEARNERS),  # (every learner, in the default or not)
                                       **{name: dict(params["minigrid"]["learn"][name], max_frames=2048, eval_every=2048,
                                                     **({"learning_starts": 512} if "learning_starts" in
                                                        params["minigrid"]["learn"][name] else {}))
                                          for name in ONLINE_BASELINES},
                                       validation_max_steps=20, model=dict(params["minigrid"]["learn"]["model"],
                                                                           n_layers=1, d_model=32))
    first = list(params.get("unseen_experiments", {}))[:1]  # one further experiment runs its stage kind
    params["unseen_experiments"] = {name: params["unseen_experiments"][name] for name in first}
    for changes in params["unseen_experiments"].values():  # the tiny knobs above, one seed, episodes that end
        changes.update(seeds=[0], max_steps=min(changes.get("max_steps", 100), 100))  # sooner
    path.write_text(yaml.safe_dump(params, sort_keys=False))


def run(args, cwd, check: bool = True, env: dict | None = None) -> str:
    """Run a command with the venv first on PATH; stdout + stderr, asserting success if ``check``."""
    env = dict(ENV, **(env or {}))
    out = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True)
    if check and out.returncode != 0:
        raise AssertionError(f"{' '.join(map(str, args))} exited {out.returncode}:\n"
                             + out.stdout[-3000:] + out.stderr[-3000:])
    return out.stdout + out.stderr


def make_tiny_repo(dst: Path, tiny: bool = True) -> Path:
    """A committed git repo at ``dst`` holding the project, with tiny params (or the default ones)."""
    dst.mkdir(parents=True)
    copy_repo(dst)
    if tiny:
        tiny_params(dst / "params.yaml")
    run(["git", "init", "-q"], dst)
    run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "add", "-A"], dst)
    run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "copy",
         "--date=2026-01-01T00:00:00Z"], dst, env={"GIT_COMMITTER_DATE": "2026-01-01T00:00:00Z"})  # same sha each time
    return dst


def changed_stages(repo: Path) -> set[str]:
    """The stages `dvc status` finds changed: their own code, params or inputs (not yet their upstream's)."""
    out = subprocess.run(["dvc", "status", "--json"], cwd=repo, env=ENV, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return set(json.loads(out.stdout))


def ran_stages(log: str) -> set[str]:
    """The stages a `dvc repro` log says it ran."""
    return {line.split("'")[1] for line in log.splitlines() if line.startswith("Running stage '")}


def lock_outs(repo: Path) -> dict[str, str]:
    """``stage:out path -> md5`` of every output recorded in ``dvc.lock``."""
    lock = yaml.safe_load((repo / "dvc.lock").read_text())
    return {f"{stage}:{o['path']}": o.get("md5", "") for stage, s in lock["stages"].items() for o in s.get("outs", [])}


def shared_first_run(shared: Path) -> tuple[Path, str, dict[str, str]]:
    """The tiny pipeline's uninterrupted `dvc repro`, run once for every test file that needs it: whichever
    pytest-xdist worker asks first runs it under a file lock in ``shared`` (a folder all workers see), the others
    wait for it. Returns its repo (as the run left it: copy it before changing anything, :func:`copy_run`), its
    log (with every process's imports: PYTHONPROFILEIMPORTTIME) and the md5 of every output in dvc.lock."""
    from filelock import FileLock

    root, done = shared / "first-run", shared / "first-run.json"
    with FileLock(str(shared / "first-run.lock")):
        if not done.is_file():
            repo = make_tiny_repo(root / "repo")
            out = subprocess.run(["dvc", "repro"], cwd=repo, env=dict(ENV, PYTHONPROFILEIMPORTTIME="1"), text=True, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT)
            result = {"log": out.stdout, "outs": lock_outs(repo) if out.returncode == 0 else None}
            done.write_text(json.dumps(result))  # (a failed run too: the other workers fail at once, not again)
    result = json.loads(done.read_text())
    if result["outs"] is None:
        raise AssertionError("the tiny pipeline's dvc repro failed:\n" + result["log"][-5000:])
    return root / "repo", result["log"], result["outs"]


def copy_run(repo: Path, dst: Path) -> Path:
    """A copy of a pipeline run's repo (git, DVC cache, outputs) that a test may change."""
    shutil.copytree(repo, dst, symlinks=True)
    return dst
