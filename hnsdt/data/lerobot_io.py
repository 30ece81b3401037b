"""Our trajectories as LeRobot v3.0 datasets: the on-disk format, written and read with the real ``lerobot``.

Per frame (one environment step): the features of :mod:`hnsdt.data.features`, where each is defined once
(dtype, element names, meaning, value): the state, the action, the reward, done and success flags, both
sub-goal labellings with their targets and the task; the grid as video with ``collect.render`` > 0; the local
view and the layout index on datasets over many layouts.

Beside LeRobot's own files, ``meta/hnsdt.json`` records the environment (id, layout text, limits), the sub-goal
vocabulary and the collection settings, ``meta/hnsdt_episodes.parquet`` one row per episode (env id, layout,
fail_prob, seed, behaviour policy, outcome), and ``README.md`` is the dataset card. Stock
``LeRobotDataset(repo_id, root=...)`` loads the result offline.
"""

from __future__ import annotations

import contextlib
import gc
import json
import logging
import os
import traceback
from pathlib import Path

import pandas as pd
from tqdm import tqdm

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # never reach for the hub: datasets live on local disk
logging.getLogger("lerobot.utils.import_utils").setLevel(logging.ERROR)  # torchcodec/ffmpeg: we store no video

import datasets  # noqa: E402

datasets.disable_progress_bars()

from datasets import arrow_dataset as _hf_arrow_dataset  # noqa: E402
from lerobot.datasets import dataset_writer as _lerobot_writer  # noqa: E402
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

from hnsdt.data.card import data_md5, render_card  # noqa: E402
from hnsdt.data.episode_stats import vectorised_episode_stats  # noqa: E402
from hnsdt.data.features import frame, info_features  # noqa: E402
from hnsdt.data.format import (EPISODES_TABLE, FORMAT_VERSION, HNSDT_META, DatasetError,  # noqa: E402,F401
                               check_dataset, episode_table)
from hnsdt.envs.layout import Layout  # noqa: E402
from hnsdt.envs.observation import local_view, whole_map  # noqa: E402
from hnsdt.envs.render import render_rgb  # noqa: E402
from hnsdt.core.fileio import atomic_dir  # noqa: E402

def dataset_features(layout: Layout, render_px: int = 0, view_radius: int = 0, map_side: int = 0) -> dict:
    """The per-frame features of a dataset on ``layout`` (:mod:`hnsdt.data.features`); ``render_px`` > 0 adds
    the grid drawn at that many pixels per cell, stored as video (what LeRobot's visualizers, the Hub's
    included, show); ``view_radius`` > 0 (datasets over many layouts) adds the local view, the whole map on a
    square of ``map_side`` and the layout index."""
    image = (layout.shape[0] * render_px, layout.shape[1] * render_px, 3) if render_px else None
    return info_features(layout.state_names, image, view_radius, map_side)


@contextlib.contextmanager
def _skip_image_embedding(features: dict):
    """lerobot's ``embed_images`` maps every row through ``embed_table_storage`` even when a dataset has no
    image feature (about 3 ms a frame, three quarters of the write time here); for such a dataset it changes
    nothing, so we bypass it while writing one."""
    if any(ft["dtype"] in ("image", "video") for ft in features.values()):
        yield
        return
    original = _lerobot_writer.embed_images
    _lerobot_writer.embed_images = lambda dataset: dataset
    try:
        yield
    finally:
        _lerobot_writer.embed_images = original


@contextlib.contextmanager
def _skip_fingerprints():
    """lerobot builds each episode as an in-memory ``datasets.Dataset`` only to write its Arrow table, and
    ``datasets`` fingerprints every new one by pickling its whole table (a third of the write time here: 14.5 of
    36 s for 640 episodes). The fingerprint names cache files of later ``map`` calls and is never written; we
    give each a random one (what ``datasets`` does with caching off) while writing. Files byte-identical."""
    original = _hf_arrow_dataset.generate_fingerprint
    _hf_arrow_dataset.generate_fingerprint = lambda dataset: _hf_arrow_dataset.generate_random_fingerprint()
    try:
        yield
    finally:
        _hf_arrow_dataset.generate_fingerprint = original


