import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from rerun.chunk import RrdReader

from conftest import hnsdt_cli
from hnsdt.agents import SymbolicAgent, rollout
from hnsdt.envs import KeyDoorVectorEnv
from hnsdt.envs.render import CELL_PX, COLOURS
from hnsdt.logs import record_from_episode, write_mcap, write_rrd
from hnsdt.logs.record import PATH_COLOUR


def _episode(layout):
    return rollout(KeyDoorVectorEnv(1, layout, 0.2, 100), SymbolicAgent(layout), seed=4)[0]


def _rows(path):
    counts = {}
    for chunk in RrdReader(str(path)).store().stream().to_chunks():
        counts[chunk.entity_path] = counts.get(chunk.entity_path, 0) + chunk.num_rows
    return counts


def test_rrd_reads_back_with_every_step_labelled_and_verified(tmp_path, keydoor):
    from hnsdt.envs.render import CLASS_ID, cell_classes

    ep = _episode(keydoor)
    meta = {"method": "symbolic", "env": "keydoor", "fail_prob": 0.2, "seed": 0, "git_revision": "abc"}
    rec = record_from_episode("symbolic/keydoor/fp0.2/seed0/ep0", keydoor, ep, meta)
    path = write_rrd(tmp_path / "ep.rrd", rec)
    reader = RrdReader(str(path))
    assert reader.recordings()[0].recording_id == "symbolic/keydoor/fp0.2/seed0/ep0"
    assert len(reader.blueprints()) == 1  # opens laid out
    rows = _rows(path)
    assert rows["/grid/cells"] == rows["/grid/agent"] == rows["/grid/path"] == ep.length + 1  # every state, the
    # final one included
    assert rows["/reward/step"] == rows["/reward/cumulative"] == ep.length
    assert rows["/plan"] == 1 and rows["/subgoal"] == len(ep.segments)
    assert rows["/events"] == ep.length + len(ep.segments) + 1  # actions, sub-goal changes, the outcome
    chunks = {c.entity_path: c.to_record_batch() for c in reader.store().stream().to_chunks()}
    props = {name: col.to_pylist()[0] for name, col in zip(chunks["/__properties/episode"].schema.names,
                                                          chunks["/__properties/episode"].columns)}
    assert {k: props[k] for k in meta} == {k: [v] for k, v in meta.items()} and props["success"] == [ep.success]
    legend = {c["class_description"]["info"]["label"] for c in chunks["/grid"].column(1).to_pylist()[0][0]}
    assert legend == {"floor", "wall", "exit", "key", "door (locked)", "door (open)", "item", "agent"}
    # the way walked so far: at step t the centres of the cells of states 0..t, the last one the agent's
    batch = chunks["/grid/path"]
    strips = [row[0] for row in batch.column(batch.schema.names.index("LineStrips2D:strips")).to_pylist()]
    agent = chunks["/grid/agent"]
    centres = [row[0] for row in agent.column(agent.schema.names.index("Points2D:positions")).to_pylist()]
    assert [len(s) for s in strips] == list(range(1, ep.length + 2))
    assert strips[-1] == centres and all(s == centres[:len(s)] for s in strips)
    summary = str(reader.store().summary())
    assert "episode" in summary and "step" in summary  # both timelines
    # the cells: walls where the layout has walls, the key until it is picked up
    first = cell_classes(keydoor, ep.states[0], cell_px=1)
    assert ((first == CLASS_ID["wall"]) == keydoor.walls).all()
    assert first[next(iter(keydoor.keys.values()))] == CLASS_ID["key"]
    verify = subprocess.run([str(Path(sys.executable).parent / "rerun"), "rrd", "verify", str(path)],
                            capture_output=True, text=True)
    assert verify.returncode == 0 and "verified without error" in verify.stdout + verify.stderr


def test_recording_files_are_what_the_writers_write(tmp_path, keydoor):
    """What an evaluation's worker hands back (``recording_files``) is what the writers put on disk: the same
    ``.mcap`` bytes, and the same ``.rrd`` recording (rerun's row ids are time-based, so not the same bytes)."""
    from hnsdt.logs import recording_files

    rec = record_from_episode("symbolic/keydoor/fp0.2/seed0/ep3", keydoor, _episode(keydoor))
    files = recording_files(rec, episode_index=3)
    assert set(files) == {".rrd", ".mcap"}
    assert files[".mcap"] == write_mcap(tmp_path / "written.mcap", rec).read_bytes()
    (tmp_path / "handed.rrd").write_bytes(files[".rrd"])
    assert _rows(tmp_path / "handed.rrd") == _rows(write_rrd(tmp_path / "written.rrd", rec, episode_index=3))
    assert RrdReader(str(tmp_path / "handed.rrd")).recordings()[0].recording_id == rec.episode_id


