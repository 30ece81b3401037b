"""Bad input, end to end through the `hnsdt` command: each case exits with status 2, prints exactly one line
naming the problem, and leaves no output behind (the README lists what is checked)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import REPO
from conftest import hnsdt_cli as hnsdt  # in-process; test_cli.py runs the command as a fresh process

PARAMS = yaml.safe_load(Path(REPO, "params.yaml").read_text())


def assert_one_error_line(out, match: str) -> None:
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2, out.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("hnsdt: error:"), out.stderr[-2000:]
    assert match in lines[0], lines[0]


def small_params(**edits) -> dict:
    """Case 1 only, HNSDT and the symbolic planner, one seed: what the dataset and checkpoint cases run."""
    p = json.loads(json.dumps(PARAMS))
    p["envs"] = {"keydoor": p["envs"]["keydoor"]}
    p["envs"]["keydoor"]["layout"] = str(Path(REPO, p["envs"]["keydoor"]["layout"]))
    p["collect"]["fail_probs"] = [0.1]
    for b in p["collect"]["behaviours"]:
        b["episodes"] = 2
    p["train"].update(envs=["keydoor"], methods=["hnsdt"], seeds=[0], epochs=2, max_steps=0)  # 2: split in halves
    p["baselines"].update(offline=[], online=[])
    p["evaluate"].update(methods=["symbolic", "hnsdt"], episodes=2, fail_probs=[0.1])
    p["compute"]["workers"] = 1  # runs in the test's process: a pool's workers would each import torch (seconds)
    # for a second of work (the pool's own bytes and errors: tests/test_train_cli.py, tests/test_fit.py)
    for dotted, value in edits.items():
        node = p
        *parents, key = dotted.split(".")
        for part in parents:
            node = node[int(part)] if isinstance(node, list) else node[part]
        if value is DELETE:
            del node[key]
        else:
            node[key] = value
    return p


DELETE = object()


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A folder with small params, a collected Case 1 dataset and a trained HNSDT seed-0 checkpoint."""
    root = tmp_path_factory.mktemp("bad-input")
    (root / "params.yaml").write_text(yaml.safe_dump(small_params(), sort_keys=False))
    for args in (["collect", "--env", "keydoor", "--out", root / "data/datasets/keydoor", "--quiet"],
                 ["train", "--env", "keydoor", "--method", "hnsdt", "--quiet",
                  "--dataset", root / "data/datasets/keydoor", "--out", root / "models/keydoor/hnsdt",
                  "--curves", root / "curves"]):
        out = hnsdt(*args, cwd=root)
        assert out.returncode == 0, out.stderr[-2000:]
    return root


def _case_dir(workdir: Path, tmp_path: Path) -> Path:
    """A private copy of the work folder, so a case's corruption stays its own."""
    dst = tmp_path / "w"
    shutil.copytree(workdir, dst)
    return dst


