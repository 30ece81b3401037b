"""One episode, in the form both recording formats are written from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hnsdt.data.segmentation import segments_of
from hnsdt.envs.layout import Layout
from hnsdt.symbolic.subgoals import ID_TO_NAME


# The way an agent has walked, drawn in both formats over the grid: a colour no cell has (RGBA; the .mcap images
# take its RGB) and a width, in cells.
PATH_COLOUR, PATH_WIDTH = np.array([200, 40, 160, 200], dtype=np.uint8), 0.16


@dataclass
class EpisodeRecord:
    episode_id: str  # e.g. "hnsdt/keydoor/fp0.1/seed0/ep3": the key of the per-episode table
    layout: Layout
    states: np.ndarray  # (T or T+1, d)
    actions: np.ndarray  # (T,)
    rewards: np.ndarray  # (T,)
    subgoal_ids: np.ndarray  # (T,)
    success: bool
    plan: list[str] = field(default_factory=list)
    segments: list[tuple[str, int, int, bool]] = field(default_factory=list)  # (operator, start, end, achieved)
    replans: int = 0
    meta: dict = field(default_factory=dict)
    fps: int = 10

    @property
    def length(self) -> int:
        return len(self.actions)


def record_from_episode(episode_id: str, layout: Layout, ep, meta: dict | None = None) -> EpisodeRecord:
    """From an :class:`hnsdt.agents.rollout.Episode` (evaluation)."""
    if ep.segments:
        segments = [(s.operator, s.start, s.end if s.end is not None else ep.length, s.achieved)
                    for s in ep.segments]
    else:
        segments = [(ID_TO_NAME[i], a, b, False) for i, a, b in segments_of(ep.subgoal_ids) if i]
    return EpisodeRecord(episode_id, layout, ep.states, ep.actions, ep.rewards, ep.subgoal_ids, ep.success,
                         list(ep.plan), segments, ep.replans, dict(meta or {}))


def record_from_dataset(root, episode_index: int) -> EpisodeRecord:
    """From one episode of a collected LeRobot dataset, with its sub-goal segments."""
    from hnsdt.data.lerobot_io import episode_table, open_dataset
    from hnsdt.envs.layout import parse_layout

    ds = open_dataset(root)
    meta = episode_table(root)
    if not 0 <= episode_index < len(meta):
        raise ValueError(f"dataset {root} has episodes 0..{len(meta) - 1}, not {episode_index}")
    import json
    from pathlib import Path

    info = json.loads((Path(root) / "meta/hnsdt.json").read_text())
    layout = parse_layout(info["layout_text"], name=info["layout"])
    cols = ds.hf_dataset.with_format("numpy")[:]
    rows = np.flatnonzero(cols["episode_index"] == episode_index)
    ids = np.ravel(cols["subgoal"])[rows]
    row = meta.iloc[episode_index].to_dict()
    return EpisodeRecord(
        episode_id=f"dataset/{Path(root).name}/ep{episode_index}", layout=layout,
        states=np.stack(cols["observation.state"])[rows], actions=np.ravel(cols["action"])[rows],
        rewards=np.ravel(cols["next.reward"])[rows], subgoal_ids=ids, success=bool(row["success"]),
        segments=[(ID_TO_NAME[i], a, b, False) for i, a, b in segments_of(ids) if i],
        meta={k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}, fps=int(info.get("fps", 10)),
    )
