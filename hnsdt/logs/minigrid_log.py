"""An episode on one of MiniGrid's own worlds as a rerun recording (.rrd) and an MCAP file for Foxglove.

Both show MiniGrid's own drawing of each step (the agent a red triangle pointing where it faces), what the agent
carries and which way it faces (MiniGrid's drawing leaves a carried object out), the operator it serves, its
actions (a failed one marked) and MiniGrid's reward. The rerun recording opens laid out (the frame beside the
state, the operator and the events); the MCAP file has the frames as ``foxglove.RawImage`` on ``/world``, the
events as ``foxglove.Log`` on ``/events`` and a JSON topic ``/step`` per step.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field

import foxglove
import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from foxglove.channels import LogChannel, RawImageChannel
from foxglove.messages import Log, LogLevel, RawImage, Timestamp

from hnsdt.minigrid.live import Step
from hnsdt.minigrid.world import DIRECTION_NAMES, Actions


@dataclass
class MiniGridRecord:
    episode_id: str  # e.g. "symbolic/MiniGrid-DoorKey-8x8-v0@100000/fp0.3/ep0"
    steps: list[Step]  # the traced steps, the closing frame last (action -1)
    success: bool
    meta: dict = field(default_factory=dict)
    fps: int = 10

    @property
    def length(self) -> int:
        return len(self.steps) - 1


def _state_text(step: Step) -> str:
    return (f"facing **{DIRECTION_NAMES[step.direction]}**, carrying **{step.carrying or 'nothing'}**"
            + (f"  \noperator: **{step.operator}**" if step.operator else ""))


def _events(rec: MiniGridRecord) -> list[tuple[int, str, str]]:
    events, prev_op, prev_carry = [], None, ""
    for t, step in enumerate(rec.steps):
        if step.operator and step.operator != prev_op:
            events.append((t, f"operator -> {step.operator}", "INFO"))
            prev_op = step.operator
        if step.carrying != prev_carry:
            events.append((t, f"carrying {step.carrying}" if step.carrying else "hands free", "INFO"))
            prev_carry = step.carrying
        if step.action >= 0:
            events.append((t, f"action {Actions(step.action).name}" + (" (failed)" if step.move_failed else ""),
                           "WARN" if step.move_failed else "DEBUG"))
    events.append((rec.length, "success" if rec.success else "episode ended without success",
                   "INFO" if rec.success else "WARN"))
    return events


def rrd_bytes(rec: MiniGridRecord) -> bytes:
    """The episode's ``.rrd``, encoded in memory (rerun's row ids are time-based: the bytes vary run to run)."""
    stream = rr.RecordingStream("hnsdt", recording_id=rec.episode_id, send_properties=False)
    stream.set_log_time_enabled(False)
    sink = rr.binary_stream(recording=stream)
    stream.send_blueprint(rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial2DView(origin="/world", name="MiniGrid"),
        rrb.Vertical(rrb.TextDocumentView(origin="/state", name="facing, carrying, operator"),
                     rrb.TextLogView(origin="/events", name="events"),
                     rrb.TimeSeriesView(origin="/reward", name="reward")),
        column_shares=[3, 2]), collapse_panels=True))
    stream.send_recording_name(rec.episode_id)
    stream.send_property("episode", rr.AnyValues(episode_id=rec.episode_id, success=bool(rec.success),
                                                 steps=rec.length, **rec.meta))
    for t, step in enumerate(rec.steps):
        stream.set_time("step", sequence=t)
        stream.log("world", rr.Image(step.frame))
        stream.log("state", rr.TextDocument(_state_text(step), media_type=rr.MediaType.MARKDOWN))
        if step.action >= 0:
            stream.log("reward", rr.Scalars(step.reward))
    for t, text, level in _events(rec):
        stream.set_time("step", sequence=t)
        stream.log("events", rr.TextLog(text, level=level))
    data = sink.read(flush=True) or b""
    stream.disconnect()
    return data + (sink.read(flush=True) or b"")


def mcap_bytes(rec: MiniGridRecord) -> bytes:
    """The episode's ``.mcap``, encoded in memory (the same bytes for the same episode)."""
    ctx = foxglove.Context()
    buffer = io.BytesIO()
    writer = foxglove.open_mcap(buffer, context=ctx)
    try:
        world = RawImageChannel("/world", context=ctx)
        events = LogChannel("/events", context=ctx)
        steps = foxglove.Channel("/step", message_encoding="json", context=ctx, schema={
            "type": "object", "properties": {k: {} for k in (
                "episode_id", "step", "direction", "carrying", "operator", "action", "move_failed", "reward")}})
        dt_ns = int(1e9 / rec.fps)
        levels = {"INFO": LogLevel.Info, "WARN": LogLevel.Warning, "DEBUG": LogLevel.Debug}
        at: dict[int, list[tuple[str, str]]] = {}
        for t, text, level in _events(rec):
            at.setdefault(t, []).append((text, level))
        for t, step in enumerate(rec.steps):  # (every topic in time order)
            stamp = Timestamp(sec=t * dt_ns // 10**9, nsec=t * dt_ns % 10**9)
            for text, level in at.get(t, []):
                events.log(Log(timestamp=stamp, level=levels[level], message=text, name="episode"), log_time=t * dt_ns)
            img = np.ascontiguousarray(step.frame, dtype=np.uint8)
            world.log(RawImage(timestamp=stamp, frame_id="world", width=img.shape[1], height=img.shape[0],
                               encoding="rgb8", step=img.shape[1] * 3, data=img.tobytes()), log_time=t * dt_ns)
            steps.log(json.dumps({
                "episode_id": rec.episode_id, "step": t, "direction": DIRECTION_NAMES[step.direction],
                "carrying": step.carrying, "operator": step.operator,
                "action": Actions(step.action).name if step.action >= 0 else "", "move_failed": step.move_failed,
                "reward": step.reward}), log_time=t * dt_ns)
    finally:
        writer.close()
    return buffer.getvalue()


def recording_files(rec: MiniGridRecord) -> dict[str, bytes]:
    """The ``.rrd`` and ``.mcap`` of the episode, by suffix."""
    return {".rrd": rrd_bytes(rec), ".mcap": mcap_bytes(rec)}
