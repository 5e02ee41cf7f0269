"""``--connect URL``: the commands that log to Rerun stream to a viewer over gRPC as well.

The viewer is the Rerun CLI's own gRPC server run headless (``rerun --port P --save FILE``),
which writes every message it receives to ``FILE``: what a viewer on another machine would get.
"""

from __future__ import annotations

import socket
import subprocess
import time
import warnings
from pathlib import Path

import pytest
import rerun as rr

from onionsort.cli import main
from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS
from recordings.rerun.common import (
    check_viewer_url,
    close_recording,
    open_recording,
    reach_viewer,
    rerun_targets,
)

rr_chunk = pytest.importorskip("rerun.chunk")


def _rerun_binary() -> Path | None:
    try:
        import rerun_cli
    except ImportError:
        return None
    exe = Path(rerun_cli.__file__).parent / "rerun"
    return exe if exe.is_file() else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Viewer:
    """A headless Rerun gRPC server saving what it receives to ``received``."""

    def __init__(self, folder: Path) -> None:
        exe = _rerun_binary()
        if exe is None:
            pytest.skip("the Rerun CLI binary (rerun_cli) is not installed")
        self.port = _free_port()
        self.url = f"rerun+http://127.0.0.1:{self.port}/proxy"
        self.received = folder / "received.rrd"
        self.proc = subprocess.Popen([str(exe), "--port", str(self.port), "--save",
                                      str(self.received)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                reach_viewer(self.url, timeout=1.0)
                return
            except ConnectionError:
                if self.proc.poll() is not None:
                    break
                time.sleep(0.1)
        self.stop()
        pytest.fail(f"the Rerun server did not start: {self.proc.stderr.read().decode()[-800:]}")

    def stop(self) -> Path:
        """Stop the server (it has written everything it received) and return its file."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.received


@pytest.fixture
def viewer(tmp_path):
    v = Viewer(tmp_path)
    yield v
    v.stop()


def rows(path) -> dict[str, int]:
    """Rows per entity of the recordings (not the blueprints) of an ``.rrd`` file, summed over
    its recordings."""
    with warnings.catch_warnings():  # what the server saves has no footer: read it whole
        warnings.simplefilter("ignore")
        reader = rr_chunk.RrdReader(path)
        out: dict[str, int] = {}
        for entry in reader.recordings():
            for chunk in reader.stream(store=entry):
                if not chunk.entity_path.startswith("/__"):  # the stream's own properties
                    out[chunk.entity_path] = out.get(chunk.entity_path, 0) + chunk.num_rows
    return out


@pytest.mark.slow  # timing-sensitive under load, as below: see the note there
def test_a_stream_goes_whole_to_the_file_and_to_the_viewer(viewer, tmp_path):
    path = tmp_path / "out.rrd"
    rec = open_recording("onionsort_test", rerun_targets(path, viewer.url))
    rec.log("learn/theta", rr.TextDocument("w: +1.0"), static=True)
    for i in range(5):
        rec.set_time("iteration", sequence=i)
        rec.log("learn/objective", rr.Scalars(float(i)))
    assert not path.exists()  # written under a temporary name until closed
    close_recording(rec)
    sent = rows(path)
    assert sent == {"/learn/theta": 1, "/learn/objective": 5}
    assert rows(viewer.stop()) == sent


def test_a_viewer_lost_on_the_way_costs_the_live_view_not_the_file(viewer, tmp_path, caplog):
    path = tmp_path / "out.rrd"
    rec = open_recording("onionsort_test", rerun_targets(path, viewer.url))
    rec.log("learn/theta", rr.TextDocument("w: +1.0"), static=True)
    rec.flush()
    viewer.stop()
    rec.log("learn/policy", rr.TextDocument("s -> a"), static=True)
    with caplog.at_level("WARNING", logger="recordings.rerun.common"):
        close_recording(rec)
    assert f"the Rerun viewer at {viewer.url} did not take the whole recording" in caplog.text
    assert rows(path) == {"/learn/theta": 1, "/learn/policy": 1}
    assert not (tmp_path / "out.rrd.partial").exists()


@pytest.mark.slow  # on a loaded machine the second recording sometimes misses the stopped
# server (1 run in 4 under a training run): delivery at disconnect is not acknowledged yet
def test_record_and_learn_stream_to_the_viewer_what_they_write(viewer, tmp_path, capsys):
    rec = tmp_path / "rec"
    assert main(["record", "--sessions", "1", "--steps-per-session", "3", "--width", "48",
                 "--height", "32", "--out", str(rec), "--rerun", str(rec / "sessions.rrd"),
                 "--connect", viewer.url]) == 0
    # learn from a session with perception topics made from its ground truth (perfect
    # perception: the learner reads only the perception topics)
    session = _perceived_from_truth(rec / "session_000.mcap")
    run = tmp_path / "run"
    assert main(["learn", str(session), "--method", "map-birl", "--observation-model",
                 str(DEFAULT_MODELS / CALIBRATION_FILE), "--allow-model-mismatch",
                 "--out", str(run), "--connect", viewer.url]) == 0
    received = rows(viewer.stop())
    record_rows, learn_rows = rows(rec / "sessions.rrd"), rows(run / "learn.rrd")
    assert any(e.startswith("/record/camera") for e in record_rows)
    assert "/learn/theta" in learn_rows
    # two recordings went to the viewer: each entity holds the rows of both
    assert received == {e: record_rows.get(e, 0) + learn_rows.get(e, 0)
                        for e in {*record_rows, *learn_rows}}


def _perceived_from_truth(path: Path) -> Path:
    from recordings import open_session
    from recordings.session.perception import add_perception

    session = open_session(path)
    steps = session.step_frames()
    docs = [{"step": t.step, "frame": frames[0].index, "occluded": bool(t.occluded),
             "observation": None if t.occluded else session.task.pair(t.state, t.action),
             "state": t.state, "action": t.action}
            for t, frames in zip(session.steps, steps, strict=True)]
    add_perception(path, docs, detections={}, inspection={},
                   frame_times={f.index: f.time_ns for f in session.frames()},
                   models={"folder": "ground truth", "depth": True, "inspection": True})
    return path


@pytest.mark.parametrize("url, why", [
    ("http://127.0.0.1:9876/proxy", "the scheme must be"),
    ("rerun+http://127.0.0.1/proxy", "no port"),
    ("rerun+http://127.0.0.1:98x6/proxy", "the port is not a number"),
    ("rerun+http://:9876/proxy", "no host"),
    ("rerun+http://127.0.0.1:9876/", "the path must be /proxy"),
])
def test_a_bad_url_is_refused_naming_what_is_wrong(url, why):
    with pytest.raises(ValueError, match=why):
        check_viewer_url(url)
    # a recording refuses it too (one with no gRPC scheme is no target at all)
    with pytest.raises(ValueError, match=why if url.startswith("rerun") else "target must be"):
        open_recording("onionsort_test", url)


@pytest.mark.parametrize("url", ["rerun+http://127.0.0.1:9876/proxy",
                                 "rerun+https://viewer.example.org:443/proxy",
                                 "rerun://[::1]:9876/proxy"])
def test_good_urls_pass(url):
    assert check_viewer_url(url) == url


def test_nothing_listening_fails_before_any_work(tmp_path, capsys):
    url = f"rerun+http://127.0.0.1:{_free_port()}/proxy"
    out = tmp_path / "rec"
    assert main(["record", "--sessions", "1", "--out", str(out), "--connect", url]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"onionsort record: error: no Rerun viewer answers at {url} "
                                "(Connection refused); start one there (`rerun`) or give its "
                                "address"]
    assert not out.exists()


def test_targets_combine_files_and_urls_but_not_spawn(tmp_path):
    assert rerun_targets(None, None) is None
    assert rerun_targets(tmp_path / "a.rrd", None) == tmp_path / "a.rrd"
    assert rerun_targets(None, "rerun+http://h:1/proxy") == "rerun+http://h:1/proxy"
    assert rerun_targets(tmp_path / "a.rrd", "rerun+http://h:1/proxy") == (
        tmp_path / "a.rrd", "rerun+http://h:1/proxy")
    with pytest.raises(ValueError, match="'spawn' cannot be combined"):
        open_recording("onionsort_test", ["spawn", tmp_path / "a.rrd"])
    assert not (tmp_path / "a.rrd.partial").exists()

