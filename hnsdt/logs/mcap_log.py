"""An episode as an MCAP file for Foxglove: the grid as ``foxglove.RawImage``, actions and operator changes as
``foxglove.Log``, and a JSON topic ``/step`` with state, action, sub-goal and reward."""

from __future__ import annotations

import json
from pathlib import Path

import foxglove
from foxglove.channels import LogChannel, RawImageChannel
from foxglove.messages import Log, LogLevel, RawImage, Timestamp

from hnsdt.envs.keydoor import ACTION_NAMES
from hnsdt.envs.render import render_rgb
from hnsdt.fileio import atomic_file
from hnsdt.logs.record import EpisodeRecord
from hnsdt.symbolic.subgoals import ID_TO_NAME

STEP_SCHEMA = {
    "type": "object",
    "properties": {
        "episode_id": {"type": "string"}, "step": {"type": "integer"},
        "state": {"type": "array", "items": {"type": "integer"}}, "state_names": {"type": "array"},
        "action": {"type": "integer"}, "action_name": {"type": "string"},
        "subgoal_id": {"type": "integer"}, "subgoal": {"type": "string"},
        "reward": {"type": "number"}, "return": {"type": "number"},
    },
}


def write_mcap(path: str | Path, rec: EpisodeRecord) -> Path:
    path = Path(path)  # atomic_file creates the parent folder
    with atomic_file(path) as tmp:
        ctx = foxglove.Context()  # a context of its own, so channels never leak between files
        writer = foxglove.open_mcap(str(tmp), allow_overwrite=True, context=ctx)
        try:
            grid = RawImageChannel("/grid", context=ctx)
            events = LogChannel("/events", context=ctx)
            steps = foxglove.Channel("/step", schema=STEP_SCHEMA, message_encoding="json", context=ctx)
            dt_ns = int(1e9 / rec.fps)
            cum, prev = 0.0, None
            for t in range(rec.length):
                ns = t * dt_ns
                stamp = Timestamp(sec=ns // 10**9, nsec=ns % 10**9)
                img = render_rgb(rec.layout, rec.states[t])
                grid.log(RawImage(timestamp=stamp, frame_id="grid", width=img.shape[1], height=img.shape[0],
                                  encoding="rgb8", step=img.shape[1] * 3, data=img.tobytes()), log_time=ns)
                name = ID_TO_NAME[int(rec.subgoal_ids[t])]
                if name != prev:
                    events.log(Log(timestamp=stamp, level=LogLevel.Info, message=f"sub-goal -> {name}",
                                   name="executor"), log_time=ns)
                    prev = name
                action = int(rec.actions[t])
                events.log(Log(timestamp=stamp, level=LogLevel.Debug, message=f"action {ACTION_NAMES[action]}",
                               name="policy"), log_time=ns)
                cum += float(rec.rewards[t])
                steps.log(json.dumps({
                    "episode_id": rec.episode_id, "step": t, "state": [int(v) for v in rec.states[t]],
                    "state_names": rec.layout.state_names, "action": action, "action_name": ACTION_NAMES[action],
                    "subgoal_id": int(rec.subgoal_ids[t]), "subgoal": name, "reward": float(rec.rewards[t]),
                    "return": cum,
                }), log_time=ns)
        finally:
            writer.close()
    return path