@contextlib.contextmanager
def _metadata_written_once(ds: LeRobotDataset):
    """lerobot rewrites ``meta/info.json`` and ``meta/stats.json`` after every episode (the running totals and
    stats; a quarter of the write time with the episode stats vectorised: 2.8 of 11 s for 256 episodes, profiled)
    and reads neither back while writing. We write both once, from the same objects, when the episodes are in:
    the same files."""
    from lerobot.datasets import dataset_metadata
    from lerobot.datasets.io_utils import write_info, write_stats

    dataset_metadata.write_info = dataset_metadata.write_stats = lambda *args: None
    try:
        yield
    finally:
        dataset_metadata.write_info, dataset_metadata.write_stats = write_info, write_stats
    write_info(ds.meta.info, ds.meta.root)
    if ds.meta.stats is not None:
        write_stats(ds.meta.stats, ds.meta.root)


@contextlib.contextmanager
def lerobot_writing(ds: LeRobotDataset, features: dict):
    """What we do to lerobot while it writes the episodes of ``ds``, each leaving the files lerobot alone writes
    (docs/datasets.md): no image embedding without images, no fingerprints, the episode statistics on whole
    arrays, the metadata written once."""
    with (_skip_image_embedding(features), _skip_fingerprints(), vectorised_episode_stats(),
          _metadata_written_once(ds)):
        yield


def write_dataset(root: str | Path, repo_id: str, layout: Layout | list[Layout], episodes: list[dict], fps: int,
                  meta: dict, card: dict, progress: bool = False, render_px: int = 0, view_radius: int = 0) -> Path:
    """Write ``episodes`` (dicts with states, actions, rewards, success, subgoal_ids, subgoal_targets, their
    ``move_`` twins and a ``meta`` row) as a LeRobot dataset at ``root``, its card made from ``card``
    (:func:`hnsdt.data.card.card_arguments`). Built in a temporary folder beside ``root`` and moved into
    place only when complete, so a failure leaves no half-written dataset. ``layout`` may be a list (episodes
    then name theirs by ``layout_index``) with ``view_radius`` > 0: each frame also stores its local view and the
    whole map."""
    root = Path(root)
    layouts = list(layout) if isinstance(layout, (list, tuple)) else [layout]
    if len(layouts) > 1 and not view_radius:
        raise ValueError("a dataset over several layouts stores views: view_radius must be > 0")
    with atomic_dir(root) as staging:
        info = write_frames(staging, repo_id, layouts, episodes, fps, progress, render_px, view_radius,
                            desc=f"write {root.name}")
        finish_dataset(staging, repo_id, layouts, [ep["meta"] for ep in episodes], meta, card, info, view_radius)
    return root


def map_side(layouts: list[Layout]) -> int:
    """The side of the square every frame's whole map is drawn on: the largest layout's longer side."""
    return max(max(lay.shape) for lay in layouts)


