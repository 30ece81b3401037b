"""Episodes on MiniGrid's own worlds (:mod:`hnsdt.minigrid.collect`) as LeRobot v3.0 datasets, written and read
with the real ``lerobot``.

Per frame (one MiniGrid step):

==================== ======== =====================================================================================
feature              dtype    meaning
==================== ======== =====================================================================================
observation.view     int64    MiniGrid's own observation ``image``: the 7 × 7 cells ahead of the agent, egocentric,
                              each (object, colour, state) by MiniGrid's indices, flattened row-major (147)
observation.state    int64    the true state the planner reads: row, col, direction (0 east … 3 north), and the
                              carried object's MiniGrid type and colour indices (0, 0: nothing)
action               int64    MiniGrid's: 0 left, 1 right, 2 forward, 3 pickup, 4 drop, 5 toggle, 6 done
next.reward          float32  MiniGrid's reward of this step (1 − 0.9 · steps / max_steps on success, else 0)
next.done            bool     the episode ended with this step
next.success         bool     this step achieved the mission
subgoal              int64    the operator this frame serves, by kind: 0 none, 1 goto_object, 2 goto_door,
                              3 goto_goal, 4 pickup, 5 open, 6 drop
subgoal.target       int64    its cell (row, col): a GoTo's destination, the object or door acted on; -1, -1 none
subgoal.object       int64    what it is about, MiniGrid's (type, colour) indices; 0, 0 for Drop and none
task                 string   the operator's name, e.g. ``PickUp(yellow key)``
==================== ======== =====================================================================================

Beside LeRobot's files, ``meta/hnsdt.json`` records the env id, the world seeds, the collection settings and the
vocabularies, ``meta/hnsdt_episodes.parquet`` one row per episode (world seed, fail_prob, failure seed, outcome),
and ``README.md`` is the card. Stock ``LeRobotDataset(repo_id, root=...)`` loads it offline.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from hnsdt.core.fileio import atomic_dir
from hnsdt.data.card import data_md5
from hnsdt.data.format import EPISODES_TABLE, HNSDT_META, DatasetError, check_dataset, frame_columns
from hnsdt.minigrid.collect import STATE_NAMES, SUBGOAL_NAMES
from hnsdt.models.windows import Frames, frames_from_arrays

VIEW_NAMES = tuple(f"x{i}y{j}{part}" for i in range(7) for j in range(7) for part in ("obj", "color", "state"))
FEATURES = {
    "observation.view": {"dtype": "int64", "shape": (147,), "names": list(VIEW_NAMES)},
    "observation.state": {"dtype": "int64", "shape": (5,), "names": list(STATE_NAMES)},
    "action": {"dtype": "int64", "shape": (1,), "names": ["action"]},
    "next.reward": {"dtype": "float32", "shape": (1,), "names": ["reward"]},
    "next.done": {"dtype": "bool", "shape": (1,), "names": ["done"]},
    "next.success": {"dtype": "bool", "shape": (1,), "names": ["success"]},
    "subgoal": {"dtype": "int64", "shape": (1,), "names": ["subgoal_kind"]},
    "subgoal.target": {"dtype": "int64", "shape": (2,), "names": ["row", "col"]},
    "subgoal.object": {"dtype": "int64", "shape": (2,), "names": ["type", "color"]},
}


def _frames(ep: dict):
    last = len(ep["actions"]) - 1
    for t in range(last + 1):
        yield {
            "observation.view": ep["views"][t].astype(np.int64),
            "observation.state": np.asarray(ep["states"][t], np.int64),
            "action": np.asarray([ep["actions"][t]], np.int64),
            "next.reward": np.asarray([ep["rewards"][t]], np.float32),
            "next.done": np.asarray([t == last]),
            "next.success": np.asarray([t == last and ep["success"]]),
            "subgoal": np.asarray([ep["subgoals"][t]], np.int64),
            "subgoal.target": np.asarray(ep["targets"][t], np.int64),
            "subgoal.object": np.asarray(ep["objects"][t], np.int64),
            "task": ep["names"][t],
        }


def _card(repo_id: str, meta: dict, rows: list[dict], md5: str) -> str:
    frames = sum(r["steps"] for r in rows)
    success = np.mean([r["success"] for r in rows]) if rows else float("nan")
    table = "\n".join(f"| `{name}` | {ft['dtype']} | {ft['shape'][0]} |" for name, ft in FEATURES.items())
    return (f"---\nlicense: {meta['license']}\ntags: [LeRobot, minigrid, hnsdt]\n---\n\n# {repo_id}\n\n"
            f"Episodes of the noisy symbolic agent (epsilon {meta['epsilon']:g}) on MiniGrid's own "
            f"`{meta['env_id']}`, stepped by MiniGrid under the paper's action failures "
            f"({', '.join(f'{p:g}' for p in meta['fail_probs'])}): {len(rows)} episodes, {frames} frames, "
            f"{len(meta['world_seeds'])} worlds (MiniGrid reset seeds {meta['world_seeds'][0]}–"
            f"{meta['world_seeds'][-1]}), success {success:.3f}. Each frame is labelled with the operator it serves "
            "(`subgoal`, `subgoal.target`, `subgoal.object`, `task`). Made by hnsdt "
            "(`hnsdt.data.minigrid_dataset`, whose docstring says what each feature means).\n\n"
            "| feature | dtype | size |\n|---|---|---|\n" + table + "\n| `task` | string | 1 |\n\n"
            f"Data md5: `{md5}`.\n\n```python\nfrom lerobot.datasets.lerobot_dataset import LeRobotDataset\n"
            f"ds = LeRobotDataset(\"{repo_id}\", root=\"PATH\")\n```\n")


def write_minigrid_dataset(root: str | Path, repo_id: str, episodes: list[dict], fps: int, meta: dict,
                           progress: bool = False) -> Path:
    """``episodes`` (:func:`hnsdt.minigrid.collect.collect_episodes`) as a LeRobot dataset at ``root``, built in a
    temporary folder beside it and moved into place only when complete. ``meta``: env_id, world_seeds,
    fail_probs, epsilon, seed, license."""
    # (lerobot takes seconds to import: only when writing, not in the learners' processes, which read)
    from hnsdt.data.lerobot_io import LeRobotDataset, lerobot_writing

    root = Path(root)
    if not episodes:
        raise ValueError(f"{root}: no episodes to write")
    with atomic_dir(root) as staging:
        ds = LeRobotDataset.create(repo_id, fps=fps, features=FEATURES, root=staging, use_videos=False)
        used = sorted({name for ep in episodes for name in ep["names"]})  # tasks first, sorted: same indices
        ds.meta.save_episode_tasks(used)
        with lerobot_writing(ds, FEATURES):
            for ep in tqdm(episodes, desc=f"write {root.name}", unit="episode", disable=not progress):
                for frame in _frames(ep):
                    ds.add_frame(frame)
                ds.save_episode()
        ds.finalize()
        rows = [dict(ep["meta"], episode_index=i) for i, ep in enumerate(episodes)]
        pd.DataFrame(rows).to_parquet(staging / EPISODES_TABLE, index=False)
        md5 = data_md5(staging)
        full = dict(meta, repo_id=repo_id, subgoal_kinds=list(SUBGOAL_NAMES), state_names=list(STATE_NAMES),
                    data_md5=md5)
        (staging / HNSDT_META).write_text(json.dumps(full, indent=2, sort_keys=True) + "\n")
        (staging / "README.md").write_text(_card(repo_id, meta, rows, md5))
    return root


def check_minigrid_dataset(root: str | Path) -> dict:
    """Validate a MiniGrid dataset's files and features (one :class:`DatasetError` line); its ``meta/hnsdt.json``."""
    meta = check_dataset(root, {name: f["dtype"] for name, f in FEATURES.items()})
    if meta.get("subgoal_kinds") != list(SUBGOAL_NAMES):
        raise DatasetError(f"dataset {root}: not a MiniGrid dataset of this version (meta/hnsdt.json has no "
                           f"subgoal_kinds {list(SUBGOAL_NAMES)}); run `dvc repro minigrid_collect`")
    return meta


def load_minigrid_frames(root: str | Path, with_md5: bool = False) -> Frames | tuple[Frames, str]:
    """The dataset's frames as the MiniGrid decision transformer reads them (:mod:`hnsdt.models.minigrid_nets`):
    states ``observation.state`` and ``observation.view`` side by side, each frame's sub-goal ``(row, col, type,
    colour)`` (its target cell and its object) as the target; ``with_md5``: and the data files' md5 they were read
    from (checked against the one the dataset recorded)."""
    from hnsdt.models.minigrid_nets import step_states  # (here: writing a dataset needs no network)

    meta = check_minigrid_dataset(root)
    cols = frame_columns(root, ["observation.state", "observation.view", "action", "next.reward", "subgoal",
                                "subgoal.target", "subgoal.object", "episode_index", "frame_index"])
    frames = frames_from_arrays(step_states(cols["observation.state"], cols["observation.view"]), cols["action"],
                                cols["next.reward"], cols["subgoal"], cols["subgoal.target"], cols["episode_index"],
                                cols["frame_index"])
    frames = replace(frames, targets=np.concatenate([frames.targets, cols["subgoal.object"]], axis=1))
    return (frames, meta.get("data_md5", "")) if with_md5 else frames
