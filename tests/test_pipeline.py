"""The real DVC pipeline, end to end, on a tiny params override in a temporary copy of the repo."""

import importlib.util
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from hnsdt.core.methods import METHODS, MINIGRID_LEARNERS
from conftest import hnsdt_cli
from tiny_repo import REPO, STAGES, UNSEEN, changed_stages, kept_in_git, ran_stages, run

pytestmark = pytest.mark.slow  # (pytest-xdist runs a file on one worker, in order: `--dist loadfile`)
_UNSEEN = yaml.safe_load((REPO / "params.yaml").read_text())["generalisation"]  # the unseen-layout experiment
EXPERIMENTS = list(yaml.safe_load((REPO / "params.yaml").read_text()).get("unseen_experiments", {}))[:1]  # further
# ones: the tiny params keep the first (tiny_repo.tiny_params)
UNSEEN_STAGES = {"collect_generalisation", "evaluate_generalisation"} | {
    f"train_generalisation@{m}" for m in _UNSEEN["methods"]} | {
    f"train_generalisation_baselines@{m}" for m in _UNSEEN["baselines"]} | {
    f"unseen_experiment@{name}" for name in EXPERIMENTS}


def _imports_by_stage(log: str) -> dict[str, set[str]]:
    """``stage -> repo paths of the hnsdt modules its processes imported``, from a `dvc repro` log taken with
    PYTHONPROFILEIMPORTTIME=1 (every Python process, pool workers included, lists its imports on stderr)."""
    found: dict[str, set[str]] = {}
    stage = None
    for line in log.splitlines():
        if m := re.search(r"Running stage '([^']+)'", line):
            stage = m.group(1)
            found[stage] = set()
        elif stage and (m := re.search(r"import time:.*\|\s*(hnsdt(\.\w+)*)\s*$", line)):  # (after a progress bar)
            origin = Path(importlib.util.find_spec(m.group(1)).origin)
            found[stage].add(origin.relative_to(REPO).as_posix())
    return found


