"""An episode as an MCAP file for Foxglove: the grid as ``foxglove.RawImage``, with the way walked so far drawn
on it as in the rerun recording; actions and operator changes as ``foxglove.Log``, and a JSON topic ``/step`` with
state, action, sub-goal and reward; and the Foxglove layout that opens those topics side by side
(:func:`episode_layout`, built with the SDK's ``foxglove.layouts``)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import foxglove
import foxglove.layouts as fl
import numpy as np
from foxglove.channels import LogChannel, RawImageChannel
from foxglove.messages import Log, LogLevel, RawImage, Timestamp

from hnsdt.envs.keydoor import ACTION_NAMES
from hnsdt.envs.render import CELL_PX, COLOURS, render_rgb
from hnsdt.core.fileio import atomic_file, write_files
from hnsdt.logs.record import PATH_COLOUR, PATH_WIDTH, EpisodeRecord
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


LAYOUT_NAME = "foxglove_layout.json"  # written beside the recordings by the evaluate stage


def episode_layout() -> fl.Layout:
    """The grid on the left; on the right the executor's sub-goal changes and the actions (``/events``), the
    return so far, and each step's full record (``/step``). Import it in Foxglove: Layouts → Import."""
    right = [fl.LogPanel(title="sub-goals and actions", config=fl.LogConfig(topic_to_render="/events")),
             fl.PlotPanel(title="return", config=fl.PlotConfig(paths=[fl.PlotSeries(value="/step.return",
                                                                                    label="return")])),
             fl.RawMessagesPanel(title="step", config=fl.RawMessagesConfig(topic_path="/step"))]
    grid = fl.ImagePanel(title="grid", config=fl.ImageConfig(image_mode=fl.ImageModeConfig(image_topic="/grid")))
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=2, content=grid),
        fl.SplitItem(proportion=3, content=fl.SplitContainer(
            direction="column", items=[fl.SplitItem(content=panel) for panel in right]))]))


def write_layout(path: str | Path) -> Path:
    with atomic_file(path) as tmp:
        tmp.write_text(episode_layout().to_json() + "\n")
    return Path(path)


def trace_step(path: np.ndarray, a, b, cell_px: int = CELL_PX) -> None:
    """Mark on the pixel mask ``path`` the line from the centre of cell ``a`` to that of cell ``b`` (the same cell
    or a neighbour: a step), ``PATH_WIDTH`` cells wide."""
    (y0, x0), (y1, x1) = (np.asarray(c[:2], dtype=np.int64) * cell_px + cell_px // 2 for c in (a, b))
    half = max(int(round(PATH_WIDTH * cell_px)) // 2, 1)
    path[min(y0, y1) - half:max(y0, y1) + half + 1, min(x0, x1) - half:max(x0, x1) + half + 1] = True


def draw_path(img: np.ndarray, path: np.ndarray) -> np.ndarray:
    """``img`` (a :func:`render_rgb` frame) with the pixels of ``path`` in the path's colour, under the agent."""
    under = path & ~(img == COLOURS["agent"]).all(axis=-1)
    img[under] = PATH_COLOUR[:3]
    return img


def write_mcap(path: str | Path, rec: EpisodeRecord) -> Path:
    path = Path(path)
    write_files({path: mcap_bytes(rec)})
    return path


def mcap_bytes(rec: EpisodeRecord) -> bytes:
    """The episode's ``.mcap`` file, encoded in memory: the SDK's own file writer reports a full disk without
    its errno ("attempted another write after a write method failed"); written by Python, it is an ``OSError``."""
    ctx = foxglove.Context()  # a context of its own, so channels never leak between files
    buffer = io.BytesIO()
    writer = foxglove.open_mcap(buffer, context=ctx)
    try:
        grid = RawImageChannel("/grid", context=ctx)
        events = LogChannel("/events", context=ctx)
        steps = foxglove.Channel("/step", schema=STEP_SCHEMA, message_encoding="json", context=ctx)
        dt_ns = int(1e9 / rec.fps)
        cum, prev = 0.0, None
        walked = np.zeros(np.multiply(rec.layout.shape, CELL_PX), dtype=bool)  # the way's pixels so far
        for t in range(rec.length):
            ns = t * dt_ns
            stamp = Timestamp(sec=ns // 10**9, nsec=ns % 10**9)
            if t:
                trace_step(walked, rec.states[t - 1], rec.states[t])
            img = draw_path(render_rgb(rec.layout, rec.states[t]), walked)
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
    return buffer.getvalue()
