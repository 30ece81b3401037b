"""A user's work on the tiny pipeline's run: the trained models on a folder of their own maps, and an
experiment with one changed knob beside the committed run. On a copy of the run shared with test_pipeline.py
(conftest's ``pipeline_run``; each worker makes its own), handed last, the longer first, to whichever pytest-xdist
worker is free (tests/conftest.py): neither test depends on what the other changes."""

from pathlib import Path

import pandas as pd
import pytest
import yaml

from conftest import hnsdt_cli
from tiny_repo import STAGES, UNSEEN, changed_stages, ran_stages, run

pytestmark = pytest.mark.slow


def _set(repo: Path, section: str, key: str, value) -> None:
    params = yaml.safe_load((repo / "params.yaml").read_text())
    node = params
    for part in section.split("."):
        node = node[part]
    node[key] = value
    (repo / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))


def test_a_changed_knob_reruns_only_the_stages_that_read_it(repo_copy, first_run):
    # the README's compare-two-runs workflow: an experiment with one changed knob beside the committed run
    run(["git", "add", "-A"], repo_copy)  # dvc.lock and the outputs kept in git (the rest: DVC's .gitignore)
    run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "the first run"], repo_copy)
    ran = ran_stages(run(["dvc", "exp", "run", "-S", "evaluate.episodes=5"], repo_copy))
    assert ran == {"evaluate", "report"}
    compared = run(["python", "tools/compare.py"], repo_copy)  # `make compare`: the knob, then what moved
    lines = compared.splitlines()
    assert lines[1].split()[:2] == ["knob", "evaluate.episodes"] and max(map(len, lines)) <= 200, compared
    assert lines[1].split()[-1] == "5", compared  # the experiment's value, in the last column
    diff = run(["dvc", "exp", "diff", "HEAD"], repo_copy)  # the experiment's params and metrics against HEAD
    assert "evaluate.episodes" in diff and all(len(line) <= 120 for line in diff.splitlines()), diff
    params = (repo_copy / "params.yaml").read_text()

    _set(repo_copy, "baselines.dqn", "lr", 0.001)  # one method's knob: only its instances retrain
    assert changed_stages(repo_copy) == {"train_online@keydoor-dqn", "train_generalisation_baselines@dqn"}
    (repo_copy / "params.yaml").write_text(params)

    _set(repo_copy, "envs.keydoor", "max_steps", 60)  # one env's knob: everything on that env
    assert changed_stages(repo_copy) == {"collect@keydoor", "evaluate"} | {
        f"{STAGES[m]}@keydoor-{m}" for m in STAGES}


def test_the_trained_models_run_on_a_folder_of_a_users_maps(tmp_path, repo_copy, first_run):
    """`hnsdt generalisation evaluate --drawn FOLDER --splits drawn`: the pipeline's trained models on maps a user
    drew, as the split `drawn` alone; then one of those episodes made again and recorded (`hnsdt replay`);
    the pipeline's outputs untouched."""
    (tmp_path / "mine").mkdir()
    corridor = tmp_path / "mine/long_corridor.txt"
    corridor.write_text("@.........a\n#########A#\nG..........\n")
    before = (repo_copy / "generalisation/results/summary.csv").read_bytes()
    out = hnsdt_cli("generalisation", "evaluate", "--drawn", tmp_path / "mine", "--splits", "drawn", "--out",
                    tmp_path / "results", "--quiet", cwd=repo_copy)
    assert out.returncode == 0, out.stderr
    drawn = pd.read_csv(tmp_path / "results/episodes.csv")
    assert set(drawn.split) == {"drawn"} and set(drawn.layout) == {"long_corridor"}
    assert set(drawn.method) == set(UNSEEN) | {"symbolic"} and drawn[drawn.method == "symbolic"].success.all()
    again = hnsdt_cli("replay", "hnsdt/long_corridor/fp0.2/seed0/ep1", "--drawn", tmp_path / "mine", "--results",
                      tmp_path / "results", "--out", tmp_path / "ep.rrd", cwd=repo_copy)
    assert again.returncode == 0 and "the same steps as evaluated" in again.stdout, again.stderr
    assert (tmp_path / "ep.mcap").stat().st_size
    assert (repo_copy / "generalisation/results/summary.csv").read_bytes() == before