def _outputs(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


# --- params: (edits, command, expected words) -------------------------------------------------------------
COLLECT = ["collect", "--env", "keydoor", "--out", "out", "--quiet"]
EVALUATE = ["evaluate", "--out", "res", "--recordings", "rec", "--quiet"]
PARAM_CASES = {
    "wrong type": ({"envs.keydoor.max_steps": "ten"}, COLLECT, "envs.keydoor.max_steps: Input should be a valid integer"),
    "unknown top-level key": ({"colect": {"seed": 1}}, COLLECT, "unknown section(s) ['colect']"),
    "unknown behaviour key": ({"collect.behaviours.0.episods": 3}, COLLECT, "unknown key collect.behaviours.0.episods"),
    "negative episodes": ({"collect.behaviours.0.episodes": -5}, COLLECT, "collect.behaviours.0.episodes: Input should be greater than or equal to 0, got -5"),
    "fail_prob above 1": ({"collect.fail_probs": [0.1, 1.5]}, COLLECT, "collect.fail_probs"),
    "fail_prob below 0": ({"evaluate.fail_probs": [-0.1]}, EVALUATE, "evaluate.fail_probs"),
    "unknown env id": ({"envs.keydoor.id": "hnsdt/Nope-v0"}, COLLECT, "not a registered id"),
    "unknown method": ({"evaluate.methods": ["symbolic", "sac"]}, EVALUATE, "evaluate.methods.1: Input should be 'lstm_hier'"),
    "unknown behaviour policy": ({"collect.behaviours.0.policy": "teleport"}, COLLECT, "collect.behaviours.0.policy: Input should be 'random' or 'noisy_planner', got 'teleport'"),
    "unknown executor mode": ({"planner.mode": "astar"}, COLLECT, "planner.mode: Input should be 'bfs' or 'cost'"),
    "unknown operator set": ({"planner.operators": "teleport"}, COLLECT, "planner.operators: Input should be"),
    "negative render size": ({"collect.render": -4}, COLLECT, "collect.render: Input should be greater than or equal to 0"),
    "render too narrow for the video encoder": ({"collect.render": 4}, COLLECT,
                                                "collect.render: 4 pixels per cell draw layout"),
    "unknown paper-arm operators": ({"planner.paper.operators": "jump"}, EVALUATE,
                                    "planner.paper.operators: Input should be"),
    "unknown arm": ({"planner.papr": {"mode": "bfs"}}, COLLECT, "unknown key planner.papr"),
    "empty seed list": ({"train.seeds": []}, EVALUATE, "train.seeds"),
    "missing section": ({"collect": DELETE}, COLLECT, "missing key collect"),
    "unknown executor": ({"compute.executor": "slurm"}, EVALUATE, "compute.executor: Input should be 'local' or 'ray'"),
    "zero threads": ({"compute.threads": 0}, EVALUATE, "compute.threads: Input should be greater than or equal to 1"),
}


@pytest.mark.parametrize("edits, command, match", PARAM_CASES.values(), ids=PARAM_CASES.keys())
def test_bad_params(tmp_path, edits, command, match):
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(small_params(**edits), sort_keys=False))
    out = hnsdt(*command, cwd=tmp_path)
    assert_one_error_line(out, match)
    assert _outputs(tmp_path) == {"params.yaml"}


# --- layout files: (text, expected words) -----------------------------------------------------------------
LAYOUT_CASES = {
    "ragged rows": ("@..G\n...\n", "rectangular"),
    "no start": ("....\n.a.G\n", "no start"),
    "two starts": ("@..G\n@...\n", "more than one start"),
    "door without its key": ("@.B.G\n", "no key"),
    "unreachable exit": ("@.#G\n..#.\n", "no path"),
    "unreachable item": ("@..G\n###.\n1#..\n", "item"),
    "unknown character": ("@.?G\n", "unknown character"),
    "empty file": ("", "empty"),
}


@pytest.mark.parametrize("text, match", LAYOUT_CASES.values(), ids=LAYOUT_CASES.keys())
def test_bad_layout_files(tmp_path, text, match):
    layout = tmp_path / "bad_layout.txt"
    layout.write_text(text)
    out = hnsdt("pddl", "--env", "hnsdt/KeyDoor-v0", "--layout", layout, "--out", tmp_path / "pddl", cwd=tmp_path)
    assert_one_error_line(out, match)
    assert _outputs(tmp_path) == {"bad_layout.txt"}


# --- datasets: (corruption, expected words) ---------------------------------------------------------------
def _drop_info(ds: Path) -> None:
    (ds / "meta/info.json").unlink()


def _truncate_parquet(ds: Path) -> None:
    data = sorted((ds / "data").rglob("*.parquet"))[0]
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])


def _flip_one_bit(f: Path, at: int) -> None:
    data = bytearray(f.read_bytes())
    data[at] ^= 0x01
    f.write_bytes(bytes(data))


