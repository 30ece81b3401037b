"""A collected LeRobot dataset's frames, read once (the Arrow table stock ``LeRobotDataset`` loads, as numpy:
:func:`hnsdt.data.format.frame_columns`) into the :class:`~hnsdt.models.windows.Frames` the offline learners
train on."""

from __future__ import annotations

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
