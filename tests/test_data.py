import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from conftest import REPO, hnsdt_cli
from hnsdt.data.collect import Behaviour, CollectConfig, collect_dataset, random_start_states
from hnsdt.data.lerobot_io import DatasetError, check_dataset, episode_table, open_dataset
from hnsdt.data.segmentation import hindsight_labels, segments_of
from hnsdt.symbolic import NAME_TO_ID


def test_hindsight_labels_end_segments_where_effects_are_gained(keydoor):
    states = np.array([[2, 0, 0, 0], [3, 0, 0, 0], [4, 0, 0, 0], [4, 0, 1, 0], [3, 0, 1, 0], [3, 1, 1, 0]])
    ids, targets = hindsight_labels(keydoor, states)
    assert [int(i) for i in ids] == [NAME_TO_ID["GoTo(key a)"]] * 2 + [NAME_TO_ID["PickKey(a)"]] + [0, 0]
    assert targets[0].tolist() == [4, 0] and targets[-1].tolist() == [-1, -1]
    assert segments_of(ids) == [(NAME_TO_ID["GoTo(key a)"], 0, 2), (NAME_TO_ID["PickKey(a)"], 2, 3), (0, 3, 5)]


def test_random_start_states_never_trap(multikeydoor, rng):
    states = random_start_states(multikeydoor, 500, rng)
    door_cells = {tuple(c): j for j, c in enumerate(multikeydoor.doors.values())}
    for s in states:
        cell = (s[0], s[1])
        assert not multikeydoor.walls[cell] and cell != multikeydoor.goal
        if cell in door_cells:
            assert s[2 + len(multikeydoor.keys) + door_cells[cell]] == 1


def _small_config(layout, seed=0):
    return CollectConfig("hnsdt/MultiKeyDoor-v0", layout, 60, [0.0, 0.2],
                         [Behaviour("random", 4, "random"), Behaviour("noisy_planner", 6, "layout", 0.1)], seed=seed)


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory, multikeydoor):
    root = tmp_path_factory.mktemp("ds") / "multi"
    collect_dataset(_small_config(multikeydoor), root, "local/multi", progress=False)
    return root


