"""Truncated, corrupt and foreign files: clear errors, and recovery of what was written."""

from __future__ import annotations

import pytest
from mcap.writer import Writer

from recordings import NotASessionError, RecordingDamagedError, open_session
from tests.recordings.conftest import step_tuples


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.97])
def test_truncated_file_names_itself_and_what_was_recovered(recorded, tmp_path, keep):
    data = recorded.path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(RecordingDamagedError, match=r"cut\.mcap is truncated or corrupt") as err:
        open_session(cut)
    assert "recovered" in str(err.value) and "recover=True" in str(err.value)
    session = open_session(cut, recover=True)
    assert session.status == "damaged"
    n = len(session)
    assert 0 < n <= len(recorded.frames)
    assert f"recovered {n} complete frames" in str(err.value)
    # what was recovered is exactly the first frames and steps the simulator produced
    assert [f.index for f in session.frames()] == list(range(n))
    for got, sim in zip(session.frames(), recorded.frames, strict=False):
        assert got.state["state"] == sim.step.state and got.color.shape == sim.color.shape
    assert step_tuples(session.steps) == step_tuples(recorded.steps[: len(session.steps)])
    # ground truth is kept for the complete steps only, the ones perception can read
    assert len(session.steps) == n // recorded.config.frames_per_step
    assert len(session.step_frames()) == len(session.steps)


def test_corrupt_chunk_is_caught_by_its_crc(recorded, tmp_path):
    data = bytearray(recorded.path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(RecordingDamagedError, match=r"bad\.mcap is truncated or corrupt"):
        open_session(bad)
    assert 0 < len(open_session(bad, recover=True)) < len(recorded.frames)


def test_file_cut_before_its_session_record_recovers_nothing(recorded, tmp_path):
    stub = tmp_path / "stub.mcap"
    stub.write_bytes(recorded.path.read_bytes()[:12])
    with pytest.raises(RecordingDamagedError, match="recovered nothing"):
        open_session(stub, recover=True)


def test_non_mcap_and_foreign_mcap_files_are_refused(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("hello")
    with pytest.raises(NotASessionError, match=r"notes\.mcap is not an MCAP file"):
        open_session(text)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(NotASessionError, match="not an MCAP file"):
        open_session(empty)
    foreign = tmp_path / "foreign.mcap"
    with foreign.open("wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/x", "json", sid)
        w.add_message(cid, log_time=0, data=b"{}", publish_time=0)
        w.finish()
    with pytest.raises(NotASessionError, match="not an onionsort session"):
        open_session(foreign)
    with pytest.raises(FileNotFoundError, match="no such recording"):
        open_session(tmp_path / "missing.mcap")
