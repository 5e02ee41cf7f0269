"""The stages' executor: the same results on 1 worker, 2 workers and Ray; a failing piece or a
killed worker is one line naming the piece."""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from onionsort.cli import main
from onionsort.stages.parallel import ParallelOptions, WorkerLost, run_pieces, worker_threads
from recordings import open_session


def square(x: int) -> tuple[int, int, int | None]:
    return x * x, os.getpid(), worker_threads()


def evaluate_threads(out: Path) -> int:
    """Sort two onions with the expert's policy (a stage that runs torch) with the models the
    worker loaded, as the demo does; torch's threads after it."""
    import torch

    from onionsort.stages.evaluate import EvaluateConfig, evaluate
    from onionsort.stages.models import PerceptionModels

    evaluate(EvaluateConfig(run=None, policy="expert", out=out, onions=2, blemished=1,
                            rerun=False, mcap=False), PerceptionModels.load_cached(None, "cpu"))
    return torch.get_num_threads()


def refuse_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    if x == 4:
        raise ZeroDivisionError("division by zero")
    return x


def killed_on_two(x: int) -> int:
    if x == 2:
        os.kill(os.getpid(), signal.SIGKILL)
    return x


def working_folder(_: int) -> str:
    return os.getcwd()


def run(fn, pieces, **options):
    return dict(run_pieces(fn, pieces, ParallelOptions(**options),
                           names=[f"piece {p}" for p in pieces], desc="test", progress=False))


def test_pieces_give_the_same_results_here_and_on_two_workers():
    here = run(square, range(6), workers=1)
    pool = run(square, range(6), workers=2)
    assert {i: r[0] for i, r in here.items()} == {i: r[0] for i, r in pool.items()}
    assert {r[1] for r in here.values()} == {os.getpid()}  # no pool at all
    assert os.getpid() not in {r[1] for r in pool.values()}
    assert {r[2] for r in pool.values()} == {1}  # each worker runs one thread
    assert worker_threads() is None  # this process is no worker: its threads are untouched


def test_a_stage_in_a_worker_keeps_torch_on_one_thread(tmp_path):
    """Two workers on two cores: a stage's own thread setting must not undo the worker's one
    thread (two pools of two threads each made every evaluation of the demo three times
    slower)."""
    threads = run(evaluate_threads, [tmp_path / "a", tmp_path / "b"], workers=2)
    assert set(threads.values()) == {1}
    assert len(json.loads((tmp_path / "a" / "evaluation.json").read_text())["onions"]) == 2


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_piece_is_named(workers):
    with pytest.raises(ValueError, match=r"^piece 3: three is not allowed$"):
        run(refuse_three, [0, 1, 2, 3], workers=workers)
    with pytest.raises(RuntimeError, match=r"^piece 4 failed \(ZeroDivisionError: division"):
        run(refuse_three, [4], workers=workers)


def test_a_killed_worker_names_its_piece():
    with pytest.raises(WorkerLost, match=r"worker process died .* running piece 2"):
        run(killed_on_two, [0, 1, 2, 3, 4, 5], workers=2)


@pytest.mark.parametrize("bad", [0, -2, 1.5, True])
def test_bad_workers_are_refused(bad):
    with pytest.raises(ValueError, match="workers must be >= 1"):
        ParallelOptions(workers=bad)
    with pytest.raises(ValueError, match="executor must be one of local, ray"):
        ParallelOptions(executor="threads")