def test_repro_runs_everything_then_nothing(repo_copy, first_run):
    from hnsdt.data.lerobot_io import open_dataset

    ran = ran_stages(first_run[0])
    assert ran == ({"collect@keydoor", "evaluate", "report", "minigrid_reference@doorkey8", "minigrid_collect@doorkey8",
                    "minigrid_learn@doorkey8"}
                   | {f"{STAGES[m]}@keydoor-{m}" for m in STAGES} | UNSEEN_STAGES)
    assert open_dataset(repo_copy / "data/datasets/keydoor").meta.total_episodes == 9
    for method in STAGES:
        assert (repo_copy / f"models/keydoor/{method}/seed0/model.safetensors").is_file()
        assert (repo_copy / f"plots/train/keydoor-{method}/seed0.csv").is_file()
    table = pd.read_csv(repo_copy / "results/episodes.csv", keep_default_na=False)
    assert len(table) == len(METHODS) * 1 * 2 * 1 * 4  # methods x envs x fail_probs x seeds x episodes
    metrics = json.loads((repo_copy / "results/metrics.json").read_text())
    assert metrics["keydoor"]["symbolic"]["fail_0"]["success_mean"] == 1.0
    assert set(metrics["keydoor"]) == set(STAGES) | {m for m, entry in METHODS.items() if entry.training == "none"}
    shown = json.loads(run(["dvc", "metrics", "show", "--json"], repo_copy))  # the headline, declared as metrics
    files = next(iter(shown.values()))["data"]  # (the workspace's: one file per split)
    headline = {Path(path).stem: f["data"] for path, f in files.items() if path.startswith("metrics/headline/")}
    learned = {m for m, entry in METHODS.items() if entry.training != "none"}
    assert set(headline) == {"keydoor", "heldout", "minigrid", "drawn", *(f"{e}.heldout" for e in EXPERIMENTS)}
    assert "symbolic" not in headline["keydoor"]
    assert sum(len(split) for split in headline.values()) <= 45 and set(headline["keydoor"]) >= learned
    printed = run(["dvc", "metrics", "show"], repo_copy)  # as the README shows it: a row per split, within 200
    assert "metrics/headline/keydoor.json" in printed and max(map(len, printed.splitlines())) <= 200, printed
    for name in ("summary.csv", "metrics.json"):  # the git-tracked copies the README's table is made from
        assert (repo_copy / "metrics" / name).read_bytes() == (repo_copy / "results" / name).read_bytes()
    usage = pd.read_csv(repo_copy / "results/training_usage.csv")
    assert set(usage[usage.training == "online"].env_steps) == {400}
    assert (usage[usage.training == "dataset"].dataset_frames > 0).all() and "epoch_kept" in usage.columns
    recorded = table[table.rrd != ""]
    assert len(recorded) == len(METHODS) * 1 * 2 and all((repo_copy / p).is_file() for p in recorded.mcap)
    report = (repo_copy / "report/report.md").read_text()
    lock = yaml.safe_load((repo_copy / "dvc.lock").read_text())
    dataset_md5 = lock["stages"]["collect@keydoor"]["outs"][0]["md5"]
    rev = run(["git", "rev-parse", "--short=12", "HEAD"], repo_copy).strip()
    assert dataset_md5 in report and "figures/comparison.png" in report and f"`{rev}" in report
    assert f"{rev}-dirty" not in report  # the run rewrote dvc.lock, nothing else
    assert (repo_copy / "report/figures/success_heatmap.png").stat().st_size > 10_000
    assert "figures/paradigms.png" in report and "Agreement with the paper's claims" in report
    assert "Where the steps of HNSDT (paper: Move + BFS) go" in report and "| keydoor | 0 | Move |" in report
    assert "The paper's own configuration" in report and (repo_copy / "recordings/foxglove_layout.json").is_file()
    assert "figures/environments.png" in report  # the paper's Figures 2 and 3, from the layout files
    # the unseen-layout experiment: every method (and the reference) on every split, in the report
    unseen = pd.read_csv(repo_copy / "generalisation/results/episodes.csv")
    drawn = len(list((repo_copy / "layouts/drawn").glob("*.txt")))  # the hand-drawn maps, every one evaluated
    assert set(unseen.method) == set(UNSEEN) | {"symbolic"}
    assert set(unseen.split) == {"train", "heldout", "minigrid", "drawn"}
    assert len(unseen) == (len(UNSEEN) + 1) * (3 + drawn) * 2 * 2  # methods x layouts x fail_probs x episodes
    assert "hand-drawn maps: 11 (3–16 × 4–16 cells)" in report and "against the target on maps it never saw" in report
    assert "Per hand-drawn map" in report and "| `spiral_9x9` |" in report
    segments = pd.read_csv(repo_copy / "generalisation/results/segments.csv")  # where HNSDT's steps go, and why
    assert set(segments.method) == {"hnsdt", "symbolic"} and "| hand-drawn maps | Move |" in report
    assert "## Unseen layouts" in report and (repo_copy / "report/figures/generalisation.png").is_file()
    assert "### What each ingredient buys" in report  # the measured variants (benchmarks/results/generalisation.csv)
    assert (repo_copy / "report/figures/scaling.png").is_file() and "![scaling](figures/scaling.png)" in report
    assert lock["stages"]["collect_generalisation"]["outs"][0]["md5"] in report
    for name in EXPERIMENTS:  # each further experiment: its stage's outputs, a section of the report
        more = pd.read_csv(repo_copy / f"generalisation/experiments/{name}/results/episodes.csv")
        assert set(more.split) == {"train", "heldout"} and f"### Unseen layouts, experiment `{name}`" in report
        assert (repo_copy / f"generalisation/experiments/{name}/models/hnsdt/seed0/model.safetensors").is_file()
    assert (repo_copy / "report/figures/environments.png").stat().st_size > 10_000
    # MiniGrid's own worlds: the optimum and the bot on the tiny run's one world, in the report
    assert (repo_copy / "minigrid/doorkey8/reference/summary.csv").is_file()
    assert "## MiniGrid's own worlds" in report and "| MiniGrid-DoorKey-8x8-v0 | 0.2 | 1.000 |" in report
    assert sorted(p.name for p in (repo_copy / "minigrid/doorkey8/recordings").iterdir()) == [
        "babyai_bot_fp0.2.mcap", "babyai_bot_fp0.2.rrd", "symbolic_fp0.2.mcap", "symbolic_fp0.2.rrd"]
    from lerobot.datasets.lerobot_dataset import LeRobotDataset  # (stock, offline: 2 worlds x 1 fail_prob)
    assert LeRobotDataset("local/minigrid-doorkey8", root=repo_copy / "minigrid/doorkey8/dataset").num_episodes == 2
    learned = pd.read_csv(repo_copy / "minigrid/doorkey8/learned/summary.csv")  # every learner, played
    assert set(learned.method) == set(MINIGRID_LEARNERS) and (learned.seeds == 1).all()
    assert (repo_copy / "minigrid/doorkey8/learned/models/hnsdt/seed0/model.safetensors").is_file()
    assert sorted(p.name for p in (repo_copy / "minigrid/doorkey8/learned_recordings").iterdir()) == sorted(
        f"{m}_fp0.2{suffix}" for m in MINIGRID_LEARNERS for suffix in (".mcap", ".rrd"))
    rrds = sorted((repo_copy / "recordings").rglob("*.rrd"))
    verify = subprocess.run([str(Path(sys.executable).parent / "rerun"), "rrd", "verify", *map(str, rrds)],
                            capture_output=True, text=True)  # every recording, by rerun's own verifier
    assert len(rrds) == len(recorded) and verify.returncode == 0, verify.stderr[-2000:]
    run(["dvc", "plots", "show", "-o", "plots_html"], repo_copy)  # offline: Vega inlined, nothing from the web
    page = (repo_copy / "plots_html/index.html").read_text()
    assert page.count("vegaEmbed(") >= 3 and not re.search(r"<script[^>]*\bsrc=", page)
    shutil.rmtree(repo_copy / "plots_html")

    assert ran_stages(run(["dvc", "repro"], repo_copy)) == set()  # nothing changed: nothing reruns
    # a run leaves nothing for git to pick up but its lock file
    status = run(["git", "status", "--porcelain", "--untracked-files=all"], repo_copy).splitlines()
    assert all(kept_in_git(line[3:]) for line in status), status


