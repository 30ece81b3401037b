import subprocess
import sys

import pytest
import yaml

from conftest import REPO, hnsdt_cli


def hnsdt(*args, cwd=REPO):
    """The entry point itself, in a fresh process (the tests of what a command says run it in this one: hnsdt_cli,
    without a second's imports each)."""
    return subprocess.run([sys.executable, "-m", "hnsdt.cli", *args], cwd=cwd, capture_output=True, text=True)


def test_plan_prints_operators_and_subgoals():
    out = hnsdt("plan", "--env", "keydoor")
    assert out.returncode == 0, out.stderr
    assert "GoTo(key a)" in out.stdout and "OpenDoor(A)" in out.stdout
    assert "5 operators, cost 14 steps" in out.stdout


def test_plan_from_a_given_state():
    out = hnsdt("plan", "--env", "hnsdt/KeyDoor-v0", "--state", "4,0,1,0")
    assert out.returncode == 0 and "PickKey" not in out.stdout and "3 operators" in out.stdout


def test_help_explains_itself():
    out = hnsdt("--help")
    assert out.returncode == 0 and "plan" in out.stdout and "collect" in out.stdout and "pddl" in out.stdout


BAD_PARAMS = [
    ("envs: [unclosed", "not valid YAML"),
    ("envs:\n  keydoor:\n    id: hnsdt/Nope-v0\n    layout: keydoor_5x5\n    max_steps: 10\n", "not a registered id"),
    ("envs:\n  keydoor:\n    id: hnsdt/KeyDoor-v0\n    layout: '@a#G'\n    max_steps: 10\n", "no path"),
    ("envs:\n  keydoor:\n    id: hnsdt/KeyDoor-v0\n    layout: keydoor_5x5\n    max_steps: ten\n",
     "envs.keydoor.max_steps: Input should be a valid integer"),
]


@pytest.mark.parametrize("text,match", BAD_PARAMS)
def test_bad_params_give_one_error_line_and_no_output(tmp_path, text, match):
    params = tmp_path / "params.yaml"
    params.write_text(text + "collect:\n  seed: 0\n  fail_probs: [0.1]\n  behaviours: []\n")
    out_dir = tmp_path / "out"
    run = hnsdt if (text, match) == BAD_PARAMS[0] else hnsdt_cli  # one through a real process's exit and stderr
    out = run("--params", str(params), "collect", "--env", "keydoor", "--out", str(out_dir))
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hnsdt: error:") and match in lines[0], out.stderr
    assert not out_dir.exists() and list(tmp_path.iterdir()) == [params]


def test_unknown_behaviour_policy(tmp_path):
    params_dict = yaml.safe_load(open(f"{REPO}/params.yaml"))
    params_dict["collect"]["behaviours"][0]["policy"] = "teleport"  # built in code, not by editing the text
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(params_dict))
    out = hnsdt_cli("--params", str(params), "collect", "--env", "keydoor", "--out", str(tmp_path / "o"))
    assert out.returncode == 2 and "collect.behaviours.0.policy: Input should be 'random' or 'noisy_planner'" in out.stderr


def test_unknown_env_name():
    out = hnsdt_cli("plan", "--env", "nowhere")
    assert out.returncode == 2 and "unknown env 'nowhere'" in out.stderr


def test_the_debug_switch_shows_the_traceback_behind_the_one_line(tmp_path, monkeypatch):
    params = tmp_path / "params.yaml"
    params.write_text(BAD_PARAMS[3][0])
    args = ("--params", str(params), "collect", "--env", "keydoor", "--out", str(tmp_path / "out"))
    monkeypatch.delenv("HNSDT_DEBUG", raising=False)
    quiet = hnsdt_cli(*args)
    monkeypatch.setenv("HNSDT_DEBUG", "1")
    loud = hnsdt_cli(*args)
    assert quiet.returncode == loud.returncode == 2 and "Traceback" not in quiet.stderr
    first, *rest = loud.stderr.splitlines()
    assert first == quiet.stderr.strip() and rest[0].startswith("Traceback") and "ParamsError" in rest[-1]
    assert not (tmp_path / "out").exists()