def test_default_workers_leave_a_core_to_each_thread_of_a_piece(monkeypatch, tmp_path):
    from onionsort.configs import parallel
    from onionsort.stages.calibrate import CalibrateConfig
    from onionsort.stages.perceive import PerceiveConfig
    from onionsort.stages.record import RecordConfig

    assert [parallel.default_workers(1, cores) for cores in (1, 2, 16)] == [1, 2, 16]
    assert [parallel.default_workers(2, cores) for cores in (1, 2, 3, 16)] == [1, 1, 1, 8]
    monkeypatch.setattr(parallel, "machine_cores", lambda: 2)
    session = tmp_path / "a.mcap"
    session.touch()
    perceive = PerceiveConfig(sessions=(session,))
    calibrate = CalibrateConfig(data=Path("d"), out=Path("o"))
    record = RecordConfig(out=Path("o"))
    # on two cores, one piece's torch keeps both busy: perceive and calibrate run in the
    # command; record (one thread a piece) gets both cores
    assert (perceive.n_workers, calibrate.n_workers, record.n_workers) == (1, 1, 2)
    assert perceive.parallel_options().workers == 1  # resolved for run_pieces
    # an explicit count is obeyed, and a stage handed another's options keeps its count
    assert PerceiveConfig(sessions=(session,), workers=2).n_workers == 2
    handed = CalibrateConfig(data=Path("d"), out=Path("o"),
                             **vars(record.parallel_options()))
    assert handed.n_workers == 2
    monkeypatch.setattr(parallel, "machine_cores", lambda: 16)
    assert (perceive.n_workers, record.n_workers) == (8, 16)
    ray = ParallelOptions(executor="ray")
    assert ray.parallel_options().workers is None  # a new Ray instance's CPUs: the cores


RECORD = ["record", "--sessions", "3", "--steps-per-session", "3", "--frames-per-step", "3",
          "--seed", "5"]


def frames_of(path: Path) -> list[tuple]:
    return [(f.index, f.step, f.phase, f.time_ns, f.color_jpeg, f.depth_raw, f.inspection_png,
             json.dumps(f.state, sort_keys=True)) for f in open_session(path).frames()]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict[int, Path]:
    """The same recording on one worker and on two."""
    out = {}
    for workers in (1, 2):
        folder = tmp_path_factory.mktemp(f"rec{workers}")
        assert main([*RECORD, "--workers", str(workers), "--out", str(folder)]) == 0
        out[workers] = folder
    return out


def test_record_on_two_workers_writes_what_one_writes(recorded):
    for name in ("session_000.mcap", "session_001.mcap", "session_002.mcap"):
        assert frames_of(recorded[2] / name) == frames_of(recorded[1] / name)


def test_a_pool_forks_only_from_a_process_without_threaded_libraries(monkeypatch):
    from onionsort.stages import parallel

    monkeypatch.setattr(sys, "platform", "linux")
    for name in parallel._THREADED:
        monkeypatch.delitem(sys.modules, name, raising=False)
    assert parallel._start_method() == "fork"
    monkeypatch.setitem(sys.modules, "torch", object())
    assert parallel._start_method() == "forkserver"
    monkeypatch.setattr(sys, "platform", "darwin")
    monkeypatch.delitem(sys.modules, "torch")
    assert parallel._start_method() == "forkserver"
    monkeypatch.setattr(sys, "platform", "win32")
    assert parallel._start_method() == "spawn"


def test_record_on_forked_workers_writes_what_one_writes(recorded, tmp_path):
    """A fresh command has loaded no threaded library when it records, so its workers are
    forked from it (this test process has torch loaded, so the fixture's pool was not)."""
    import subprocess

    out = tmp_path / "forked"
    done = subprocess.run([sys.executable, "-m", "onionsort.cli", "-v", *RECORD, "--workers",
                           "2", "--out", str(out)], capture_output=True, text=True, check=True)
    assert "a local pool of 2 workers (fork)" in done.stderr
    for name in ("session_000.mcap", "session_001.mcap", "session_002.mcap"):
        assert frames_of(out / name) == frames_of(recorded[1] / name)


def _perceived_copies(recorded, tmp_path, *runs: list[str]) -> list[list[Path]]:
    out = []
    for k, extra in enumerate(runs):
        folder = tmp_path / f"p{k}"
        folder.mkdir()
        paths = []
        for src in sorted(recorded[1].glob("*.mcap")):
            paths.append(folder / src.name)
            paths[-1].write_bytes(src.read_bytes())
        assert main(["perceive", *map(str, paths), *extra]) == 0
        out.append(paths)
    return out


