"""The task description travels with the data: session metadata, dataset.json, Rerun text."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from irl.domains.onion_sorting import SORTING_TASK
from irl.domains.task import TaskDescription
from recordings import SessionWriter, open_session
from recordings.labels.dataset import DatasetWriter, dataset_task, read_split
from recordings.session.schema import SESSION_METADATA

#: A made-up task of two factors (2 x 3 = 6 states) and two actions.
TOY = TaskDescription("toy-room", {"light": ("off", "on"), "door": ("closed", "open", "ajar")},
                      action_names=("wait", "toggle"), feature_names=("lit",))
K = np.array([[50.0, 0.0, 8.0], [0.0, 50.0, 6.0], [0.0, 0.0, 1.0]])
FPS = 2


@dataclass(frozen=True)
class Step:
    step: int
    state: int
    action: int
    next_state: int
    occluded: bool


@dataclass(frozen=True)
class Frame:
    """A tiny frame satisfying ``recordings.session.frames.TruthFrame`` without a simulator."""

    index: int
    step: Step
    phase: int
    time_s: float
    color: np.ndarray = field(default_factory=lambda: np.full((12, 16, 3), 90, np.uint8))
    depth: np.ndarray = field(default_factory=lambda: np.full((12, 16), 1.5, np.float32))
    onions: tuple = ()
    occluded_fraction: float = 0.0
    inspection: np.ndarray | None = None
    inspection_onions: tuple = ()


def toy_frames(task: TaskDescription = TOY, n_steps: int = 5) -> list[Frame]:
    """``n_steps`` steps of ``FPS`` frames through the states of ``task``; step 2 occluded."""
    frames = []
    for t in range(n_steps):
        s, a = (3 * t + 1) % task.n_states, t % task.n_actions
        step = Step(t, s, a, (s + 1) % task.n_states, occluded=t == 2)
        frames += [Frame(t * FPS + p, step, p, (t * FPS + p) / 10.0) for p in range(FPS)]
    return frames


def write_session(path: Path, frames: list[Frame], **kwargs) -> Path:
    with SessionWriter(path, {"seed": 0}, K, frames_per_step=FPS, **kwargs) as writer:
        for frame in frames:
            writer.write_frame(frame)
    return path


def without_task(source: Path, target: Path) -> Path:
    """A copy of ``source`` whose session record lacks ``"task"`` (a file from before it)."""
    with source.open("rb") as fh:
        reader = make_reader(fh)
        metadata = list(reader.iter_metadata())
        messages = list(reader.iter_messages(log_time_order=False))
    with target.open("wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="", library="test")
        for m in metadata:
            if m.name == SESSION_METADATA:
                writer.add_metadata(m.name, {k: v for k, v in m.metadata.items() if k != "task"})
        schemas, channels = {}, {}
        for sch, ch, msg in messages:
            if sch.id not in schemas:
                schemas[sch.id] = writer.register_schema(sch.name, sch.encoding, sch.data)
            if ch.id not in channels:
                channels[ch.id] = writer.register_channel(ch.topic, ch.message_encoding,
                                                          schemas[sch.id])
            writer.add_message(channels[ch.id], log_time=msg.log_time, data=msg.data,
                               publish_time=msg.publish_time, sequence=msg.sequence)
        for m in metadata:
            if m.name != SESSION_METADATA:
                writer.add_metadata(m.name, dict(m.metadata))
        writer.finish()
    return target


def test_the_sorting_task_is_stored_in_a_recorded_session(recorded):
    session = open_session(recorded.path)
    assert session.metadata["task"] == SORTING_TASK.to_dict()
    assert session.task == SORTING_TASK
    demo = session.demonstration()
    expected = [None if s.occluded else SORTING_TASK.pair(s.state, s.action)
                for s in recorded.steps]
    assert list(demo.observations) == expected
    truth = next(f.state for f in session.frames() if f.state is not None)
    values = SORTING_TASK.decode(truth["state"])
    assert {k: truth[k] for k in values} == {
        k: SORTING_TASK.value_name(k, v) for k, v in values.items()}


def test_a_made_up_task_round_trips_through_a_session(tmp_path):
    frames = toy_frames()
    session = open_session(write_session(tmp_path / "toy.mcap", frames, task=TOY))
    assert session.task == TOY
    assert TaskDescription.from_dict(session.metadata["task"]) == TOY
    for frame, read in zip(frames, session.frames(), strict=True):
        values = TOY.decode(frame.step.state)
        assert {k: read.state[k] for k in TOY.factor_names} == {
            k: TOY.value_name(k, v) for k, v in values.items()}
        assert "onion" not in read.state
    steps = frames[::FPS]
    assert list(session.demonstration().observations) == [
        None if f.step.occluded else TOY.pair(f.step.state, f.step.action) for f in steps]
    with session.path.open("rb") as fh:
        names = [json.loads(m.data)["action_name"]
                 for _, _, m in make_reader(fh).iter_messages(topics=["/ground_truth/action"])]
    assert names == [TOY.action_names[f.step.action] for f in steps]


def test_a_session_without_a_task_reads_as_onion_sorting(tmp_path, recorded):
    old = without_task(Path(recorded.path), tmp_path / "old.mcap")
    session = open_session(old)
    assert "task" not in session.metadata
    assert session.task == SORTING_TASK
    assert session.demonstration() == open_session(recorded.path).demonstration()


def test_the_writer_refuses_a_task_it_cannot_write(tmp_path):
    clash = TaskDescription("clash", {"state": ("a", "b")}, action_names=("x",),
                            feature_names=("f",))
    with pytest.raises(ValueError, match=r"factors \['state'\] clash"):
        SessionWriter(tmp_path / "a.mcap", {}, K, frames_per_step=FPS, task=clash)
    with pytest.raises(ValueError, match="must not hold 'task'"):
        SessionWriter(tmp_path / "b.mcap", {"task": "x"}, K, frames_per_step=FPS)
    with pytest.raises(TypeError, match="task must be a TaskDescription"):
        SessionWriter(tmp_path / "c.mcap", {}, K, frames_per_step=FPS,
                      task=TOY.to_dict())  # type: ignore[arg-type]


def test_a_session_with_a_broken_task_is_refused(tmp_path):
    from recordings.session.reader import NotASessionError
    from recordings.session.rewrite import rewrite_session

    path = write_session(tmp_path / "toy.mcap", toy_frames(), task=TOY)
    rewrite_session(path, session_update={"task": json.dumps({"name": "x"})})
    with pytest.raises(NotASessionError, match="task is not a task description"):
        open_session(path)


def test_a_made_up_task_round_trips_through_a_dataset(tmp_path):
    writer = DatasetWriter(tmp_path / "toy", {"seed": 1}, task=TOY)
    frames = toy_frames()
    for frame in frames:
        writer.add("train", frame, session=0)
    writer.close()
    doc = json.loads((tmp_path / "toy" / "dataset.json").read_text())
    assert doc["task"] == TOY.to_dict()
    assert dataset_task(tmp_path / "toy") == TOY
    records = [f.record for f in read_split(tmp_path / "toy", "train")]
    assert [{k: r[k] for k in TOY.factor_names} for r in records] == [
        TOY.decode(f.step.state) for f in frames]
    assert all("onion" not in r for r in records)


def test_the_default_dataset_task_and_a_dataset_from_before_it(tmp_path):
    writer = DatasetWriter(tmp_path / "d", {"seed": 1})
    writer.close()
    assert dataset_task(tmp_path / "d") == SORTING_TASK
    path = tmp_path / "d" / "dataset.json"
    doc = json.loads(path.read_text())
    del doc["task"]
    path.write_text(json.dumps(doc))
    assert dataset_task(tmp_path / "d") == SORTING_TASK
    with pytest.raises(ValueError, match="must not hold 'task'"):
        DatasetWriter(tmp_path / "e", {"task": 1})
    with pytest.raises(FileNotFoundError, match="not a dataset folder"):
        dataset_task(tmp_path / "nothing")


def test_rerun_text_and_series_follow_the_task(tmp_path):
    pytest.importorskip("rerun")
    from types import SimpleNamespace

    from onionsort.stages.evaluate_rerun import _describe
    from recordings.rerun.common import factor_values, value_labels
    from recordings.rerun.perceive import _observation_text
    from recordings.rerun.session import SessionLogger, _state_text

    session = open_session(write_session(tmp_path / "toy.mcap", toy_frames(), task=TOY))
    frame = next(iter(session.frames()))  # step 0: state 1 = (off, open), action wait
    assert "**state** 1: light=off, door=open" in _state_text(frame, TOY)
    assert "**action** wait" in _state_text(frame, TOY)
    assert factor_values(TOY) == {**TOY.factors, "action": TOY.action_names}
    assert value_labels(TOY.action_names) == "0=wait, 1=toggle"
    event = SimpleNamespace(step=0, state=1, action=1, next_state=4, onion=None, blemished=None,
                            perceived=None, fate=None)
    assert _describe(event, TOY)[0] == "#0 toggle: (off, open) -> (on, open)"
    msg = {"step": 0, "occluded": False, "observation": 3, "state": 1, "light": 0, "door": 1,
           "action": 1}
    text, _ = _observation_text(msg, factor_values(TOY))
    assert "(light=off, door=open, action=toggle)" in text
    rrd = tmp_path / "toy.rrd"
    with SessionLogger(rrd) as logger:
        logger.log_session(session, 0)
    from rerun.chunk import RrdReader

    rows: dict[str, int] = {}
    for chunk in RrdReader(rrd).store().stream():
        if not chunk.is_static:
            path = chunk.entity_path.lstrip("/")
            rows[path] = rows.get(path, 0) + chunk.num_rows
    for name in ("light", "door", "action"):
        assert rows[f"record/truth/factors/{name}"] == 5, name
    assert "record/truth/factors/onion" not in rows