def test_the_same_collection_gives_the_same_bytes_naming_no_revision(small_dataset, multikeydoor, tmp_path):
    """A dataset's files are the same bytes on every run of the same collection: nothing in them names the code
    revision or the run (the revision lives in dvc.lock and the report), so a rerun changes no downstream hash."""
    from hnsdt.core.provenance import git_revision

    again = tmp_path / "multi"
    collect_dataset(_small_config(multikeydoor), again, "local/multi", progress=False)
    files = sorted(p.relative_to(small_dataset) for p in small_dataset.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert [f for f in files if (small_dataset / f).read_bytes() != (again / f).read_bytes()] == []
    revision = git_revision().removesuffix("-dirty").encode()
    assert [f for f in files if revision in (small_dataset / f).read_bytes()] == []


def test_training_reads_the_frames_stock_lerobot_loads(small_dataset):
    """hnsdt.data.format.frame_columns (pyarrow, no lerobot import) gives every frame column exactly as the
    Arrow table of stock LeRobotDataset: the same values, dtypes and order."""
    from hnsdt.data.features import REQUIRED_DTYPES
    from hnsdt.data.format import frame_columns

    names = [*REQUIRED_DTYPES, "episode_index", "frame_index"]
    ours = frame_columns(small_dataset, names)
    theirs = LeRobotDataset("local/multi", root=small_dataset).hf_dataset.with_format("numpy")[:]
    for name in names:
        expected = np.stack(theirs[name]) if theirs[name].dtype == object else np.asarray(theirs[name])
        expected = expected[:, 0] if expected.ndim == 2 and expected.shape[1] == 1 else expected
        assert ours[name].dtype == expected.dtype and np.array_equal(ours[name], expected), name


def test_round_trip_through_stock_lerobot(small_dataset, multikeydoor):
    ds = LeRobotDataset("local/multi", root=small_dataset)
    table = episode_table(small_dataset)
    assert ds.meta.total_episodes == len(table) == 10
    assert ds.meta.info.codebase_version == "v3.0"
    assert ds.features["observation.state"]["names"] == multikeydoor.state_names
    frame = ds[0]
    first = frame["observation.state"].tolist()
    if table.loc[0, "start"] == "layout":
        assert first == [*multikeydoor.start, *[0] * multikeydoor.n_flags]
    else:  # a random start: a free cell that is not the exit, flags drawn at random (0/1)
        assert tuple(first[:2]) in {tuple(c) for c in multikeydoor.free_cells()} - {multikeydoor.goal}
        assert set(first[2:]) <= {0, 1}
    from hnsdt.data.features import REQUIRED_DTYPES
    from hnsdt.data.lerobot_io import dataset_features

    assert {k: v["dtype"] for k, v in dataset_features(multikeydoor).items() if k in REQUIRED_DTYPES} == REQUIRED_DTYPES
    assert frame["task"] in json.loads((small_dataset / "meta/hnsdt.json").read_text())["subgoal_vocabulary"]
    # Frames are the collected transitions: each next state follows from the dynamics, tasks match sub-goal ids.
    vocab = json.loads((small_dataset / "meta/hnsdt.json").read_text())["subgoal_vocabulary"]
    hf = ds.hf_dataset.with_format("numpy")[:]
    tasks = ds.meta.tasks.reset_index().set_index("task_index")["task"]
    for i in range(len(ds)):
        assert tasks[int(hf["task_index"][i])] == vocab[int(np.ravel(hf["subgoal"][i])[0])]
    # Episode metadata: env, layout, fail_prob, seed, behaviour.
    assert set(table.columns) >= {"env_id", "layout", "fail_prob", "seed", "policy", "behaviour", "success"}
    assert sorted(table.fail_prob.unique()) == [0.0, 0.2]
    planner = table[table.policy == "noisy_planner"]
    assert planner.success.all()  # epsilon 0.1 with replanning still always succeeds in 60 steps


def test_context_windows_via_delta_timestamps(small_dataset):
    h = 4
    ds = LeRobotDataset("local/multi", root=small_dataset,
                        delta_timestamps={"observation.state": [-k / 10 for k in range(h, -1, -1)],
                                          "action": [-k / 10 for k in range(h, 0, -1)]})
    first, later = ds[0], ds[h + 2]
    assert first["observation.state"].shape == (h + 1, 8)
    assert first["observation.state_is_pad"].tolist() == [True] * h + [False]
    assert not later["observation.state_is_pad"].any()
    plain = LeRobotDataset("local/multi", root=small_dataset)
    assert later["observation.state"][-1].tolist() == plain[h + 2]["observation.state"].tolist()
    assert later["action"][-1].item() == plain[h + 1]["action"].item()


def _effect(name: str, target) -> str:
    if name == "GoTo(exit)":
        return "Done"
    if name.startswith("GoTo"):
        return f"At({target[0]},{target[1]})"
    kind, obj = name[:-1].split("(")
    return {"PickKey": "HasKey", "OpenDoor": "DoorOpen", "PickItem": "HasItem"}[kind] + f"({obj})"


def test_subgoal_segments_end_where_effects_are_gained(small_dataset, multikeydoor):
    from hnsdt.symbolic.abstraction import SymbolicState

    ds = open_dataset(small_dataset)
    policy = episode_table(small_dataset).set_index("episode_index")["policy"]
    hf = ds.hf_dataset.with_format("numpy")[:]
    states, subgoals = hf["observation.state"], np.ravel(hf["subgoal"])
    targets, eps = hf["subgoal.target"], hf["episode_index"]
    vocab = json.loads((small_dataset / "meta/hnsdt.json").read_text())["subgoal_vocabulary"]
    ends = {"random": [], "noisy_planner": []}
    for t in range(len(states)):
        last_of_episode = t == len(states) - 1 or eps[t] != eps[t + 1]
        if subgoals[t] == 0 or (not last_of_episode and subgoals[t] == subgoals[t + 1]):
            continue
        after = states[t] if last_of_episode else states[t + 1]
        if last_of_episode:  # the episode's final transition: its next state is not stored as a frame
            continue
        preds = SymbolicState.from_observation(multikeydoor, after).predicates(multikeydoor)
        ends[policy[int(eps[t])]].append(_effect(vocab[subgoals[t]], targets[t]) in preds)
    assert ends["random"] and all(ends["random"])  # hindsight: a segment ends exactly where its effect holds
    assert ends["noisy_planner"] and np.mean(ends["noisy_planner"]) > 0.8  # the rest are replans


def test_same_seed_same_files(tmp_path):
    params = tmp_path / "params.yaml"
    small = yaml.safe_load(open(REPO + "/params.yaml"))
    for behaviour in small["collect"]["behaviours"]:
        behaviour["episodes"] = 4  # built in code: a format change cannot silently run this at full size
    params.write_text(yaml.safe_dump(small))
    outs = []
    for run in ("a", "b"):
        out = tmp_path / run
        done = hnsdt_cli("--params", params, "collect", "--env", "keydoor", "--out", out, "--quiet")
        assert done.returncode == 0, done.stderr
        outs.append(out)
    files = sorted(p.relative_to(outs[0]) for p in outs[0].rglob("*") if p.is_file())
    assert files and files == sorted(p.relative_to(outs[1]) for p in outs[1].rglob("*") if p.is_file())
    for rel in files:
        assert (outs[0] / rel).read_bytes() == (outs[1] / rel).read_bytes(), rel


def test_corrupt_or_missing_datasets_fail_clearly(small_dataset, tmp_path):
    import shutil

    with pytest.raises(DatasetError, match="no such folder"):
        check_dataset(tmp_path / "nothing")
    broken = tmp_path / "broken"
    shutil.copytree(small_dataset, broken)
    (broken / "meta/hnsdt_episodes.parquet").unlink()
    with pytest.raises(DatasetError, match="missing meta/hnsdt_episodes.parquet"):
        check_dataset(broken)
    shutil.rmtree(broken)
    shutil.copytree(small_dataset, broken)
    (broken / "meta/info.json").write_text("{ not json")
    with pytest.raises(DatasetError, match="corrupt JSON"):
        open_dataset(broken)
    shutil.rmtree(broken)
    shutil.copytree(small_dataset, broken)
    for f in (broken / "data").rglob("*.parquet"):
        f.write_bytes(b"garbage")
    with pytest.raises(DatasetError, match="LeRobot cannot read it"):
        open_dataset(broken)


def test_the_card_follows_the_hub_and_lerobot_conventions(small_dataset):
    from huggingface_hub import DatasetCard

    from hnsdt.data.card import BIBTEX, data_md5
    from hnsdt.data.features import FEATURES

    text = (small_dataset / "README.md").read_text()
    card = DatasetCard(text)
    assert card.data.license == "apache-2.0" and card.data.task_categories == ["robotics"]
    assert {"LeRobot", "MultiKeyDoor-v0"} <= set(card.data.tags)
    pattern = card.data.configs[0]["data_files"]
    assert list(small_dataset.glob(pattern)), f"the card's data_files {pattern} match no file"
    info = json.loads((small_dataset / "meta/info.json").read_text())
    documented = {f.name for f in FEATURES}
    assert set(info["features"]) - {"timestamp", "frame_index", "episode_index", "index", "task_index"} <= documented
    assert all(f"| `{name}` |" in text for name in documented & (set(info["features"]) | {"task"}))
    assert "| `observation.image` |" not in text  # not rendered: not described
    assert BIBTEX in text and data_md5(small_dataset) in text and "name no code revision" in text
    meta = json.loads((small_dataset / "meta/hnsdt.json").read_text())
    assert meta["data_md5"] == data_md5(small_dataset) and meta["card"]["license"] == "apache-2.0"


def test_push_lists_what_it_would_upload_and_fails_offline_with_one_line(small_dataset, tmp_path, capsys,
                                                                         monkeypatch):
    import shutil

    from hnsdt.cli import main

    root = tmp_path / "ds"
    shutil.copytree(small_dataset, root)
    before = sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())
    args = ["dataset", "push", "multikeydoor", "--root", str(root), "--repo-id", "someone/multikeydoor"]
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")  # in this process: nothing may reach the Hub
    assert main([*args, "--dry-run"]) == 0  # (in-process: the listing and the bad id need no fresh import)
    listed = [line.strip() for line in capsys.readouterr().out.splitlines() if line.startswith("  ")]
    assert listed == before and "README.md" in listed and "meta/info.json" in listed
    assert main([*args[:-1], "multikeydoor"]) == 2 and "--repo-id must be OWNER/NAME" in capsys.readouterr().err
    cmd = [sys.executable, "-m", "hnsdt.cli", *args]  # the Hub library reads HF_HUB_OFFLINE when imported
    offline = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, env=dict(os.environ, HF_HUB_OFFLINE="1"))
    lines = offline.stderr.strip().splitlines()
    assert offline.returncode == 2 and lines == ["hnsdt: error: cannot push to the Hugging Face Hub: HF_HUB_OFFLINE "
                                                 "is set"], offline.stderr
    assert sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file()) == before