def same_perception(a: Path, b: Path) -> None:
    """The same perceived demonstration, and the same detections to float rounding: torch
    sums in another order on another number of threads (one in a worker, two here)."""
    da, db = open_session(a).perceived_demonstration(), open_session(b).perceived_demonstration()
    assert list(da.observations) == list(db.observations)
    assert list(da.occluded) == list(db.occluded)
    for topic in ("/perception/detections", "/perception/state"):
        xa, xb = perception_numbers(a, topic), perception_numbers(b, topic)
        assert len(xa) == len(xb) > 0
        np.testing.assert_allclose(xa, xb, atol=1e-4)


def perception_numbers(path: Path, topic: str) -> np.ndarray:
    """Every number of a perception topic's JSON messages, in order."""
    from mcap.reader import make_reader

    def numbers(x):
        if isinstance(x, dict):
            return [n for k in sorted(x) for n in numbers(x[k])]
        if isinstance(x, list):
            return [n for v in x for n in numbers(v)]
        return [float(x)] if isinstance(x, int | float) else []

    with open(path, "rb") as f:
        return np.asarray([n for _, _, m in make_reader(f).iter_messages(topics=[topic])
                           for n in numbers(json.loads(m.data))])


def test_perceive_on_two_workers_perceives_what_one_does(recorded, tmp_path):
    one, two = _perceived_copies(recorded, tmp_path, ["--workers", "1"], ["--workers", "2"])
    for a, b in zip(one, two, strict=True):
        same_perception(a, b)


def test_perceive_on_forked_workers_perceives_what_one_does(recorded, tmp_path):
    """The command loads no torch when its workers perceive (they load the models), so its
    pool forks from it, as record's does."""
    import subprocess

    (one,) = _perceived_copies(recorded, tmp_path, ["--workers", "1"])
    paths = []
    for src in sorted(recorded[1].glob("*.mcap")):
        paths.append(tmp_path / src.name)
        paths[-1].write_bytes(src.read_bytes())
    done = subprocess.run([sys.executable, "-m", "onionsort.cli", "-v", "perceive",
                           *map(str, paths), "--workers", "2"], capture_output=True, text=True,
                          check=True)
    assert "a local pool of 2 workers (fork)" in done.stderr
    for a, b in zip(one, paths, strict=True):
        same_perception(a, b)


def test_a_checkpoints_config_reads_without_torch(tmp_path):
    """The command checks the sessions' frame counts from the classifier's checkpoint without
    loading torch (its workers load the models); what it reads is what loading gives, and a
    file that is no checkpoint gives None (loading then says what is wrong)."""
    import subprocess

    from onionsort.stages.models import DEFAULT_MODELS, PerceptionModels

    code = ("import sys; from onionsort.stages.models import PerceptionModels; "
            "print(PerceptionModels.frames_per_step_of(None), 'torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    loaded = PerceptionModels.load_cached(None, "cpu")
    assert done.stdout.split() == [str(loaded.frames_per_step), "False"]
    for name in ("state_classifier.pt", "detector.pt", "inspection_classifier.pt"):
        (tmp_path / name).write_bytes((DEFAULT_MODELS / name).read_bytes())
    for bad in (b"not a checkpoint", _zipped(b""), _zipped(b"\x80\x02}q\x00.")):
        (tmp_path / "state_classifier.pt").write_bytes(bad)  # no zip; empty pickle; no config
        assert PerceptionModels.frames_per_step_of(tmp_path) is None


def _zipped(pickled: bytes) -> bytes:
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("archive/data.pkl", pickled)
    return buffer.getvalue()


def test_perceive_on_ray_writes_the_files_local_workers_write(recorded, tmp_path, ray):
    local, on_ray = _perceived_copies(recorded, tmp_path, ["--workers", "2"],
                                      ["--executor", "ray"])
    for a, b in zip(local, on_ray, strict=True):
        assert a.read_bytes() == b.read_bytes()  # one thread each: byte-identical


def untimed(results: dict) -> dict:
    def strip(x):
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if k not in ("seconds", "learn_seconds")}
        if isinstance(x, list):
            return [strip(v) for v in x]
        return x
    return strip(results)