def test_every_stage_depends_on_the_code_it_runs(repo_copy, first_run):
    """Every hnsdt module that a stage's processes import is among its DVC deps (the file, or a folder holding
    it), so an edit to it reruns the stage; and, for real, editing one module marks the stages that import it."""
    imports = _imports_by_stage(first_run[0])
    lock = yaml.safe_load((repo_copy / "dvc.lock").read_text())["stages"]
    assert imports.keys() == lock.keys()
    for stage, modules in imports.items():
        deps = [d["path"].rstrip("/") for d in lock[stage]["deps"]]
        missing = {m for m in modules if not any(m == d or m.startswith(d + "/") for d in deps)}
        assert not missing, f"stage {stage} runs {sorted(missing)} but does not depend on it"
    module = repo_copy / "hnsdt/data/lerobot_io.py"
    readers = {stage for stage, modules in imports.items() if "hnsdt/data/lerobot_io.py" in modules}
    assert "collect@keydoor" in readers and "train_online@keydoor-dqn" not in readers
    original = module.read_bytes()
    module.write_bytes(original + b"\n# edited\n")
    try:
        changed = changed_stages(repo_copy)
    finally:
        module.write_bytes(original)
    assert readers <= changed and "train_online@keydoor-dqn" not in changed
    # a docstring edited in one experiment's stage module reruns that stage, and the stages that run its code (the
    # further unseen-layout experiments, each collecting, training and evaluating in one stage), nothing else
    for stage_module, stages in [("evaluate_unseen", {"evaluate_generalisation"} | {
            f"unseen_experiment@{name}" for name in EXPERIMENTS}), ("evaluate", {"evaluate"})]:
        module = repo_copy / f"hnsdt/stages/{stage_module}.py"
        original = module.read_text()
        assert original.startswith('"""')
        module.write_text('"""(edited) ' + original[3:])
        try:
            assert changed_stages(repo_copy) == stages
        finally:
            module.write_text(original)
    # Python's bytecode cache, which any import writes beside the code where PYTHONDONTWRITEBYTECODE is not set
    # (as on most machines), changes no stage (.dvcignore)
    (repo_copy / "hnsdt/data/__pycache__").mkdir(exist_ok=True)
    (repo_copy / "hnsdt/data/__pycache__/lerobot_io.cpython-312.pyc").write_bytes(b"bytecode")
    assert changed_stages(repo_copy) == set()


