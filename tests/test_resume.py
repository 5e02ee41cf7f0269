"""``record --resume`` and ``demo --resume``: an interrupted run, resumed, gives what an
uninterrupted run with the same seed gives."""

from __future__ import annotations

import importlib
import importlib.util
import json
import shutil

import pytest
from mcap.reader import make_reader

from onionsort.cli import main
from recordings import SessionWriter, open_session

#: The tiny recording of these tests: 2 sessions of 4 steps, small images, recorded in this
#: process (the interruptions are made by patching it).
RECORD = ["record", "--workers", "1", "--sessions", "2", "--steps-per-session", "4",
          "--frames-per-step", "2", "--width", "48", "--height", "32", "--seed", "3"]


def mcap_content(path) -> tuple[list, list]:
    """Every metadata record (the creation time aside) and every message (topic, times,
    bytes) of an MCAP file, read with CRC validation."""
    with open(path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        messages = [(channel.topic, message.log_time, message.publish_time, message.sequence,
                     message.data) for _, channel, message in reader.iter_messages()]
        metadata = [(m.name, {k: v for k, v in m.metadata.items() if k != "created_utc"})
                    for m in reader.iter_metadata()]
    return metadata, messages


def interrupt_at(monkeypatch, session: str, frame: int) -> None:
    """Make the next recording stop with Ctrl-C when ``session`` has ``frame`` frames."""
    write_frame = SessionWriter.write_frame

    def stopping(self, *args, **kwargs):
        if self.path.name == session and self.n_frames == frame:
            raise KeyboardInterrupt
        return write_frame(self, *args, **kwargs)

    monkeypatch.setattr(SessionWriter, "write_frame", stopping)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("record") / "whole"
    assert main([*RECORD, "--out", str(out), "--rerun", str(out / "sessions.rrd")]) == 0
    return out


@pytest.mark.parametrize("how", ["interrupted", "killed"])
def test_record_resume_keeps_complete_sessions_and_redoes_the_interrupted_one(
        uninterrupted, tmp_path, monkeypatch, capsys, how):
    out = tmp_path / "rec"
    argv = [*RECORD, "--out", str(out), "--rerun", str(out / "sessions.rrd")]
    with monkeypatch.context() as m:
        interrupt_at(m, "session_001.mcap", 5)
        assert main(argv) == 130
    second = out / "session_001.mcap"
    assert open_session(second).status == "interrupted"
    if how == "killed":  # what SIGKILL leaves: no summary or footer, and a stray temporary
        second.write_bytes(second.read_bytes()[: second.stat().st_size * 2 // 3])
        (out / "session_001.mcap.partial").write_bytes(b"header of a session being opened")
    first = out / "session_000.mcap"
    kept = (first.stat().st_ino, first.stat().st_mtime_ns, first.read_bytes())
    # Ctrl-C finished the Rerun file with the first session alone
    assert _rrd_rows(out / "sessions.rrd") != _rrd_rows(uninterrupted / "sessions.rrd")

    # without --resume an existing recording is refused, and the message says how to resume
    assert main(argv) == 2
    assert "--resume" in capsys.readouterr().err

    assert main([*argv, "--resume"]) == 0
    assert (first.stat().st_ino, first.stat().st_mtime_ns, first.read_bytes()) == kept
    names = sorted(p.name for p in out.iterdir())
    assert names == ["session_000.mcap", "session_001.mcap", "sessions.rrd"]
    for name in ("session_000.mcap", "session_001.mcap"):
        session = open_session(out / name)
        assert session.status == "complete" and len(session.step_frames()) == 4
        assert mcap_content(out / name) == mcap_content(uninterrupted / name), name
    # the Rerun recording holds every session, as the uninterrupted run's does
    assert _rrd_rows(out / "sessions.rrd") == _rrd_rows(uninterrupted / "sessions.rrd")

    # resuming a finished recording records nothing
    before = {p.name: p.stat().st_mtime_ns for p in out.glob("*.mcap")}
    assert main([*argv, "--resume"]) == 0
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.mcap")} == before


def _rrd_rows(path) -> dict[str, int]:
    """Rows per entity of an ``.rrd`` file."""
    from rerun.chunk import RrdReader

    rows: dict[str, int] = {}
    for chunk in RrdReader(path).store().stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return rows


def test_record_resume_refuses_a_recording_made_with_other_settings(uninterrupted, tmp_path,
                                                                      capsys):
    out = tmp_path / "rec"
    shutil.copytree(uninterrupted, out)
    given = {p: p.read_bytes() for p in out.iterdir()}
    argv = [a if a != "3" else "4" for a in RECORD]  # another --seed
    assert main([*argv, "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "recorded with other settings (seed, session_seed differ)" in err
    assert {p: p.read_bytes() for p in out.iterdir()} == given
    assert main([*RECORD, "--steps-per-session", "5", "--out", str(out), "--resume"]) == 2
    assert "config.n_steps differ" in capsys.readouterr().err


def test_record_resume_into_an_empty_folder_records_everything(uninterrupted, tmp_path):
    out = tmp_path / "fresh"
    assert main([*RECORD, "--out", str(out), "--resume"]) == 0
    for name in ("session_000.mcap", "session_001.mcap"):
        assert mcap_content(out / name) == mcap_content(uninterrupted / name)


# --- demo --------------------------------------------------------------------------------

DEMO = ["demo", "--quick", "--workers", "1", "--sessions", "2"]
#: Timings, the only numbers of results.json that may differ between two runs.
TIMINGS = ("seconds", "learn_seconds")


#: What names a forward-backward backend, which changes no other number of a resumed demo.
BACKEND = ("backend", "backends")


def _without_timings(doc, also=()):
    if isinstance(doc, dict):
        return {k: _without_timings(v, also) for k, v in doc.items()
                if k not in TIMINGS and k not in also}
    if isinstance(doc, list):
        return [_without_timings(v, also) for v in doc]
    return doc


class Spy:
    """Counts the calls of a demo stage function (calling through; ``args`` holds the first
    argument of each), and can interrupt the ``n``-th like Ctrl-C."""

    def __init__(self, monkeypatch, name: str, interrupt_at: int | None = None) -> None:
        stage = importlib.import_module("onionsort.stages.demo")  # the module, not the function
        self.calls, self.args = 0, []
        self.real = getattr(stage, name)
        self.interrupt_at = interrupt_at
        monkeypatch.setattr(stage, name, self)

    def __call__(self, *args, **kwargs):
        self.calls += 1
        self.args.append(args[0] if args else None)
        if self.calls == self.interrupt_at:
            raise KeyboardInterrupt
        return self.real(*args, **kwargs)


def test_demo_refuses_to_resume_another_demo_or_to_mix_into_one(tmp_path, monkeypatch, capsys):
    out = tmp_path / "demo"
    with monkeypatch.context() as m:
        heldout = Spy(m, "make_dataset", interrupt_at=1)  # stopped in its first stage
        assert main([*DEMO, "--out", str(out)]) == 130
    assert heldout.args[0].workers == 1  # the held-out frames render where the demo was told
    assert json.loads((out / "progress" / "config.json").read_text())["sessions"] == 2
    given = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main([*DEMO, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "already holds files of an earlier or interrupted run: progress" in err
    assert "pass --resume to continue it" in err
    assert main([*DEMO, "--seed", "1", "--resume", "--out", str(out)]) == 2
    assert ("holds a demo started with other settings (seed 0 there, 1 now); resume with the "
            "settings it was started with") in capsys.readouterr().err
    assert main([*DEMO[:-1], "3", "--resume", "--out", str(out)]) == 2
    assert "(sessions 2 there, 3 now)" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == given


@pytest.mark.slow
def test_demo_resumed_twice_gives_the_uninterrupted_results(tmp_path, monkeypatch):
    whole, out = tmp_path / "whole", tmp_path / "demo"
    assert main([*DEMO, "--out", str(whole)]) == 0

    # 1. stopped while recording its second session
    with monkeypatch.context() as m:
        interrupt_at(m, "session_001.mcap", 5)
        assert main([*DEMO, "--out", str(out)]) == 130
    done = sorted(p.stem for p in (out / "progress").glob("*.json"))
    assert done == ["calibrate", "config", "heldout"]
    assert open_session(out / "sessions" / "session_001.mcap").status == "interrupted"

    # 2. resumed, and stopped again as the second method's policy is evaluated
    with monkeypatch.context() as m:
        calibrate, record = Spy(m, "calibrate"), Spy(m, "record")
        Spy(m, "evaluate", interrupt_at=2)
        assert main([*DEMO, "--resume", "--out", str(out)]) == 130
    assert (calibrate.calls, record.calls) == (0, 1)
    assert (out / "progress" / "learn-0-map-birl.json").is_file()
    assert not (out / "progress" / "evaluate-0-map-birl.json").exists()

    # 3. resumed to the end, with the other forward-backward backend where numba is installed
    # (equal to rounding): only what was not finished runs
    backend = "numba" if importlib.util.find_spec("numba") else "numpy"
    with monkeypatch.context() as m:
        spies = {name: Spy(m, name) for name in ("make_dataset", "calibrate", "record",
                                                  "perceive", "learn", "evaluate")}
        assert main([*DEMO, "--resume", "--backend", backend, "--out", str(out)]) == 0
    assert {k: s.calls for k, s in spies.items()} == {
        "make_dataset": 0, "calibrate": 0, "record": 0, "perceive": 0, "learn": 1,
        "evaluate": 2}
    (resumed,) = spies["learn"].args
    assert resumed.method == "hidden-data-em" and resumed.backend == backend

    results = json.loads((out / "results.json").read_text())
    expected = json.loads((whole / "results.json").read_text())
    assert results["backends"] == sorted({"numpy", backend})
    assert [r["backend"] for m in ("mmap-birl", "map-birl", "hidden-data-em")
            for r in results["methods"][m]["per_repeat"]] == ["numpy", "numpy", backend]
    assert _without_timings(results, BACKEND) == _without_timings(expected, BACKEND)
    for name in ("session_000.mcap", "session_001.mcap"):
        assert mcap_content(out / "sessions" / name) == mcap_content(whole / "sessions" / name)
    for method in ("mmap-birl", "map-birl", "hidden-data-em"):
        for name in ("model.json", "evaluation.json"):
            # model.json names its sessions and calibration by their paths in the run folder
            mine = json.loads((out / method / name).read_text().replace(str(out), str(whole)))
            assert _without_timings(mine, BACKEND) == _without_timings(
                json.loads((whole / method / name).read_text()), BACKEND), (method, name)
    assert sorted(p.relative_to(out) for p in out.rglob("*.rrd")) == sorted(
        p.relative_to(whole) for p in whole.rglob("*.rrd"))
    assert not list(out.rglob("*.partial"))

    # a finished demo resumed is left as it is
    before = (out / "results.json").read_bytes()
    assert main([*DEMO, "--resume", "--out", str(out)]) == 0
    assert (out / "results.json").read_bytes() == before