DEMO = ["demo", "--quick", "--repeats", "2", "--sessions", "2", "--seed", "3"]


@pytest.mark.slow
def test_demo_on_two_workers_and_on_ray_gives_the_same_results(tmp_path, ray):
    results = {}
    for name, extra in (("one", ["--workers", "1"]), ("two", ["--workers", "2"]),
                        ("ray", ["--executor", "ray"])):
        assert main([*DEMO, *extra, "--out", str(tmp_path / name)]) == 0
        results[name] = untimed(json.loads((tmp_path / name / "results.json").read_text()))
    assert results["two"] == results["one"]
    assert results["ray"] == results["one"]
    assert np.isfinite(results["one"]["methods"]["mmap-birl"]["precision"])


def _descendants(pid: int) -> list[int]:
    """The processes under ``pid`` (Linux: read from /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def _writer_of(pid: int, name: str, timeout: float = 120.0) -> int:
    """The process under ``pid`` that has the file ``name`` open, once it has some frames."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for child in _descendants(pid):
            try:
                links = [os.readlink(fd) for fd in Path(f"/proc/{child}/fd").iterdir()]
            except OSError:
                continue
            held = [link for link in links if Path(link).name == name]
            if held and Path(held[0]).stat().st_size > 100_000:
                return child
        time.sleep(0.05)
    pytest.fail(f"no worker wrote {name} within {timeout} s")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="finds the worker in /proc")