def test_replay_points_to_an_evaluated_episode(repo_copy, tmp_path):
    out = hnsdt_cli("replay", "hnsdt/keydoor/fp0.2/seed0/ep0", cwd=repo_copy)
    assert out.returncode == 0, out.stderr
    assert "recordings/hnsdt/keydoor/fp0.2/seed0/ep0.rrd" in out.stdout and ".mcap" in out.stdout
    # an episode that was not recorded is made again from its checkpoint and seeds and checked against its row
    again = hnsdt_cli("replay", "hnsdt/keydoor/fp0.2/seed0/ep3", "--out", tmp_path / "ep3.rrd", cwd=repo_copy)
    assert again.returncode == 0 and "(the same steps as evaluated)" in again.stdout, again.stderr
    assert (tmp_path / "ep3.rrd").stat().st_size and (tmp_path / "ep3.mcap").stat().st_size
    cell = hnsdt_cli("replay", "*/keydoor/fp0.2/seed0/ep1", "--out", tmp_path / "cell", cwd=repo_copy)  # side by side
    assert cell.returncode == 0 and cell.stdout.count("(the same steps as evaluated)") == len(METHODS), cell.stderr
    assert len(list((tmp_path / "cell").glob("*.mcap"))) == len(METHODS)
    (tmp_path / "changed").mkdir()  # ... and one whose row says otherwise is one error line, and no file
    table = pd.read_csv(repo_copy / "results/episodes.csv", keep_default_na=False)
    table.loc[table.episode_id == "hnsdt/keydoor/fp0.2/seed0/ep3", "steps"] += 1
    table.to_csv(tmp_path / "changed/episodes.csv", index=False)
    wrong = hnsdt_cli("replay", "hnsdt/keydoor/fp0.2/seed0/ep3", "--results", tmp_path / "changed", "--out",
                      tmp_path / "wrong.rrd", cwd=repo_copy)
    assert wrong.returncode == 2 and "changed since that evaluation" in wrong.stderr.splitlines()[-1]
    assert not list(tmp_path.glob("wrong*"))
    cell = hnsdt_cli("replay", "*/keydoor/fp0.2/seed0/ep0", cwd=repo_copy)  # every method's episode of one cell
    assert cell.returncode == 0, cell.stderr
    opened = cell.stdout.splitlines()[-1]
    assert opened.startswith("open with: rerun ") and opened.count(".rrd") == len(METHODS)
    assert "foxglove_layout.json" in opened
    # the unseen-layout experiment's episodes through the same command, by the same kind of id
    unseen = pd.read_csv(repo_copy / "generalisation/results/episodes.csv")
    episode = unseen[(unseen.split == "drawn") & (unseen.method == "hnsdt")].episode_id.iloc[0]
    assert episode.startswith("hnsdt/") and "/" not in unseen[unseen.split == "drawn"].layout.iloc[0]
    drawn = hnsdt_cli("replay", episode, "--experiment", "unseen", "--out", tmp_path / "drawn.rrd", cwd=repo_copy)
    assert drawn.returncode == 0 and "(the same steps as evaluated)" in drawn.stdout, drawn.stderr
    assert f"{episode} (unseen, drawn)" in drawn.stdout and (tmp_path / "drawn.mcap").stat().st_size


def test_an_episode_made_again_is_the_evaluated_one_to_the_bit(repo_copy):
    """`hnsdt replay` of an episode that was not recorded runs its method × env × seed again
    (:func:`rerun_episode`); made so, every method's recorded episode gives the evaluation's own .mcap file (every
    state, action, sub-goal and reward; the .rrd files carry time-based row ids)."""
    import contextlib

    from hnsdt.compose.config import env_spec, evaluate_settings, executor_config, load_params
    from hnsdt.core.methods import ARMS
    from hnsdt.evaluation.paper import Cell, rerun_episode

    with contextlib.chdir(repo_copy):  # (the params' layout paths are the repo's)
        params = load_params("params.yaml")
        settings = evaluate_settings(params)
        envs = {e: env_spec(params, e) for e in settings.envs}
        executors = {arm: executor_config(params, arm) for arm in ARMS}
        for method in settings.methods:
            outcome, files = rerun_episode(settings, envs, executors, "models", Cell(method, "keydoor", 0.2, 0), 0)
            recorded = Path(f"recordings/{method}/keydoor/fp0.2/seed0/ep0.mcap")
            assert files[".mcap"] == recorded.read_bytes(), method
        with pytest.raises(ValueError, match=r"hnsdt/keydoor/fp0.5/seed0/ep0: not an episode of this evaluation"):
            rerun_episode(settings, envs, executors, "models", Cell("hnsdt", "keydoor", 0.5, 0), 0)


def test_the_lock_file_holds_exactly_the_pipelines_stages():
    """No stale entries in this repository's dvc.lock (the report cites it for provenance)."""
    listed = {line.split()[0] for line in run(["dvc", "stage", "list"], REPO).splitlines() if line.strip()}
    assert set(yaml.safe_load((REPO / "dvc.lock").read_text())["stages"]) == listed
