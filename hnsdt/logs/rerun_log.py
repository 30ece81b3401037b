"""An episode as a rerun recording (.rrd) that opens laid out and explains itself: the grid as labelled cells
(an annotation context gives every class its name and colour, so the viewer shows a legend and hover labels),
the agent and the way it has walked so far, the plan, the active sub-goal, events and rewards; recording
properties say which method, env, fail_prob, seed and episode it is, and from which code revision and params."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hnsdt.envs.keydoor import ACTION_NAMES
from hnsdt.envs.render import CELL_PX, CLASS_ID, CLASSES, COLOURS, cell_classes
from hnsdt.core.fileio import write_files
from hnsdt.logs.record import PATH_COLOUR, PATH_WIDTH, EpisodeRecord
from hnsdt.symbolic.subgoals import ID_TO_NAME


LABELS = {"goal": "exit", "door_closed": "door (locked)", "door_open": "door (open)"}
ANNOTATIONS = rr.AnnotationContext([rr.AnnotationInfo(id=i, label=LABELS.get(name, name), color=COLOURS[name])
                                    for i, name in CLASSES.items()])


def recording_properties(rec: EpisodeRecord) -> dict:
    """What the recording is: its episode id, outcome and the record's metadata (method, env, fail_prob,
    seed, git revision, params digest ... as the caller gave them)."""
    props = {"episode_id": rec.episode_id, "success": bool(rec.success), "steps": int(rec.length),
             "return": float(np.sum(rec.rewards))}
    for key, value in rec.meta.items():
        if value is None or (isinstance(value, float) and np.isnan(value)):
            continue
        props[key] = value.item() if hasattr(value, "item") else value
    return props


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
    path = Path(path)
    write_files({path: rrd_bytes(rec, episode_index)})
    return path


def rrd_bytes(rec: EpisodeRecord, episode_index: int = 0) -> bytes:
    """The episode's ``.rrd`` file, encoded in memory: rerun's own file sink, once a full disk stops its writes,
    waits in its flush forever; written by Python, a full disk is an ``OSError`` (:mod:`hnsdt.core.fileio`)."""
    # No wall clock in the file where rerun lets us leave it out: no start-time property, no `log_time`
    # timeline (rerun's row ids stay time-based, so the bytes still differ from run to run).
    stream = rr.RecordingStream("hnsdt", recording_id=rec.episode_id, send_properties=False)
    stream.set_log_time_enabled(False)
    sink = rr.binary_stream(recording=stream)
    _log_episode(stream, rec, episode_index)
    data = sink.read(flush=True) or b""
    stream.disconnect()
    return data + (sink.read(flush=True) or b"")  # (what disconnecting ends the stream with)


def _times(episode_index: int, steps) -> list[rr.TimeColumn]:
    """Index columns for rows at ``steps`` of this episode (both timelines)."""
    steps = np.asarray(list(steps), dtype=np.int64)
    return [rr.TimeColumn("episode", sequence=np.full(len(steps), episode_index)),
            rr.TimeColumn("step", sequence=steps)]


def _log_episode(stream: rr.RecordingStream, rec: EpisodeRecord, episode_index: int) -> None:
    stream.send_blueprint(blueprint())
    stream.send_recording_name(rec.episode_id)
    stream.send_property("episode", rr.AnyValues(**recording_properties(rec)))
    stream.log("grid", ANNOTATIONS, static=True)
    stream.log("plan", rr.TextDocument(_plan_markdown(rec), media_type=rr.MediaType.MARKDOWN), static=True)
    stream.set_time("episode", sequence=episode_index)
    states = rec.states[: rec.length + 1]  # with the state after the last action, when recorded
    # every series in one call each (rows on the `episode` and `step` timelines): the cells and the agent of
    # every state, the final one included
    cells = np.stack([cell_classes(rec.layout, state, CELL_PX) for state in states])
    fmt = rr.components.ImageFormat(width=cells.shape[2], height=cells.shape[1], channel_datatype="U8")
    stream.send_columns("grid/cells", indexes=_times(episode_index, range(len(states))),
                        columns=rr.SegmentationImage.columns(buffer=cells.reshape(len(states), -1),
                                                             format=[fmt] * len(states)))
    centres = (states[:, [1, 0]].astype(np.float32) + 0.5) * CELL_PX  # (x, y)
    stream.send_columns("grid/agent", indexes=_times(episode_index, range(len(states))),
                        columns=rr.Points2D.columns(positions=centres, radii=np.full(len(states), 0.35 * CELL_PX),
                                                    class_ids=np.full(len(states), CLASS_ID["agent"])))
    # the way walked so far, one strip per state (the viewer shows the one at its time cursor): where the agent
    # has been — its loops and detours — beside where it is
    stream.send_columns("grid/path", indexes=_times(episode_index, range(len(states))),
                        columns=rr.LineStrips2D.columns(strips=[centres[:t + 1] for t in range(len(states))],
                                                        radii=np.full(len(states), PATH_WIDTH / 2 * CELL_PX),
                                                        colors=np.tile(PATH_COLOUR, (len(states), 1))))
    times = _times(episode_index, range(rec.length))
    rewards = np.asarray(rec.rewards, dtype=np.float64)
    stream.send_columns("reward/step", indexes=times, columns=rr.Scalars.columns(scalars=rewards))
    stream.send_columns("reward/cumulative", indexes=times, columns=rr.Scalars.columns(scalars=np.cumsum(rewards)))
    names = [ID_TO_NAME[int(i)] for i in rec.subgoal_ids[: rec.length]]
    changes = [t for t in range(rec.length) if t == 0 or names[t] != names[t - 1]]
    stream.send_columns("subgoal", indexes=_times(episode_index, changes), columns=rr.TextDocument.columns(
        text=[f"**{names[t]}**" for t in changes], media_type=[rr.MediaType.MARKDOWN] * len(changes)))
    events = [(t, f"sub-goal -> {names[t]}", "INFO") for t in changes]
    events += [(t, f"action {ACTION_NAMES[int(a)]}", "DEBUG") for t, a in enumerate(rec.actions[: rec.length])]
    if len(states) > rec.length:
        events.append((rec.length, "success" if rec.success else "episode ended without success",
                       "INFO" if rec.success else "WARN"))
    events.sort(key=lambda e: e[0])  # stable: a step's sub-goal change before its action
    stream.send_columns("events", indexes=_times(episode_index, [t for t, _, _ in events]),
                        columns=rr.TextLog.columns(text=[m for _, m, _ in events], level=[lv for _, _, lv in events]))