def test_a_killed_worker_fails_the_recording_and_resume_finishes_it(tmp_path):
    import subprocess
    import sys

    argv = ["record", "--sessions", "3", "--steps-per-session", "30", "--seed", "9"]
    out = tmp_path / "rec"
    proc = subprocess.Popen([sys.executable, "-m", "onionsort.cli", *argv, "--workers", "2",
                             "--out", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    os.kill(_writer_of(proc.pid, "session_001.mcap"), signal.SIGKILL)
    assert proc.wait(timeout=120) == 1
    err = proc.stderr.read().decode().strip().splitlines()[-1]
    assert err.startswith("onionsort record: error: a worker process died")
    assert "session_001.mcap" in err and "--resume" in err

    assert main([*argv, "--workers", "2", "--out", str(out), "--resume"]) == 0
    assert main([*argv, "--workers", "1", "--out", str(tmp_path / "whole")]) == 0
    for name in ("session_000.mcap", "session_001.mcap", "session_002.mcap"):
        assert open_session(out / name).status == "complete"
        assert frames_of(out / name) == frames_of(tmp_path / "whole" / name)


def dataset_files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name != "dataset.json"}


def test_dataset_on_two_workers_writes_the_same_files(tmp_path):
    argv = ["dataset", "--frames", "40", "--steps-per-session", "4", "--frames-per-step", "2",
            "--robot-onions", "12", "--robot-views", "2", "--difficulty", "clean,hard",
            "--seed", "2"]
    for workers in (1, 2):
        assert main([*argv, "--workers", str(workers), "--out", str(tmp_path / f"d{workers}")]) == 0
    one, two = dataset_files(tmp_path / "d1"), dataset_files(tmp_path / "d2")
    assert one == two and len(one) > 40
    meta = [json.loads((tmp_path / d / "dataset.json").read_text()) for d in ("d1", "d2")]
    assert {k: v for k, v in meta[0].items() if k != "created_utc"} == {
        k: v for k, v in meta[1].items() if k != "created_utc"}


def test_calibrate_on_two_workers_measures_what_one_does(tmp_path):
    """Each of the dataset's sessions is a piece on the workers, who load the models; the
    calibration and its observation model are those of one worker, which perceives them all."""
    data = tmp_path / "data"
    assert main(["dataset", "--frames", "36", "--robot-onions", "0", "--steps-per-session", "4",
                 "--seed", "12", "--workers", "1", "--out", str(data)]) == 0
    for workers in (1, 2):
        assert main(["calibrate", "--data", str(data), "--split", "all", "--workers",
                     str(workers), "--out", str(tmp_path / f"cal{workers}")]) == 0
    one, two = (json.loads((tmp_path / f"cal{w}" / "calibration.json").read_text())
                for w in (1, 2))
    assert one == two and one["metrics"]["n_steps"] == 12
    probs = [np.load(tmp_path / f"cal{w}" / "observation_model.npz")["probs"] for w in (1, 2)]
    assert np.array_equal(*probs)


def test_learn_and_evaluate_several_on_two_workers_write_what_one_writes(recorded, tmp_path):
    from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

    (sessions,) = _perceived_copies(recorded, tmp_path, ["--workers", "2"])
    methods = ["mmap-birl", "map-birl", "hidden-data-em"]
    written = {}
    for workers in ("1", "2"):
        out = tmp_path / f"learn{workers}"
        assert main(["learn", *map(str, sessions), "--method", ",".join(methods),
                     "--observation-model", str(DEFAULT_MODELS / CALIBRATION_FILE),
                     "--allow-model-mismatch", "--workers", workers, "--out", str(out)]) == 0
        runs = [out / m for m in methods]
        assert main(["evaluate", *map(str, runs), "--onions", "4", "--blemished", "2",
                     "--ground-truth-inspection", "--no-rerun", "--no-mcap",
                     "--workers", workers]) == 0
        written[workers] = {m: (json.loads((run / "model.json").read_text()),
                                json.loads((run / "evaluation.json").read_text()))
                            for m, run in zip(methods, runs, strict=True)}
    assert written["2"] == written["1"]
    for method, (model, evaluation) in written["1"].items():
        assert model["method"] == evaluation["method"] == method


def sleep_then_write(path: str) -> int:
    """A piece that outlives its command if nothing stops it: it writes ``path`` after 30 s."""
    import time

    Path(path + ".started").write_text(str(os.getpid()))
    time.sleep(30)
    Path(path).write_text("written by a worker whose command was gone")
    return os.getpid()


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="finds the workers in /proc")
def test_workers_stop_when_their_command_is_killed(tmp_path):
    """A SIGKILLed command leaves no worker writing on alone: each stops its piece."""
    import subprocess
    import time

    marks = [str(tmp_path / f"piece{i}") for i in range(2)]
    script = (
        "from onionsort.stages.parallel import ParallelOptions, run_pieces\n"
        "from tests.test_parallel import sleep_then_write\n"
        f"list(run_pieces(sleep_then_write, {marks!r}, ParallelOptions(workers=2), "
        "names=['a', 'b'], desc='t', progress=False))\n")
    command = subprocess.Popen([sys.executable, "-c", script], cwd=Path(__file__).parent.parent)
    deadline = time.monotonic() + 120
    while not all(Path(m + ".started").exists() for m in marks):
        assert time.monotonic() < deadline and command.poll() is None, "the pieces never started"
        time.sleep(0.1)
    workers = [int(Path(m + ".started").read_text()) for m in marks]
    command.kill()
    command.wait()
    deadline = time.monotonic() + 25  # well before the pieces would write (30 s)
    while any(Path(f"/proc/{w}").exists() and "Z" not in _state(w) for w in workers):
        assert time.monotonic() < deadline, "a worker outlived its command"
        time.sleep(0.2)
    time.sleep(1)
    assert not any(Path(m).exists() for m in marks)


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


def test_a_kept_pool_is_not_used_from_another_working_folder(tmp_path, monkeypatch):
    """Workers resolve relative paths against the folder they started in: after the caller
    moves to another folder, its pieces run where it is now (as the api example's relative
    run folders need, in a process that ran pieces elsewhere before)."""
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        monkeypatch.chdir(tmp_path / name)
        got = run(working_folder, range(2), workers=2)
        assert set(got.values()) == {str(tmp_path / name)}
