"""A recording stopped by Ctrl-C, SIGTERM or SIGKILL keeps every frame written before it."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time

import pytest

from recordings import RecordingDamagedError, open_session


def _start_and_wait(out, min_bytes=150_000, timeout=60.0):
    """Start a long recording in a subprocess and wait until its file has some frames."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "onionsort.cli", "record", "--sessions", "1",
         "--steps-per-session", "500", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    path = out / "session_000.mcap"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists() and path.stat().st_size > min_bytes:
            return proc, path
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"the recording did not start: {proc.stderr.read().decode()[-2000:]}")


def test_sigkill_leaves_every_flushed_frame_recoverable(tmp_path):
    proc, path = _start_and_wait(tmp_path)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    with pytest.raises(RecordingDamagedError, match=r"session_000\.mcap is truncated"):
        open_session(path)
    session = open_session(path, recover=True)
    assert len(session) >= 3
    assert [f.index for f in session.frames()] == list(range(len(session)))
    assert len(session.demonstration()) == len(session.steps) >= 1
    for frame in session.frames():  # every recovered frame is whole
        assert frame.color.shape == (240, 320, 3) and frame.depth.shape == (240, 320)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_and_sigterm_finish_the_file(tmp_path, sig):
    proc, path = _start_and_wait(tmp_path)
    proc.send_signal(sig)
    assert proc.wait(timeout=30) == 130
    assert "interrupted" in proc.stderr.read().decode()
    session = open_session(path)  # a finished, valid file: no recovery needed
    assert session.status == "interrupted"
    assert len(session) >= 3
    rerun = shutil.which("rerun") or (sys.executable.rsplit("/", 1)[0] + "/rerun")
    if shutil.which(rerun):
        check = subprocess.run([rerun, "mcap", "check", str(path)], capture_output=True)
        assert check.returncode == 0, check.stdout.decode() + check.stderr.decode()


def test_a_signal_during_a_write_is_delivered_after_the_frame_is_whole(recorded, tmp_path,
                                                                       monkeypatch):
    """Ctrl-C that lands while a frame's chunk is going to the file waits for the chunk: the
    interrupt is raised once the frame is counted, and the finished file holds it whole."""
    from mcap.writer import Writer

    from recordings import SessionWriter
    from robot.camera import intrinsics

    real_flush = Writer.flush
    flushed = []

    def interrupted_flush(self):
        signal.raise_signal(signal.SIGINT)  # arrives while the chunk is being written
        real_flush(self)
        flushed.append(True)

    config = recorded.config
    path = tmp_path / "s.mcap"
    # Python's own Ctrl-C handler, whatever this process started with: a shell's background
    # job starts with SIGINT ignored, and a signal ignored stays ignored, held or not
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt), SessionWriter(
                path, {"seed": 4, "config": config.to_dict()}, intrinsics(config.camera),
                intrinsics(config.inspection), frames_per_step=config.frames_per_step) as writer:
            writer.write_frame(recorded.frames[0])
            monkeypatch.setattr(Writer, "flush", interrupted_flush)
            writer.write_frame(recorded.frames[1])
    finally:
        signal.signal(signal.SIGINT, previous)
        monkeypatch.undo()
    assert flushed == [True] and writer.n_frames == 2  # the interrupt waited for the write
    session = open_session(path)  # finished and valid: no recovery needed
    assert session.status == "interrupted"
    assert [f.index for f in session.frames()] == [0, 1]
