"""An episode as a rerun recording (.rrd) that opens laid out: grid, plan, sub-goal and events, rewards."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hnsdt.envs.keydoor import ACTION_NAMES
from hnsdt.fileio import atomic_file
from hnsdt.envs.render import render_rgb
from hnsdt.logs.record import EpisodeRecord
from hnsdt.symbolic.subgoals import ID_TO_NAME


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="/grid", name="grid"),
            rrb.Vertical(
                rrb.TextDocumentView(origin="/plan", name="plan"),
                rrb.TextDocumentView(origin="/subgoal", name="active sub-goal"),
                rrb.TextLogView(origin="/events", name="events"),
                rrb.TimeSeriesView(origin="/reward", name="reward"),
            ),
            column_shares=[2, 3],
        ),
        collapse_panels=True,
    )


def _plan_markdown(rec: EpisodeRecord) -> str:
    lines = [f"## {rec.episode_id}", "", f"outcome: **{'success' if rec.success else 'failure'}** in "
             f"{rec.length} steps, return {float(np.sum(rec.rewards)):.2f}, replans {rec.replans}", ""]
    if rec.plan:
        lines += ["### initial plan", ""] + [f"{i}. {op}" for i, op in enumerate(rec.plan, 1)] + [""]
    if rec.segments:
        lines += ["### executed sub-goals", "", "| operator | steps | achieved |", "|---|---|---|"]
        lines += [f"| {op} | {a}–{b} | {'yes' if ok else 'no'} |" for op, a, b, ok in rec.segments]
    return "\n".join(lines)


def write_rrd(path: str | Path, rec: EpisodeRecord, episode_index: int = 0) -> Path:
    path = Path(path)  # atomic_file creates the parent folder
    # No wall clock in the file where rerun lets us leave it out: no start-time property, no `log_time`
    # timeline (rerun's row ids stay time-based, so the bytes still differ from run to run).
    stream = rr.RecordingStream("hnsdt", recording_id=rec.episode_id, send_properties=False)
    stream.set_log_time_enabled(False)
    with atomic_file(path) as tmp:
        _log_episode(stream, tmp, rec, episode_index)
    return path


def _log_episode(stream: rr.RecordingStream, tmp: Path, rec: EpisodeRecord, episode_index: int) -> None:
    stream.save(str(tmp))
    stream.send_blueprint(blueprint())
    stream.set_time("episode", sequence=episode_index)
    stream.set_time("step", sequence=0)
    stream.log("plan", rr.TextDocument(_plan_markdown(rec), media_type=rr.MediaType.MARKDOWN), static=True)
    cum = 0.0
    prev = None
    for t in range(rec.length):
        stream.set_time("step", sequence=t)
        stream.log("grid", rr.Image(render_rgb(rec.layout, rec.states[t])))
        name = ID_TO_NAME[int(rec.subgoal_ids[t])]
        if name != prev:
            stream.log("subgoal", rr.TextDocument(f"**{name}**", media_type=rr.MediaType.MARKDOWN))
            stream.log("events", rr.TextLog(f"sub-goal -> {name}", level="INFO"))
            prev = name
        stream.log("events", rr.TextLog(f"action {ACTION_NAMES[int(rec.actions[t])]}", level="DEBUG"))
        cum += float(rec.rewards[t])
        stream.log("reward/step", rr.Scalars(float(rec.rewards[t])))
        stream.log("reward/cumulative", rr.Scalars(cum))
    if len(rec.states) > rec.length:  # the state after the last action
        stream.set_time("step", sequence=rec.length)
        stream.log("grid", rr.Image(render_rgb(rec.layout, rec.states[rec.length])))
        stream.log("events", rr.TextLog("success" if rec.success else "episode ended without success",
                                        level="INFO" if rec.success else "WARN"))
    stream.flush()
    stream.disconnect()