def _flip_a_data_bit(ds: Path) -> None:
    data = sorted((ds / "data").rglob("*.parquet"))[0]
    _flip_one_bit(data, data.stat().st_size // 2)


def _wrong_dtype(ds: Path) -> None:
    info = json.loads((ds / "meta/info.json").read_text())
    info["features"]["action"]["dtype"] = "float32"
    (ds / "meta/info.json").write_text(json.dumps(info))


def _zero_episodes(ds: Path) -> None:
    info = json.loads((ds / "meta/info.json").read_text())
    info["total_episodes"] = 0
    (ds / "meta/info.json").write_text(json.dumps(info))


DATASET_CASES = {
    "missing meta/info.json": (_drop_info, "missing meta/info.json"),
    "truncated parquet": (_truncate_parquet, "its data files are damaged"),
    "one bit flipped in a parquet file": (_flip_a_data_bit, "its data files are damaged (their md5 is not"),
    "feature with the wrong dtype": (_wrong_dtype, "feature 'action' has dtype float32, expected int64"),
    "zero episodes": (_zero_episodes, "no episodes"),
}


TRAIN = ["train", "--env", "keydoor", "--method", "hnsdt", "--seed", "1", "--quiet", "--out", "m", "--curves", "c",
         "--dataset", "data/datasets/keydoor"]


@pytest.mark.parametrize("corrupt, match", DATASET_CASES.values(), ids=DATASET_CASES.keys())
def test_bad_datasets(workdir, tmp_path, corrupt, match):
    _run_corrupted(workdir, tmp_path, lambda w: corrupt(w / "data/datasets/keydoor"), TRAIN, match)


def _run_corrupted(workdir: Path, tmp_path: Path, corrupt, command: list, match: str) -> None:
    """Corrupt a private copy of the work folder, run the command there: one error line, nothing written."""
    w = _case_dir(workdir, tmp_path)
    corrupt(w)
    before = _outputs(w)
    assert_one_error_line(hnsdt(*command, cwd=w), match)
    assert _outputs(w) == before


# --- checkpoints: (corruption or params edit, expected words) ---------------------------------------------
def _truncate_weights(models: Path) -> None:
    f = models / "keydoor/hnsdt/seed0/model.safetensors"
    f.write_bytes(f.read_bytes()[:100])


def _flip_a_weight_bit(models: Path) -> None:  # (a float's low bit: it loads, and acts almost alike)
    f = models / "keydoor/hnsdt/seed0/model.safetensors"
    _flip_one_bit(f, f.stat().st_size - 8)


def _mismatched_config(models: Path) -> None:
    f = models / "keydoor/hnsdt/seed0/config.json"
    meta = json.loads(f.read_text())
    meta["model"]["d_model"] = 64
    f.write_text(json.dumps(meta))


def _missing_seed(models: Path) -> None:
    shutil.rmtree(models / "keydoor/hnsdt/seed0")


CHECKPOINT_CASES = {
    "truncated safetensors": (_truncate_weights, "model.safetensors is damaged"),
    "one bit flipped in model.safetensors": (_flip_a_weight_bit, "model.safetensors is damaged (its sha256 is not"),
    "config that does not match the weights": (_mismatched_config, "do not match"),
    "missing seed": (_missing_seed, "seed0: missing model.safetensors"),
}


@pytest.mark.parametrize("corrupt, match", CHECKPOINT_CASES.values(), ids=CHECKPOINT_CASES.keys())
def test_bad_checkpoints(workdir, tmp_path, corrupt, match):
    _run_corrupted(workdir, tmp_path, lambda w: corrupt(w / "models"), EVALUATE, match)


def test_replay_of_an_episode_that_does_not_exist(workdir, tmp_path):
    w = _case_dir(workdir, tmp_path)
    assert hnsdt("evaluate", "--quiet", cwd=w).returncode == 0
    before = _outputs(w)
    out = hnsdt("replay", "hnsdt/keydoor/fp0.1/seed0/ep99", cwd=w)
    assert_one_error_line(out, "no episode 'hnsdt/keydoor/fp0.1/seed0/ep99'")
    assert _outputs(w) == before


def _truncate(f: Path) -> None:
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])


