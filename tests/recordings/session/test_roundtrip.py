"""What the reader gives back is what the simulator did."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from irl.demonstrations import Demonstration
from irl.domains.onion_sorting import N_ACTIONS
from recordings import SessionWriter, open_session, read_demonstrations
from recordings.session.schema import Topic
from tests.recordings.conftest import step_tuples


def test_demonstration_from_ground_truth_equals_what_the_simulator_did(recorded):
    session = open_session(recorded.path)
    states = [s.state for s in recorded.steps]
    actions = [s.action for s in recorded.steps]
    occluded = [s.occluded for s in recorded.steps]
    expected = Demonstration.from_pairs(states, actions, N_ACTIONS, occluded=occluded)
    assert session.demonstration() == expected
    assert step_tuples(session.steps) == step_tuples(recorded.steps)
    assert np.array_equal(session.trajectory().states, states)
    assert session.demonstration().n_occluded == sum(occluded)
    assert read_demonstrations([recorded.path]) == [expected]


def test_frames_and_labels_round_trip(recorded):
    session = open_session(recorded.path)
    assert session.status == "complete"
    assert session.metadata["seed"] == 4
    assert session.metadata["config"]["n_steps"] == 12
    assert len(session) == len(recorded.frames)
    for got, sim in zip(session.frames(), recorded.frames, strict=True):
        assert got.index == sim.index and got.step == sim.step.step
        assert got.state["state"] == sim.step.state and got.state["action"] == sim.step.action
        assert got.occluded == sim.step.occluded
        boxes = {b["onion_id"]: (b["x_min"], b["y_min"], b["x_max"], b["y_max"], b["class_id"])
                 for b in got.boxes}
        expected = {o.onion_id: (*o.box, int(o.blemished)) for o in sim.onions if o.box}
        assert boxes == expected
        assert [o["blemished"] for o in got.onions] == [o.blemished for o in sim.onions]
        assert np.abs(got.depth - sim.depth).max() <= 0.0005 + 1e-6
        color = got.color
        assert color.shape == sim.color.shape
        assert np.abs(color.astype(int) - sim.color).mean() < 6  # JPEG
        assert (got.inspection is not None) == (sim.inspection is not None)
        if sim.inspection is not None:
            assert np.array_equal(got.inspection, sim.inspection)  # PNG is lossless


def test_file_passes_a_crc_validating_read_with_the_mcap_reader(recorded):
    with open(recorded.path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts = {}
        for _, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.message_encoding == "json":
                json.loads(message.data)
    n_frames, n_steps = len(recorded.frames), len(recorded.steps)
    assert topics[Topic.COLOR] == "foxglove.CompressedImage"
    assert topics[Topic.DEPTH] == "foxglove.RawImage"
    assert topics[Topic.CALIBRATION] == "foxglove.CameraCalibration"
    assert topics[Topic.ANNOTATIONS] == "foxglove.ImageAnnotations"
    assert counts[Topic.ANNOTATIONS] == n_frames
    assert counts[Topic.COLOR] == counts[Topic.DEPTH] == counts[Topic.STATE] == n_frames
    assert counts[Topic.ACTION] == n_steps
    assert counts[Topic.INSPECTION] == n_frames  # the inspection camera renders every frame
    assert summary.statistics.chunk_count == n_frames  # one chunk per frame


def test_writer_refuses_to_overwrite(recorded):
    with pytest.raises(FileExistsError, match="exists"):
        SessionWriter(recorded.path, {}, np.eye(3), np.eye(3), frames_per_step=2)


def test_a_format_1_session_still_opens_with_its_steps_from_ground_truth(recorded, tmp_path):
    """Version 1 had no step clock; the reader takes step and phase from /ground_truth/state."""
    from recordings import strip_ground_truth
    from recordings.session.rewrite import rewrite_session

    old = rewrite_session(recorded.path, tmp_path / "v1.mcap", drop_topics=(Topic.STEP_CLOCK,),
                          session_update={"format_version": "1"})
    v1, v2 = open_session(old), open_session(recorded.path)
    assert v1.metadata["format_version"] == 1 and v1.has_ground_truth and v1.has_depth
    assert [(f.index, f.step, f.phase) for f in v1.frames()] == [
        (f.index, f.step, f.phase) for f in v2.frames()]
    assert v1.demonstration() == v2.demonstration()
    with pytest.raises(ValueError, match="format-1 session"):
        strip_ground_truth(old, tmp_path / "bare.mcap")
    assert not (tmp_path / "bare.mcap").exists()