def write_frames(folder: Path, repo_id: str, layouts: list[Layout], episodes: list[dict], fps: int,
                 progress: bool = False, render_px: int = 0, view_radius: int = 0, side: int | None = None,
                 desc: str = "write", first: int = 0) -> dict:
    """LeRobot's part of a dataset at ``folder`` (which must not exist): its frames, episodes metadata, tasks and
    stats, written by ``lerobot``; returns its ``meta.info``. A shard of a dataset passes the whole dataset's
    map square ``side`` (default: the largest of ``layouts``) and the dataset's index of its first layout,
    ``first`` (its episodes name theirs by the dataset's index)."""
    from hnsdt.symbolic.subgoals import ID_TO_NAME

    layout = layouts[0]  # the state's names (every layout of a dataset has the same flags)
    side = (side or map_side(layouts)) if view_radius else 0
    features = dataset_features(layout, render_px, view_radius, side)
    draw = (lambda state: render_rgb(layout, state, render_px)) if render_px else None
    view = (lambda ep: {
        "views": local_view(layouts[ep["layout_index"] - first], ep["states"], view_radius).reshape(
            len(ep["states"]), -1),
        "maps": whole_map(layouts[ep["layout_index"] - first], ep["states"], side).reshape(len(ep["states"]), -1),
    }) if view_radius else None
    with _quiet_video_encoder():
        ds = LeRobotDataset.create(repo_id, fps=fps, features=features, root=folder, use_videos=bool(render_px))
        try:
            # Register the tasks in vocabulary order first, so task_index is the same on every run.
            used = sorted({int(i) for ep in episodes for i in ep["subgoal_ids"]})
            ds.meta.save_episode_tasks([ID_TO_NAME[i] for i in used])
            with lerobot_writing(ds, features):
                for ep in tqdm(episodes, desc=desc, unit="episode", disable=not progress):
                    _add_episode(ds, ep, features, draw, view)
                    ds.save_episode()
            ds.finalize()
        except BaseException as e:  # (a full disk): LeRobot's writers, still open, flush again when collected
            with contextlib.suppress(Exception):
                ds.finalize()
            traceback.clear_frames(e.__traceback__)  # the failed calls' frames hold them: collect them now,
            ds = None  # while the staging folder is still there to be removed, not after (it came back) and
            gc.collect()  # with their files still open (a tmpfs would not give the space back)
            raise
        return ds.meta.info


def finish_dataset(folder: Path, repo_id: str, layouts: list[Layout], rows: list[dict], meta: dict, card: dict,
                   info: dict, view_radius: int = 0) -> None:
    """Our files beside LeRobot's at ``folder``: the episode table (``rows``, one per episode in order), the
    data files' md5, ``meta/hnsdt.json`` and the card."""
    from hnsdt.symbolic.subgoals import ID_TO_NAME

    pd.DataFrame([dict(row, episode_index=i) for i, row in enumerate(rows)]).to_parquet(folder / EPISODES_TABLE,
                                                                                       index=False)
    md5 = data_md5(folder)
    texts = ({"layout_texts": [lay.text for lay in layouts], "view_radius": view_radius,
              "map_side": map_side(layouts)} if view_radius else {})
    full_meta = dict(meta, format_version=FORMAT_VERSION, subgoal_vocabulary=ID_TO_NAME,
                     layout_text=layouts[0].text, state_names=layouts[0].state_names, card=card, data_md5=md5,
                     **texts)
    (folder / HNSDT_META).write_text(json.dumps(full_meta, indent=2, sort_keys=True) + "\n")
    (folder / "README.md").write_text(render_card(card, info, repo_id, md5))


