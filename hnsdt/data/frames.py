"""A collected LeRobot dataset's frames, read once through stock ``LeRobotDataset`` (its Arrow table, as numpy)
into the :class:`~hnsdt.models.windows.Frames` the offline learners train on."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hnsdt.models.windows import Frames, frames_from_arrays


def load_frames(root: str | Path, operators: str = "goto") -> Frames:
    """The dataset's frames, with the sub-goal labelling of the operator set ``operators``: ``goto`` reads
    ``subgoal`` (the planner's operators, or hindsight GoTo labels), ``move`` the paper's ``move_subgoal``.
    A dataset with views (over many layouts) gives view states: row, col, view codes, flags."""
    from hnsdt.data.lerobot_io import episode_table, open_dataset

    column = {"goto": "subgoal", "move": "move_subgoal"}[operators]
    ds = open_dataset(root)
    cols = ds.hf_dataset.with_format("numpy")[:]
    policies = episode_table(root).set_index("episode_index")["policy"]
    states = np.stack(cols["observation.state"])
    if "observation.view" in cols:  # a dataset over many layouts: view states (hnsdt.models.view.view_states)
        states = np.concatenate([states[:, :2], np.stack(cols["observation.view"]), states[:, 2:]], axis=1)
    return frames_from_arrays(states, np.ravel(cols["action"]),
                              np.ravel(cols["next.reward"]), np.ravel(cols[column]),
                              np.stack(cols[f"{column}.target"]), cols["episode_index"], cols["frame_index"],
                              policies.loc[cols["episode_index"]].to_numpy())
