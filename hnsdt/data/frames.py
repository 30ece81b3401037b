"""A collected LeRobot dataset's frames, read once (the Arrow table stock ``LeRobotDataset`` loads, as numpy:
:func:`hnsdt.data.format.frame_columns`) into the :class:`~hnsdt.models.windows.Frames` the offline learners
train on; :class:`DatasetFrames`, the same frames by reference, is what a training task carries."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from hnsdt.models.windows import Frames, frames_from_arrays


def load_frames(root: str | Path, operators: str = "goto", whole_map: bool = False) -> Frames:
    """The dataset's frames, with the sub-goal labelling of the operator set ``operators``: ``goto`` reads
    ``subgoal`` (the planner's operators, or hindsight GoTo labels), ``move`` the paper's ``move_subgoal``.
    A dataset with views (over many layouts) gives view states: row, col, view codes, flags, and with
    ``whole_map`` the whole map's codes after them (:func:`hnsdt.models.view.view_states`' ``map_side``)."""
    from hnsdt.data.format import DatasetError, check_dataset, episode_table, frame_columns

    column = {"goto": "subgoal", "move": "move_subgoal"}[operators]
    meta = check_dataset(root)
    view = ["observation.view"] if meta.get("view_radius") else []
    if whole_map and not meta.get("map_side"):
        raise DatasetError(f"dataset {root}: no observation.map (the whole map a planner module reads); collect it "
                           "again with this version")
    grid = ["observation.map"] if whole_map else []
    cols = frame_columns(root, ["observation.state", "action", "next.reward", column, f"{column}.target",
                                "episode_index", "frame_index", *view, *grid])
    policies = episode_table(root).set_index("episode_index")["policy"]
    states = cols["observation.state"]
    if view:  # a dataset over many layouts: view states (hnsdt.models.view.view_states)
        states = np.concatenate([states[:, :2], cols["observation.view"], states[:, 2:], *(cols[g] for g in grid)],
                                axis=1)
    return frames_from_arrays(states, cols["action"], cols["next.reward"], cols[column], cols[f"{column}.target"],
                              cols["episode_index"], cols["frame_index"],
                              policies.loc[cols["episode_index"]].to_numpy())


@dataclass(frozen=True)
class DatasetFrames:
    """A dataset's frames by reference (:func:`load_frames`' arguments and the data files' md5): what a training
    task carries instead of the frames, so that each process reads them from the dataset once (:meth:`load`)
    and no task is pickled with them — a stage of five seeds on two workers at 40,000 maps would otherwise hold
    a copy of its frames per task in flight. Its md5 names the bytes: a dataset changed since (or damaged) is
    refused when read. (On Ray the stage hands its tasks the frames themselves, through Ray's object store: a
    cluster's nodes need no copy of the dataset.)"""

    root: str
    operators: str = "goto"
    whole_map: bool = False
    data_md5: str = ""

    @classmethod
    def of(cls, root: str | Path, operators: str = "goto", whole_map: bool = False) -> "DatasetFrames":
        from hnsdt.data.format import check_dataset

        return cls(str(root), operators, whole_map, check_dataset(root).get("data_md5", ""))

    def load(self) -> Frames:
        """The frames (read once per process: the last dataset read is kept)."""
        return _read(self)


@lru_cache(maxsize=1)
def _read(ref: DatasetFrames) -> Frames:
    from hnsdt.data.format import HNSDT_META, DatasetError

    md5 = json.loads((Path(ref.root) / HNSDT_META).read_text()).get("data_md5", "")
    if md5 != ref.data_md5:
        raise DatasetError(f"dataset {ref.root}: changed since the stage read it (data md5 {md5}, was "
                           f"{ref.data_md5}); run the stage again")
    return load_frames(ref.root, ref.operators, ref.whole_map)