def join(folder: Path, repo_id: str, parts: list[Path], progress: bool = False) -> dict:
    """LeRobot's part of a dataset at ``folder`` (which must not exist) joined from the datasets ``parts``, in
    order, one part at a time; returns its ``meta.info``. Each part's data and episodes files are copied with
    ``lerobot``'s own functions for its aggregation (episode, frame and task indices renumbered, the episodes'
    stats shifted) and stay files of their own; the parts' stats are merged by ``lerobot``'s ``aggregate_stats``.
    Tasks are numbered in sub-goal vocabulary order, as in a dataset written in one piece.

    Not ``aggregate_datasets`` itself: it holds every part's episode metadata at once (each episode's stats
    include the whole map's) and reads the growing episodes file back for every part, 4.84 GiB at 40 parts of
    1,000 maps (measured; docs/timings.md, "Ten times the data")."""
    from lerobot.datasets import aggregate as lerobot_aggregate
    from lerobot.datasets.compute_stats import aggregate_stats
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
    from lerobot.datasets.io_utils import load_tasks, write_info, write_stats, write_tasks
    from lerobot.datasets.utils import DEFAULT_CHUNK_SIZE, DEFAULT_DATA_FILE_SIZE_IN_MB, DEFAULT_EPISODES_PATH

    from hnsdt.symbolic.subgoals import NAME_TO_ID

    names = sorted({name for part in parts for name in load_tasks(part).index}, key=NAME_TO_ID.__getitem__)
    data_at, episode_files, stats, dst = {"chunk": 0, "file": 0}, 0, [], None
    for part in tqdm(parts, desc=f"join {folder.name}", unit="shard", disable=not progress):
        src = LeRobotDatasetMetadata(repo_id, root=part)  # (its episodes: one part's, released each turn)
        if dst is None:
            dst = LeRobotDatasetMetadata.create(repo_id=repo_id, fps=src.fps, robot_type=src.robot_type,
                                                features=src.features, root=folder, use_videos=False)
            dst.tasks = pd.DataFrame({"task_index": range(len(names))}, index=pd.Index(names, name="task"))
        elif src.features != dst.features:
            raise DatasetError(f"{part}: its features are not those of {parts[0]}; it cannot join them")
        data_at = lerobot_aggregate.aggregate_data(src, dst, data_at, DEFAULT_DATA_FILE_SIZE_IN_MB,
                                                   DEFAULT_CHUNK_SIZE, concatenate_data=False)
        for chunk, file in sorted(set(zip(src.episodes["meta/episodes/chunk_index"],
                                          src.episodes["meta/episodes/file_index"]))):
            rows = lerobot_aggregate.update_meta_data(
                pd.read_parquet(part / DEFAULT_EPISODES_PATH.format(chunk_index=chunk, file_index=file)), dst,
                {"chunk": 0, "file": 0}, data_at, {})
            at = dict(zip(("chunk", "file"), divmod(episode_files, DEFAULT_CHUNK_SIZE)))  # (LeRobot's numbering)
            rows["meta/episodes/chunk_index"], rows["meta/episodes/file_index"] = at["chunk"], at["file"]
            path = folder / DEFAULT_EPISODES_PATH.format(chunk_index=at["chunk"], file_index=at["file"])
            path.parent.mkdir(parents=True, exist_ok=True)
            rows.to_parquet(path)
            episode_files += 1
        data_at.pop("src_to_dst", None)
        dst.info.total_episodes += src.total_episodes
        dst.info.total_frames += src.total_frames
        stats.append(src.stats)
    write_tasks(dst.tasks, folder)
    dst.info.total_tasks = len(names)
    dst.info.splits = {"train": f"0:{dst.info.total_episodes}"}
    write_info(dst.info, folder)
    write_stats(aggregate_stats(stats), folder)
    return dst.info


@contextlib.contextmanager
def _quiet_video_encoder():
    """FFmpeg (through PyAV) reports every MP4 it finishes on stderr; keep a collect's output readable."""
    import av.logging

    level = av.logging.get_level()
    av.logging.set_level(av.logging.ERROR)
    try:
        yield
    finally:
        av.logging.set_level(level)


def _add_episode(ds: LeRobotDataset, ep: dict, features: dict, draw=None, view=None) -> None:
    extra = {}
    if draw is not None:
        extra["images"] = [draw(state) for state in ep["states"][:len(ep["actions"])]]
    if view is not None:
        extra.update(view(ep))
    ep = dict(ep, **extra)
    for t in range(len(ep["actions"])):
        ds.add_frame(frame(ep, t, features))


def open_dataset(root: str | Path, delta_timestamps: dict | None = None, repo_id: str | None = None
                 ) -> LeRobotDataset:
    """Open one of our datasets with stock ``LeRobotDataset`` (offline), after checking its files."""
    meta = check_dataset(root)
    logging.disable(logging.ERROR)  # `datasets` logs a damaged file before raising; the error below says it once
    try:
        return LeRobotDataset(repo_id or meta.get("repo_id", "local/hnsdt"), root=Path(root),
                              delta_timestamps=delta_timestamps)
    except Exception as e:  # noqa: BLE001  (pyarrow, datasets and lerobot raise many kinds)
        cause = e.__cause__ or e.__context__
        why = f"{type(e).__name__}: {e}" + (f"; {type(cause).__name__}: {cause}" if cause else "")
        raise DatasetError(f"dataset {root}: LeRobot cannot read it ({why})") from None
    finally:
        logging.disable(logging.NOTSET)