def _flip_a_third_in(f: Path) -> None:
    _flip_one_bit(f, f.stat().st_size // 3)


@pytest.mark.parametrize("suffix, damage", [(".rrd", _truncate), (".mcap", _flip_a_third_in)],
                         ids=["truncated rrd", "one bit flipped in an mcap"])
def test_replay_of_a_damaged_recording(workdir, tmp_path, suffix, damage):
    """A damaged kept recording: replay names it and what to run, instead of handing it out. (An .rrd has no
    checksum: `rerun rrd verify` finds a truncation or a broken record, not a bit flipped inside an image.)"""
    w = _case_dir(workdir, tmp_path)
    assert hnsdt("evaluate", "--quiet", cwd=w).returncode == 0
    recording = (w / "recordings/hnsdt/keydoor/fp0.1/seed0/ep0").with_suffix(suffix)
    assert hnsdt("replay", "hnsdt/keydoor/fp0.1/seed0/ep0", cwd=w).returncode == 0  # intact: handed out
    damage(recording)
    out = hnsdt("replay", "hnsdt/keydoor/fp0.1/seed0/ep0", cwd=w)
    assert_one_error_line(out, f"recording recordings/hnsdt/keydoor/fp0.1/seed0/ep0{suffix} is damaged")


def test_a_dataset_without_an_operator_s_segments_stops_training(tmp_path):
    """The paper's HNSDT learns from random exploration only: a dataset with none cannot teach it PickKey,
    OpenDoor or Move, and training says so before it starts."""
    params = small_params(**{"collect.behaviours.0.episodes": 0, "train.methods": ["hnsdt_paper"]})
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    assert hnsdt(*COLLECT[:3], "--out", "data", "--quiet", cwd=tmp_path).returncode == 0
    before = _outputs(tmp_path)
    out = hnsdt("train", "--env", "keydoor", "--method", "hnsdt_paper", "--quiet", "--dataset", "data", "--out", "m",
                "--curves", "c", cwd=tmp_path)
    assert_one_error_line(out, "give no segment of PickKey(a), OpenDoor(A), Move")
    assert _outputs(tmp_path) == before


def test_the_table_has_at_least_twenty_cases():
    assert len(PARAM_CASES) + len(LAYOUT_CASES) + len(DATASET_CASES) + len(CHECKPOINT_CASES) + 1 >= 20


@pytest.mark.parametrize("name, cut, recovery", [
    ("dvc.lock", "schema: '2.0'\nstages:\n  collect@keydoor:\n    cmd: 'python pipe", "git checkout dvc.lock"),
    ("dvc.lock", "schema: '2.0'\nstages:\n  collect@keydoor:\n", "git checkout dvc.lock"),
    (".dvc/tmp/rwlock", '{"write": {"/repo/data/datasets/keydoor": {"pid": 12', "rm .dvc/tmp/rwlock"),
])
def test_a_dvc_lock_file_cut_short_stops_make_pipeline_in_one_line(tmp_path, name, cut, recovery):
    """What a run killed while DVC rewrote one of its lock files in place leaves (the soak found both): `make
    pipeline`'s check (tools/check_locks.py) names the file and its recovery; whole files pass."""
    check = [sys.executable, str(Path(REPO, "tools/check_locks.py"))]
    (tmp_path / ".dvc/tmp").mkdir(parents=True)
    shutil.copy(Path(REPO, "dvc.lock"), tmp_path / "dvc.lock")
    (tmp_path / ".dvc/tmp/rwlock").write_text('{"write": {}, "read": {}}')
    assert subprocess.run(check, cwd=tmp_path, capture_output=True).returncode == 0
    (tmp_path / name).write_text(cut)
    out = subprocess.run(check, cwd=tmp_path, capture_output=True, text=True)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert f"{name} is damaged" in lines[0] and recovery in lines[0], lines[0]