def _protobuf_class(schema):
    """The message class an MCAP protobuf schema (a FileDescriptorSet) describes."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def test_mcap_reads_back_with_foxglove_schemas_and_json_steps(tmp_path, keydoor):
    ep = _episode(keydoor)
    rec = record_from_episode("symbolic/keydoor/fp0.2/seed0/ep0", keydoor, ep)
    path = write_mcap(tmp_path / "ep.mcap", rec)
    topics, schemas, steps, frames = {}, {}, [], []
    with open(path, "rb") as f:  # the reader checks every chunk's CRC as it goes
        for schema, channel, message in make_reader(f, validate_crcs=True).iter_messages():
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema.name
            if channel.topic == "/step":
                steps.append(json.loads(message.data))
            if channel.topic == "/grid":
                grid_schema = schema
                frames.append(message.data)
    assert schemas["/grid"] == "foxglove.RawImage" and schemas["/events"] == "foxglove.Log"
    assert topics["/grid"] == topics["/step"] == ep.length
    assert [s["action"] for s in steps] == ep.actions.tolist()
    assert steps[0]["subgoal"] == "GoTo(key a)" and steps[-1]["state"] == ep.states[-2].tolist()
    assert np.isclose(steps[-1]["return"], ep.ret)
    # the way walked so far is drawn on each frame, under the agent: at every cell centre the path colour where
    # the agent has been before (and is not now), the agent's where it is, neither anywhere else
    raw_image = _protobuf_class(grid_schema)  # decoded through the schema in the file, as Foxglove does
    visited = set()
    for t, frame in enumerate(map(raw_image.FromString, frames)):
        img = np.frombuffer(frame.data, np.uint8).reshape(frame.height, frame.width, 3)
        here = tuple(ep.states[t][:2])
        visited.add(here)
        for r, c in np.ndindex(keydoor.shape):
            centre = tuple(img[r * CELL_PX + CELL_PX // 2, c * CELL_PX + CELL_PX // 2])
            expected = (COLOURS["agent"] if (r, c) == here else tuple(PATH_COLOUR[:3]) if (r, c) in visited and t
                        else None)
            assert (centre == expected) if expected else centre not in (COLOURS["agent"], tuple(PATH_COLOUR[:3]))
    # ... as a line: the last frame has it halfway between the centres of the two cells of every move before it
    cells = ep.states[:len(frames), :2] * CELL_PX + CELL_PX // 2
    moves = [(a + b) // 2 for a, b in zip(cells[:-1], cells[1:]) if (a != b).any()]
    assert moves and all(tuple(img[y, x]) == tuple(PATH_COLOUR[:3]) for y, x in moves)


def test_the_foxglove_layout_opens_the_recorded_topics(tmp_path, keydoor):
    from hnsdt.logs import episode_layout, write_layout

    path = write_layout(tmp_path / "layout.json")
    layout = json.loads(path.read_text())
    assert layout["version"] == 1 and path.read_text() == episode_layout().to_json() + "\n"

    def panels(node):
        if node.get("type") == "panel":
            yield node
        for item in node.get("items", []):
            yield from panels(item["content"])

    found = {p["panelType"]: p["config"] for p in panels(layout["content"])}
    assert set(found) == {"Image", "Log", "Plot", "RawMessages"}
    rec = record_from_episode("symbolic/keydoor/fp0.2/seed0/ep0", keydoor, _episode(keydoor))
    with open(write_mcap(tmp_path / "ep.mcap", rec), "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    named = {found["Image"]["imageMode"]["imageTopic"], found["Log"]["topicToRender"],
             found["RawMessages"]["topicPath"], found["Plot"]["paths"][0]["value"].split(".")[0]}
    assert named == topics == {"/grid", "/events", "/step"}


def test_replay_renders_a_dataset_episode(tmp_path, keydoor):
    from hnsdt.data.collect import Behaviour, CollectConfig, collect_dataset

    cfg = CollectConfig("hnsdt/KeyDoor-v0", keydoor, 40, [0.1], [Behaviour("noisy_planner", 2, "layout", 0.1)])
    root = collect_dataset(cfg, tmp_path / "ds", "local/ds", progress=False)
    out = hnsdt_cli("replay", "--dataset", root, "--episode", "1", "--out", tmp_path / "ep1.rrd")
    assert out.returncode == 0, out.stderr
    assert "GoTo(key a) -> PickKey(a)" in out.stdout
    assert _rows(tmp_path / "ep1.rrd")["/grid"] > 0 and (tmp_path / "ep1.mcap").is_file()
    bad = hnsdt_cli("replay", "--dataset", root, "--episode", "9")
    assert bad.returncode == 2 and "has episodes 0..1" in bad.stderr