@pytest.mark.slow  # (an end-to-end run: tests/conftest.py, pyproject.toml's markers)
def test_rendered_frames_load_in_stock_lerobot_and_its_visualizer(tmp_path, keydoor):
    """`collect.render`: the grid of every frame as video, which lerobot-dataset-viz turns into a recording."""
    from hnsdt.envs.render import render_rgb

    cfg = CollectConfig("hnsdt/KeyDoor-v0", keydoor, 30, [0.0], [Behaviour("noisy_planner", 2, "layout", 0.1)],
                        render=8)
    root = collect_dataset(cfg, tmp_path / "ds", "local/rendered", progress=False)
    ds = LeRobotDataset("local/rendered", root=root)
    assert ds.meta.video_keys == ["observation.image"]
    frame = ds[5]
    image = (frame["observation.image"].permute(1, 2, 0).numpy() * 255).round()
    drawn = render_rgb(keydoor, frame["observation.state"].numpy(), 8).astype(float)
    assert image.shape == drawn.shape == (40, 40, 3)
    assert np.abs(image - drawn).mean() < 8  # lossy video, but the same picture
    assert "| `observation.image` |" in (root / "README.md").read_text()
    out = subprocess.run([str(Path(sys.executable).parent / "lerobot-dataset-viz"), "--repo-id", "local/rendered",
                          "--root", str(root), "--episode-index", "1", "--save", "1", "--output-dir",
                          str(tmp_path / "viz")], capture_output=True, text=True, env=dict(os.environ, HF_HUB_OFFLINE="1"))
    assert out.returncode == 0, out.stderr[-2000:]
    rrd = list((tmp_path / "viz").glob("*.rrd"))
    assert len(rrd) == 1 and rrd[0].stat().st_size > 10_000
    shown = subprocess.run([str(Path(sys.executable).parent / "rerun"), "rrd", "print", str(rrd[0])],
                           capture_output=True, text=True)
    assert "observation.image" in shown.stdout + shown.stderr


def test_the_docs_dataset_snippets_load_a_dataset_without_noise(small_dataset, tmp_path):
    """The README's and docs/datasets.md's stock-LeRobot snippets, run as a user would (a fresh process), load a
    collected dataset and print nothing on stderr (LeRobot's default video backend, torchcodec, prints ~100 lines
    of tracebacks where FFmpeg's shared libraries are missing)."""
    import re

    for page in ("README.md", "docs/datasets.md"):
        blocks = re.findall(r"```python\n(.*?)```", (Path(REPO) / page).read_text(), re.S)
        snippet = next(b for b in blocks if "LeRobotDataset(" in b)
        code = snippet.replace("data/datasets/keydoor", str(small_dataset)) + "\nprint(len(ds))\n"
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                             env={**os.environ, "HF_HOME": str(tmp_path / "hf")})
        assert out.returncode == 0 and int(out.stdout.split()[-1]) > 0, (page, out.stderr[-2000:])
        assert out.stderr == "", (page, out.stderr[:2000])
