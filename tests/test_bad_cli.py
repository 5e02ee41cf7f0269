"""Bad input at the console script: every subcommand answers with one line, exit code 2.

Each case of the table gives a bad invocation and words the message must hold (what is wrong
and the value or path given). Inputs are bad enough to be refused before any rendering,
perception or fitting, so the whole table runs in seconds. A few cases also run as a real
process, where a traceback would reach stderr. The last tests check that every flag a hint of
the CLI names exists on the parser of the command that prints it.
"""

from __future__ import annotations

import ast
import importlib
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from onionsort.cli import build_parser, main
from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

ROOT = Path(__file__).resolve().parents[1]
SHIPPED_CALIBRATION = DEFAULT_MODELS / CALIBRATION_FILE


def _sensor_session(path: Path, *, frames_per_step: int, steps: int = 2) -> Path:
    """A small sensor-only session written without the simulator (plain arrays)."""
    from recordings import SessionWriter

    with SessionWriter(path, {"source": "test"}, np.array([[50.0, 0, 16], [0, 50.0, 12],
                                                           [0, 0, 1]]),
                       frames_per_step=frames_per_step, depth=False,
                       ground_truth=False) as writer:
        rng = np.random.default_rng(0)
        for i in range(steps * frames_per_step):
            writer.write_sensor_frame(index=i, step=i // frames_per_step,
                                      phase=i % frames_per_step, time_ns=i * 10**8,
                                      color=rng.integers(0, 255, (24, 32, 3), np.uint8))
    return path


@pytest.fixture(scope="module")
def fx(tmp_path_factory) -> Path:
    """Files for bad input: a regular file, non-MCAP files, broken JSON, damaged sessions,
    run and dataset folders that are not what they claim."""
    from recordings.session.perception import add_perception

    d = tmp_path_factory.mktemp("bad")
    (d / "afile").write_text("a regular file\n")
    (d / "garbage.mcap").write_text("not an mcap file\n")
    (d / "bad.json").write_text("{oops")
    (d / "video.mp4").write_bytes(b"\x00" * 64)
    for name, model in (("run_nomodel", None), ("run_bad", "{bad"),
                        ("run_shape", json.dumps({"policy_indices": [1, 2]}))):
        (d / name).mkdir()
        if model is not None:
            (d / name / "model.json").write_text(model)
    (d / "run_done").mkdir()
    (d / "run_done" / "model.json").write_text("{}")
    (d / "cal_done").mkdir()
    (d / "cal_done" / CALIBRATION_FILE).write_text("{}")
    old = json.loads(SHIPPED_CALIBRATION.read_text())  # written before session swaps were
    del old["session_swaps"]                           # measured
    (d / "cal_old.json").write_text(json.dumps(old))
    (d / "data_none").mkdir()
    (d / "models_bad_detector").mkdir()
    for name in ("state_classifier.pt", "inspection_classifier.pt"):
        (d / "models_bad_detector" / name).write_bytes((DEFAULT_MODELS / name).read_bytes())
    (d / "models_bad_detector" / "detector.pt").write_bytes(b"not a checkpoint")
    (d / "data_bad").mkdir()
    (d / "data_bad" / "dataset.json").write_text("{bad")
    (d / "half").mkdir()
    (d / "half" / "sessions").mkdir()
    from onionsort.stages.demo import SIZES, DemoConfig, _settings

    (d / "swaps" / "progress").mkdir(parents=True)  # a demo started with --session-swaps
    (d / "swaps" / "progress" / "config.json").write_text(json.dumps(_settings(
        DemoConfig(out=d / "swaps", quick=True, session_swaps=True), dict(SIZES[True]))))
    (d / "rec").mkdir()
    (d / "rec" / "session_000.mcap").write_bytes(b"an earlier session")
    _sensor_session(d / "two_frames.mcap", frames_per_step=2)
    _sensor_session(d / "unperceived.mcap", frames_per_step=3)
    perceived = _sensor_session(d / "perceived.mcap", frames_per_step=3)
    add_perception(perceived, [{"step": 0, "frame": 0, "occluded": True, "observation": None}],
                   detections={}, inspection={}, frame_times={0: 0}, models={"folder": "x"})
    whole = _sensor_session(d / "whole.mcap", frames_per_step=3).read_bytes()
    (d / "truncated.mcap").write_bytes(whole[: len(whole) // 2])
    return d


CAL = str(SHIPPED_CALIBRATION)
#: (argv, words the one-line message must contain). ``{d}`` is the fixture folder.
FUSION = ["train", "robot-fusion", "--data", "{d}/data_bad", "--out", "{d}/x"]
CASES = [
    # experiment
    (["experiment", "forestworld", "--methods", "svm", "--out", "{d}/x"],
     ["methods must be among", "svm"]),
    (["experiment", "forestworld", "--occlusion", "1.5", "--out", "{d}/x"],
     ["occlusion must be in", "1.5"]),
    (["experiment", "sorting", "--trajectories", "0", "--out", "{d}/x"],
     ["--trajectories must be", "'0'"]),
    (["experiment", "forestworld", "--quick", "--out", "{d}/afile/x"],
     ["afile/x", "cannot be created", "Not a directory"]),
    (["experiment", "forestworld", "--noise", "a,b"], ["--noise", "comma-separated", "'a,b'"]),
    (["experiment", "sideworld"], ["invalid choice", "'sideworld'"]),
    (["experiment", "forestworld", "--batches", "0", "--out", "{d}/x"],
     ["batches must be >= 1", "0"]),
    (["experiment", "forestworld", "--workers", "0", "--out", "{d}/x"],
     ["workers must be >= 1", "0"]),
    (["experiment", "forestworld", "--executor", "spark", "--out", "{d}/x"],
     ["--executor", "invalid choice", "'spark'", "'local'"]),
    (["experiment", "forestworld", "--ray-address", "auto", "--out", "{d}/x"],
     ["ray_address is for executor 'ray'", "'local'"]),
    (["record", "--workers", "0", "--out", "{d}/x"], ["workers must be >= 1", "0"]),
    (["demo", "--quick", "--workers", "-1", "--out", "{d}/x"], ["workers must be >= 1", "-1"]),
    (["demo", "--quick", "--executor", "dask", "--out", "{d}/x"],
     ["--executor", "invalid choice", "'dask'"]),
    (["experiment", "forestworld", "--backend", "cuda", "--out", "{d}/x"],
     ["--backend", "invalid choice", "'cuda'", "'numba'"]),
    (["dataset", "--frames", "12", "--difficulty", "clean,foggy", "--out", "{d}/x"],
     ["unknown level", "'foggy'"]),
    (["evaluate", "{d}/run_nomodel", "--connect", "rerun+http://h/proxy"],
     ["connect must be", "no port"]),
    # record
    (["record", "--sessions", "0", "--out", "{d}/x"], ["sessions must be >= 1", "got 0"]),
    (["record", "--out", "{d}/afile/rec"], ["afile/rec", "cannot be created", "Not a directory"]),
    (["record", "--out", "{d}/afile"], ["afile", "is a file, not a folder"]),
    (["record", "--occlusion", "2", "--out", "{d}/x"], ["occlusion must be in [0, 1]", "2.0"]),
    (["record", "--width", "4", "--out", "{d}/x"], ["width and height must be >= 8", "4x240"]),
    (["record", "--steps-per-session", "0", "--out", "{d}/x"],
     ["steps_per_session must be >= 1", "got 0"]),
    (["record", "--sessions", "1", "--rerun", "{d}/x.txt", "--out", "{d}/x"],
     ["must be an .rrd file", "x.txt"]),
    (["record", "--difficulty", "nope", "--out", "{d}/x"], ["--difficulty", "'nope'"]),
    (["record", "--sessions", "1", "--out", "{d}/rec"],
     ["session_000.mcap exists", "--overwrite", "--resume"]),
    (["record", "--sessions", "1", "--out", "{d}/rec", "--resume"],
     ["cannot resume", "session_000.mcap is not an MCAP file"]),
    (["record", "--out", "{d}/rec", "--resume", "--overwrite"],
     ["--overwrite", "not allowed with argument --resume"]),
    (["record", "--connect", "http://host:9876/proxy", "--out", "{d}/x"],
     ["connect must be the gRPC URL of a Rerun viewer", "'http://host:9876/proxy'"]),
    (["record", "--connect", "rerun+http://127.0.0.1:9/proxy", "--out", "{d}/x"],
     ["no Rerun viewer answers at rerun+http://127.0.0.1:9/proxy", "refused"]),
    # import
    (["import", "--out", "{d}/s.mcap"], ["give exactly one source", "video=None"]),
    (["import", "{d}/two_frames.mcap", "--step-seconds", "2", "--out", "{d}/s.mcap"],
     ["two_frames.mcap is an onionsort session already"]),
    (["import", "{d}/video.mp4", "--depth-topic", "/d", "--out", "{d}/s.mcap"],
     ["--depth-topic go with a ROS bag", "video.mp4 is not one"]),
    (["import", "{d}/video.mp4", "--list"], ["--list lists a bag's topics", "video.mp4"]),
    (["import", "{d}/nofile.mp4", "--step-seconds", "2", "--out", "{d}/s.mcap"],
     ["nofile.mp4", "no such video file"]),
    (["import", "{d}/video.mp4", "--step-seconds", "2", "--out", "{d}/s.mcap"],
     ["cannot open", "video.mp4"]),
    (["import", "{d}/video.mp4", "--step-seconds", "0", "--out", "{d}/s.mcap"],
     ["step_seconds must be > 0", "0.0"]),
    (["import", "{d}/video.mp4", "--step-seconds", "2", "--out", "{d}/afile"],
     ["afile exists", "--out"]),
    (["import", "{d}/video.mp4", "--step-seconds", "2", "--out", "{d}/afile/s.mcap"],
     ["afile", "is a file, not a folder"]),
    # export
    (["label", "export", "{d}/data_none", "--format", "coco", "--out", "{d}/x"],
     ["data_none is not a dataset folder"]),
    (["label", "select", "{d}/two_frames.mcap", "--frames", "0", "--out", "{d}/x"],
     ["frames must be >= 1; got 0"]),
    (["label", "select", "{d}/unperceived.mcap", "--frames", "3", "--recall", "--out",
      "{d}/x"], ["unperceived.mcap carries no ground truth", "--recall"]),
    (["label", "select", "{d}/garbage.mcap", "--frames", "5", "--out", "{d}/x"],
     ["garbage.mcap", "not an MCAP file"]),
    (["label", "import", "{d}/afile", "--format", "yolo", "--out", "{d}/x"],
     ["afile: no such folder"]),
    (["label", "import", "{d}/data_none", "--format", "coco", "--out", "{d}/x"],
     ["data_none: no COCO annotations"]),
    (["label", "import", "{d}/data_none", "--format", "coco", "--classes", "rotten=bad",
      "--out", "{d}/x"], ["expected good=NAME,blemished=NAME", "'rotten=bad'"]),
    (["export", "{d}/garbage.mcap", "--out", "{d}/x"], ["garbage.mcap", "not an MCAP file"]),
    (["export", "{d}/truncated.mcap", "--out", "{d}/x"],
     ["truncated.mcap", "truncated or corrupt"]),
    (["export", "{d}/nofile.mcap", "--out", "{d}/x"], ["nofile.mcap", "no such recording"]),
    (["export", "{d}/two_frames.mcap", "--out", "{d}/afile"], ["afile exists", "--out"]),
    (["export", "{d}/two_frames.mcap", "--format", "ros1", "--out", "{d}/x"],
     ["--format", "invalid choice", "'ros1'"]),
    (["export", "{d}/two_frames.mcap", "--storage", "zip", "--out", "{d}/x"],
     ["--storage", "invalid choice", "'zip'"]),
    # dataset
    (["dataset", "--frames", "0", "--out", "{d}/x"], ["frames must be >= 1", "got 0"]),
    (["dataset", "--val", "0.6", "--test", "0.6", "--out", "{d}/x"],
     ["--val and --test must be", "0.6, 0.6"]),
    (["dataset", "--difficulty", "nope", "--out", "{d}/x"], ["unknown level", "'nope'"]),
    (["dataset", "--robot-onions", "-1", "--out", "{d}/x"], ["robot_onions must be >= 0", "-1"]),
    (["dataset", "--robot-views", "0", "--out", "{d}/x"], ["robot_views must be >= 1", "got 0"]),
    (["dataset", "--inspection-size", "320", "--out", "{d}/x"],
     ["--inspection-size", "WIDTHxHEIGHT", "'320'"]),
    (["dataset", "--inspection-size", "16x12", "--out", "{d}/x"],
     ["--inspection-size", "32 to 1920", "'16x12'"]),
    (["dataset", "--inspection-size", "320x120", "--out", "{d}/x"],
     ["--inspection-size", "4:3", "'320x120'"]),
    # train
    (["train"], ["required", "MODEL"]),
    (["train", "state-classifier", "--data", "{d}/data_none", "--out", "{d}/x"],
     ["data_none", "not a dataset folder"]),
    (["train", "detector", "--data", "{d}/data_bad", "--out", "{d}/x"],
     ["data_bad/dataset.json", "not JSON"]),
    (["train", "detector", "--data", "{d}/data_none", "--out", "{d}/x", "--resume"],
     ["cannot resume", "detector_last.pt"]),
    (["train", "state-classifier", "--data", "{d}/data_none", "--out", "{d}/x", "--epochs", "0"],
     ["epochs must be >= 1", "got 0"]),
    (["train", "state-classifier", "--data", "{d}/data_none", "--out", "{d}/x", "--lr", "0"],
     ["lr must be > 0", "got 0.0"]),
    # perceive
    (["perceive", "{d}/nofile.mcap"], ["no such session file", "nofile.mcap"]),
    (["perceive", "{d}/garbage.mcap"], ["garbage.mcap", "not an MCAP file"]),
    (["perceive", "{d}/truncated.mcap"], ["truncated.mcap", "truncated or corrupt"]),
    (["perceive", "{d}/unperceived.mcap", "{d}/perceived.mcap"],
     ["perceived.mcap already holds perception topics", "--replace"]),
    (["perceive", "{d}/two_frames.mcap"], ["two_frames.mcap", "2 frames", "--frames-per-step 3"]),
    (["perceive", "{d}/unperceived.mcap", "{d}/two_frames.mcap", "--workers", "2"],
     ["two_frames.mcap", "2 frames", "--frames-per-step 3"]),  # found without torch
    (["perceive", "{d}/unperceived.mcap", "{d}/two_frames.mcap", "--workers", "2", "--models",
      "{d}/data_none"], ["data_none has no state_classifier.pt", "onionsort train"]),
    (["perceive", "{d}/unperceived.mcap", "{d}/whole.mcap", "--workers", "2", "--models",
      "{d}/models_bad_detector"], ["detector.pt is not a detector checkpoint"]),
    # calibrate
    (["calibrate", "--data", "{d}/data_none", "--out", "{d}/x"],
     ["data_none", "not a dataset folder"]),
    (["calibrate", "--data", "{d}/data_none", "--out", "{d}/afile/x"],
     ["afile/x", "cannot be created"]),
    (["calibrate", "--data", "{d}/data_none", "--out", "{d}/x", "--smoothing", "-1"],
     ["smoothing must be >= 0", "-1.0"]),
    (["calibrate", "--data", "{d}/data_none", "--out", "{d}/cal_done"],
     ["cal_done/calibration.json exists", "--overwrite"]),
    # eval-perception
    (["eval-perception", "--data", "{d}/data_bad"], ["data_bad/dataset.json", "not JSON"]),
    (["eval-perception", "--data", "{d}/data_none", "--split", "nope"],
     ["split must be one of", "'nope'"]),
    # compare-perception
    (["compare-perception", "--base", "{d}/bad.json", "--candidate", "{d}/bad.json"],
     ["bad.json is not JSON", "eval-perception --json"]),
    (["compare-perception", "--base", "{d}/no.json", "--candidate", "{d}/no.json"],
     ["no.json", "No such file"]),
    (["compare-perception", "--base", "{d}/run_shape/model.json", "--candidate",
      "{d}/run_shape/model.json"], ["model.json is not an `eval-perception --json` result",
                                    "'map_by_view'"]),
    (["compare-perception", "--base", "{d}/bad.json", "--base", "{d}/bad.json",
      "--candidate", "{d}/bad.json"], ["one --candidate result per --base one",
                                       "2 --base and 1 --candidate"]),
    (["compare-perception", "--base", "{d}/bad.json"], ["required", "--candidate"]),
    # learn
    (["learn", "{d}/nofile.mcap", "--observation-model", CAL, "--out", "{d}/x"],
     ["no such session file", "nofile.mcap"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", "{d}/bad.json", "--out", "{d}/x"],
     ["bad.json", "not a calibration file"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--out", "{d}/x"],
     ["unperceived.mcap has no perception topics", "onionsort perceive"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--out", "{d}/afile/x"],
     ["afile/x", "cannot be created"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--out", "{d}/run_done"],
     ["run_done/model.json exists", "--overwrite"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--method", "svm",
      "--out", "{d}/x"], ["--method", "'svm'"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--beta", "0",
      "--out", "{d}/x"], ["beta must be a finite number > 0", "0"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--prior-std", "nan",
      "--out", "{d}/x"], ["prior_std must be a finite number > 0", "nan"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--backend", "cuda",
      "--out", "{d}/x"], ["--backend", "invalid choice", "'cuda'", "'numba'"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--method", "maxent",
      "--posterior", "--out", "{d}/x"], ["posterior needs a Bayesian method", "maxent"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--posterior",
      "--samples", "3", "--out", "{d}/x"], ["samples must be an int >= 10", "3"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--posterior",
      "--posterior-method", "nuts", "--out", "{d}/x"],
     ["--posterior-method", "invalid choice", "'nuts'"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--connect",
      "rerun+http://host/proxy", "--out", "{d}/x"], ["connect must be", "no port",
                                                     "'rerun+http://host/proxy'"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", "{d}/cal_old.json",
      "--session-swaps", "--out", "{d}/x"],
     ["cal_old.json does not say how often a whole session", "calibrate again"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--session-swaps",
      "--method", "map-birl", "--out", "{d}/x"], ["session_swaps needs mmap-birl", "map-birl"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--method", "bc",
      "--posterior", "--out", "{d}/x"], ["posterior needs a Bayesian method", "bc"]),
    (["demo", "--quick", "--out", "{d}/x", "--methods", "bc,dagger"],
     ["--methods", "invalid choice", "'dagger'"]),
    (["demo", "--quick", "--out", "{d}/x", "--defer-below", "2"],
     ["defer_below must be in (0, 1]", "2.0"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", CAL, "--method",
      "mmap-birl,svm", "--out", "{d}/x"], ["--method", "invalid choice", "'svm'"]),
    (["evaluate", "{d}/run_nomodel", "{d}/run_bad", "--out", "{d}/x"],
     ["--out takes one run's outputs", "their own folder"]),
    # suggest
    (["suggest", "{d}/run_nomodel"], ["run_nomodel holds no posterior", "--posterior"]),
    (["suggest", "{d}/run_nomodel", "--top", "0"], ["top must be an int >= 1", "0"]),
    # evaluate
    (["evaluate", "{d}/run_nomodel"], ["run_nomodel holds no learned model", "onionsort learn"]),
    (["evaluate", "{d}/run_bad"], ["run_bad/model.json is not a learned model"]),
    (["evaluate", "{d}/run_shape"], ["the policy must give one action", "shape (2,)"]),
    (["evaluate", "{d}/run_nomodel", "--onions", "0"], ["onions must be >= 1", "got 0"]),
    (["evaluate", "{d}/run_nomodel", "--blemished", "80"], ["blemished must be in", "got 80"]),
    (["evaluate", "--policy", "expert"], ["--policy expert needs --out DIR"]),
    (["evaluate", "{d}/run_nomodel", "--policy", "expert", "--out", "{d}/x"],
     ["--policy expert", "takes no RUN_DIR", "run_nomodel"]),
    (["evaluate"], ["learned policy needs its run folder", "--policy expert"]),
    (["evaluate", "--policy", "expert", "--out", "{d}/x", "--device", "tpu"],
     ["--device", "invalid choice", "'tpu'", "'cuda'"]),
    (["evaluate", "--policy", "expert", "--out", "{d}/x", "--inspection-views", "0"],
     ["inspection_views must be >= 1", "got 0"]),
    (["evaluate", "--policy", "expert", "--out", "{d}/x", "--miss-cost", "-1"],
     ["miss_cost must be >= 0", "got -1"]),
    (["score", "{d}/no-tally.csv", "--truth", "{d}/no-truth.csv"],
     ["no-tally.csv: no such tally CSV", "columns lineup, index, fate"]),
    (["evaluate", "--policy", "expert", "--out", "{d}/x", "--fusion", "max"],
     ["--fusion", "invalid choice", "'max'"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x"],
     ["data_bad/dataset.json", "not JSON"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x", "--level-weights",
      "muddy=2"], ["--level-weights", "unknown level 'muddy'"]),
    ([*FUSION, "--by-level", "--level-forms", "hard=isotonic"], ["unknown form 'isotonic'"]),
    ([*FUSION, "--by-level", "--level-forms", "hard"], ["expected level=form pairs", "'hard'"]),
    ([*FUSION, "--level-forms", "hard=powers"], ["level_forms needs by_level"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x", "--fusion", "mean"],
     ["--fusion", "invalid choice", "'mean'"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x", "--visibility", "1.5"],
     ["visibility must be in (0, 1]", "got 1.5"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x", "--lr=-1e-3"],
     ["lr must be > 0", "got -0.001"]),
    (["train", "detector", "--data", "{d}/data_bad", "--out", "{d}/x", "--through-cameras",
      "8801,x"], ["--through-cameras", "expected comma-separated seeds", "'x' in '8801,x'"]),
    (["train", "detector", "--data", "{d}/data_bad", "--out", "{d}/x", "--through-cameras",
      "8801,-1"], ["through_cameras must be a seed, an int >= 0", "got -1"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x", "--through-cameras",
      "12,12"], ["through_cameras names seed 12 twice"]),
    (["train", "inspection", "--data", "{d}/data_bad", "--out", "{d}/x", "--log-odds-data",
      "{d}/data_bad"], ["log_odds_data", "data_bad is also training data"]),
    (["perceive", "{d}/unperceived.mcap", "--device", "gpu"],
     ["--device", "invalid choice", "'gpu'"]),
    (["eval-perception", "--data", "{d}/data_bad", "--views", "0"], ["views must be >= 1"]),
    (["eval-perception", "--data", "{d}/data_bad", "--camera-shift", "-3"],
     ["camera_shift must be a seed, an int >= 0", "-3"]),
    (["eval-perception", "--data", "{d}/data_bad", "--camera-shift", "warm"],
     ["--camera-shift", "expected comma-separated seeds", "'warm'"]),
    (["eval-perception", "--data", "{d}/data_bad", "--camera-shift", "11,x,13"],
     ["--camera-shift", "expected comma-separated seeds", "'x' in '11,x,13'"]),
    (["eval-perception", "--data", "{d}/data_bad", "--camera-shift", "11,,13"],
     ["--camera-shift", "expected comma-separated seeds", "'' in '11,,13'"]),
    (["eval-perception", "--data", "{d}/data_bad", "--camera-shift", "11,-2"],
     ["camera_shift must be a seed, an int >= 0", "got -2"]),
    (["eval-perception", "--data", "{d}/data_bad", "--camera-shift", "11,12,11"],
     ["camera_shift names seed 11 twice", "[11, 12, 11]"]),
    (["eval-perception", "--data", "{d}/data_bad", "--one-camera"],
     ["one_camera needs camera_shift"]),
    (["eval-posterior", "chess"], ["argument domain", "invalid choice", "'chess'"]),
    (["eval-posterior", "sorting", "--problems", "0"], ["problems must be >= 1", "got 0"]),
    (["eval-posterior", "sorting", "--noise", "1.5"], ["noise must be in [0, 1)", "got 1.5"]),
    (["eval-posterior", "sorting", "--method", "nuts"],
     ["--method", "invalid choice", "'nuts'", "'laplace'"]),
    # demo
    (["demo", "--quick", "--out", "{d}/afile/demo"], ["afile/demo", "cannot be created"]),
    (["demo", "--quick", "--out", "{d}/half"],
     ["half already holds files of an earlier or interrupted run", "sessions", "new --out"]),
    (["demo", "--quick", "--repeats", "0", "--out", "{d}/x"], ["repeats must be >= 1", "got 0"]),
    (["demo", "--quick", "--resume", "--out", "{d}/half"],
     ["cannot resume", "half holds no demo progress", "new --out"]),
    (["demo", "--quick", "--resume", "--out", "{d}/swaps"],
     ["cannot resume", "session_swaps True there, None now"]),
    (["demo", "--quick", "--connect", "rerun+http://h:1/viewer", "--out", "{d}/x"],
     ["connect must be", "the path must be /proxy", "'rerun+http://h:1/viewer'"]),
    (["demo", "--quick", "--backend", "cuda", "--out", "{d}/x"],
     ["--backend", "invalid choice", "'cuda'", "'numba'"]),
    # report
    (["report", "{d}/nofile"], ["RUN_DIR", "nofile does not exist", "onionsort demo"]),
    (["report", "{d}/afile"], ["afile is a file, not a folder"]),
    (["report", "{d}/data_none"], ["data_none is no run folder (it is empty)",
                                   "onionsort experiment", "summary.json"]),
    (["report", "{d}/run_done"], ["run_done is no run folder (it holds model.json)"]),
    (["report", "{d}/data_bad"], ["data_bad is no run folder (it holds dataset.json)"]),
    # the top level
    (["sort-onions"], ["invalid choice", "'sort-onions'"]),
    (["--debug"], ["required", "COMMAND"]),
]


def _run_in_process(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    return code, capsys.readouterr().err


def _one_clear_line(code: int, err: str, words: list[str]) -> None:
    lines = err.splitlines()
    assert code == 2, err
    assert len(lines) == 1, f"expected one line on stderr; got {lines}"
    assert "Traceback" not in err
    assert lines[0].startswith("onionsort")
    for word in words:
        assert word in lines[0], f"{word!r} missing from {lines[0]!r}"
    command = (lines[0].split(":")[0].split()[1:] or [""])[0]
    wrong = _misnamed_flags(lines[0], command)
    assert not wrong, f"{lines[0]!r} names flags that do not exist: {wrong}"


def test_the_table_covers_every_subcommand_with_at_least_30_cases():
    commands = set(build_parser()._subparsers._group_actions[0].choices)
    covered = {argv[0] for argv, _ in CASES}
    assert commands <= covered, f"no bad invocation of {sorted(commands - covered)}"
    assert len(CASES) >= 30


@pytest.mark.parametrize("argv, words", CASES, ids=[" ".join(a)[:60] for a, _ in CASES])
def test_bad_invocation_is_one_clear_line_with_exit_code_2(fx, capsys, argv, words):
    argv = [a.format(d=fx) for a in argv]
    given = {p: p.read_bytes() for p in fx.rglob("*") if p.is_file()}
    code, err = _run_in_process(argv, capsys)
    _one_clear_line(code, err, [w.format(d=fx) for w in words])
    # a refused command leaves the files it was given as they were
    assert {p: p.read_bytes() for p in given} == given
    assert not (fx / "x").exists() or not any((fx / "x").iterdir())


@pytest.mark.parametrize("argv, words", [
    (["record", "--sessions", "1", "--out", "{d}/afile/rec"], ["afile/rec", "Not a directory"]),
    (["demo", "--quick", "--out", "{d}/afile/demo"], ["afile/demo", "Not a directory"]),
    (["perceive", "{d}/garbage.mcap"], ["not an MCAP file"]),
    (["learn", "{d}/unperceived.mcap", "--observation-model", "{d}/bad.json", "--out",
      "{d}/x"], ["not a calibration file"]),
    (["train", "detector"], ["required", "--data"]),
])
def test_no_traceback_reaches_stderr_of_the_process(fx, argv, words):
    argv = [a.format(d=fx) for a in argv]
    done = subprocess.run([sys.executable, "-m", "onionsort.cli", *argv], capture_output=True,
                          text=True, cwd=fx, timeout=120)
    _one_clear_line(done.returncode, done.stderr, words)
    assert done.stdout == ""


@pytest.mark.parametrize("argv", [
    ["experiment", "forestworld", "--quick", "--backend", "numba", "--out", "{d}/x"],
    ["experiment", "forestworld", "--quick", "--backend", "numba", "--out", "{d}/x", "--resume"],
    ["learn", "{d}/perceived.mcap", "--observation-model", CAL, "--method", "maxent",
     "--backend", "numba", "--out", "{d}/x"],
    ["demo", "--quick", "--backend", "numba", "--out", "{d}/x"],
])
def test_numba_asked_for_but_not_installed_is_one_line_with_the_install_hint(fx, capsys,
                                                                              monkeypatch, argv):
    """Refused before anything is read, fitted or written, whichever learner would run."""
    import irl._numba

    monkeypatch.setattr(irl._numba, "available", lambda: False)
    argv = [a.format(d=fx) for a in argv]
    code, err = _run_in_process(argv, capsys)
    _one_clear_line(code, err, ["backend 'numba' needs numba, which is not installed",
                                "pip install 'onionsort[fast]'"])
    assert not (fx / "x").exists() or not any((fx / "x").iterdir())


def test_debug_shows_the_traceback(fx):
    done = subprocess.run([sys.executable, "-m", "onionsort.cli", "--debug", "record",
                           "--sessions", "1", "--out", str(fx / "afile" / "rec")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode != 0
    assert "Traceback" in done.stderr and "cannot be created" in done.stderr


def test_an_unexpected_failure_is_one_line_with_exit_code_1(monkeypatch, capsys, tmp_path):
    stage = importlib.import_module("onionsort.stages.evaluate")

    def broken(*args, **kwargs):
        raise RuntimeError("something inside broke")

    monkeypatch.setattr(stage, "load_policy", broken)
    code, err = _run_in_process(["evaluate", str(tmp_path)], capsys)
    assert code == 1
    assert err.splitlines() == [
        "onionsort evaluate: internal error: RuntimeError: something inside broke (run again "
        "with --debug for the traceback, and please report it)"]


def _unwritable_folder(tmp_path: Path) -> Path:
    import os

    if os.geteuid() != 0:
        folder = tmp_path / "read-only"
        folder.mkdir()
        folder.chmod(0o500)
        return folder
    folder = Path("/sys/kernel")  # refuses new files even to root
    if not folder.is_dir() or _can_create(folder):
        pytest.skip("no folder here refuses files to this user")
    return folder


def _can_create(folder: Path) -> bool:
    try:
        (folder / ".probe").touch()
    except OSError:
        return False
    (folder / ".probe").unlink()
    return True


def test_calibrate_refuses_an_unwritable_out_before_perception_runs(fx, tmp_path, monkeypatch,
                                                                      capsys):
    stage = importlib.import_module("onionsort.stages.calibrate")

    ran = []
    monkeypatch.setattr(stage, "measure_perception", lambda *a, **k: ran.append(a))
    monkeypatch.setattr(stage.PerceptionModels, "load", lambda *a, **k: ran.append(a))
    out = _unwritable_folder(tmp_path)
    code, err = _run_in_process(["calibrate", "--data", str(fx / "data_none"), "--out",
                                 str(out)], capsys)
    _one_clear_line(code, err, [str(out), "cannot be written to"])
    assert ran == []


def test_record_and_learn_refuse_an_unwritable_out(fx, tmp_path, capsys):
    out = _unwritable_folder(tmp_path)
    code, err = _run_in_process(["record", "--sessions", "1", "--out", str(out)], capsys)
    _one_clear_line(code, err, [str(out), "cannot be written to"])
    code, err = _run_in_process(["learn", str(fx / "unperceived.mcap"), "--observation-model",
                                 CAL, "--out", str(out)], capsys)
    _one_clear_line(code, err, [str(out), "cannot be written to"])


# --- every flag a hint names exists -------------------------------------------------------

_FLAG = re.compile(r"--[a-z][a-z0-9]*(?:-[a-z0-9]+)*")
_COMMANDS = sorted(build_parser()._subparsers._group_actions[0].choices, key=len, reverse=True)
#: A command line in a message or a docstring: ```onionsort CMD ARGS```, or ````CMD ARGS````.
_COMMAND_LINE = re.compile(r"(?:onionsort |``?)(" + "|".join(map(re.escape, _COMMANDS))
                           + r")\b((?: [^`\n\0]*?)?)(?=`|\n|$|\0|\))")
#: Flags a message builds from a value (``f"--no-{k}"``), with every value it can take.
#: The command they belong to is given where it is not the module's own.
_DYNAMIC_FLAGS = {
    ("onionsort/stages/learn.py", "--no-"): (["--no-depth", "--no-inspection"], ["calibrate"]),
    ("onionsort/stages/experiment.py", "--"): (["--trajectories", "--length", "--learner-beta"],
                                               None),
}
#: Flags of other programs named in messages and docs (pip).
_FOREIGN = {("robot/assets.py", "--no-deps"), ("recordings/sources/video.py", "--list-devices")}
#: Which commands print the messages of a module of ``onionsort/commands`` or
#: ``onionsort/stages`` (by the module's name).
_MODULE_COMMANDS = {"import_video": ["import"], "eval_perception": ["eval-perception"],
                    "compare_perception": ["compare-perception"],
                    "eval_posterior": ["eval-posterior"],
                    "calibrate": ["calibrate", "eval-perception"],
                    "label_select": ["label"], "lineup": ["evaluate", "score"]}
_SHARED = {"base", "models", "parallel", "__init__", "_args"}
#: Which commands run a stage module's refusals (``calibrate.py``'s come from calibrate alone).
_CALLER_COMMANDS = {**_MODULE_COMMANDS, "calibrate": ["calibrate"], "inspection": ["train"]}


def _parsers() -> dict[str, set[str]]:
    """The flags of every command (``train``: of its models too), and of the top level."""
    parser = build_parser()

    def flags(p) -> set[str]:
        out = {s for a in p._actions for s in a.option_strings}
        for sub in (p._subparsers._group_actions if p._subparsers else []):
            for child in sub.choices.values():
                out |= flags(child)
        return out

    top = {s for a in parser._actions for s in a.option_strings}
    commands = parser._subparsers._group_actions[0].choices
    return {"": top, **{name: flags(p) | top for name, p in commands.items()}}


def _texts(tree: ast.AST):
    """Every string of a module (an f-string with each value as ``\\0``), with its line."""
    inside = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            parts = []
            for v in node.values:
                inside.add(id(v))
                parts.append(v.value if isinstance(v, ast.Constant) else "\0")
            yield "".join(parts), node.lineno
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and id(node) not in inside:
            yield node.value, node.lineno


def _hint_flags():
    """(module, line, flag, commands it must exist on or None for any) of every hint."""
    found = []
    for package in ("onionsort", "recordings", "state_abstraction", "perception", "robot",
                    "irl"):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            stem = path.stem
            own = None
            if rel.startswith("onionsort/commands/") and stem not in _SHARED:
                own = _MODULE_COMMANDS.get(stem, [stem])[:1]
            elif rel.startswith("onionsort/stages/") and stem not in _SHARED:
                own = _MODULE_COMMANDS.get(stem, [stem])
            for text, line in _texts(ast.parse(path.read_text())):
                named = {}  # flags inside `onionsort CMD ...` belong to CMD
                for m in _COMMAND_LINE.finditer(text):
                    for f in _FLAG.finditer(m.group(2)):
                        named[m.start(2) + f.start()] = [m.group(1)]
                for m in _FLAG.finditer(text):
                    flag, after = m.group(), text[m.end():m.end() + 1]
                    if (rel, flag) in _FOREIGN:
                        continue
                    if after == "\0" or (after == "-" and text[m.end() + 1:m.end() + 2] == "\0"):
                        key = (rel, flag + after if after == "-" else flag)
                        assert key in _DYNAMIC_FLAGS, f"{rel}:{line}: a flag built from a " \
                            f"value ({text[m.start():m.end() + 2]!r}); list it in _DYNAMIC_FLAGS"
                        flags, command = _DYNAMIC_FLAGS[key]
                        for each in flags:
                            found.append((rel, line, each, command or own))
                        continue
                    found.append((rel, line, flag, named.get(m.start(), own)))
                for _ in re.finditer(r"--(?=\0)", text):
                    key = (rel, "--")
                    assert key in _DYNAMIC_FLAGS, f"{rel}:{line}: a flag built from a value"
                    flags, command = _DYNAMIC_FLAGS[key]
                    for each in flags:
                        found.append((rel, line, each, command or own))
    return found


def _misnamed_flags(text: str, command: str) -> list[str]:
    """Flags of ``text`` that its command lacks: those inside ```onionsort CMD ...``` are
    CMD's, the others ``command``'s."""
    parsers = _parsers()
    theirs = {}
    for m in _COMMAND_LINE.finditer(text):
        for f in _FLAG.finditer(m.group(2)):
            theirs[m.start(2) + f.start()] = m.group(1)
    return [f"{m.group()} (of `onionsort {theirs.get(m.start(), command)}`)"
            for m in _FLAG.finditer(text)
            if m.group() not in parsers.get(theirs.get(m.start(), command), ())]


def test_the_hint_scan_finds_the_hints_it_should():
    hints = {(rel, flag) for rel, _, flag, _ in _hint_flags()}
    assert ("onionsort/stages/record.py", "--overwrite") in hints
    assert ("onionsort/stages/learn.py", "--allow-model-mismatch") in hints
    assert ("onionsort/stages/learn.py", "--no-inspection") in hints
    assert ("recordings/session/perception.py", "--replace") in hints
    assert len(hints) > 40


def test_every_flag_a_hint_names_exists_on_its_command():
    parsers = _parsers()
    anywhere = set().union(*parsers.values())
    wrong = []
    for rel, line, flag, commands in _hint_flags():
        if commands is None:
            if flag not in anywhere:
                wrong.append(f"{rel}:{line}: {flag} is no flag of any command")
            continue
        # a stage module serving two commands (calibrate.py) prints each hint for one of them
        if not any(flag in parsers.get(command, ()) for command in commands):
            wrong.append(f"{rel}:{line}: {flag} is no flag of `onionsort "
                         f"{' or '.join(commands)}`")
    assert not wrong, "\n".join(wrong)


def test_shared_refusals_are_raised_only_by_commands_that_have_their_flag():
    """``refuse_existing`` (onionsort/stages/base.py) tells the user to pass ``--overwrite``:
    every stage that calls it must belong to commands that have the flag."""
    parsers = _parsers()
    base = ast.parse((ROOT / "onionsort/stages/base.py").read_text())
    hints = {}
    for fn in (n for n in base.body if isinstance(n, ast.FunctionDef)):
        # a default (``what="--out"``) is no hint of its own: the caller may pass another
        defaults = {id(d) for d in fn.args.defaults + fn.args.kw_defaults if d is not None}
        flags = {f for node in ast.walk(fn) if isinstance(node, ast.Constant)
                 and isinstance(node.value, str) and id(node) not in defaults
                 for f in _FLAG.findall(node.value)}
        if flags:
            hints[fn.name] = flags
    assert hints.get("refuse_existing") == {"--overwrite"}
    wrong = []
    for path in sorted((ROOT / "onionsort/stages").glob("*.py")):
        if path.stem in _SHARED:
            continue
        called = {n.func.id for n in ast.walk(ast.parse(path.read_text()))
                  if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
        for name in called & set(hints):
            for command in _CALLER_COMMANDS.get(path.stem, [path.stem]):
                missing = hints[name] - parsers[command]
                if missing:
                    wrong.append(f"{path.name} calls {name}, whose message names "
                                 f"{sorted(missing)}, which `onionsort {command}` lacks")
    assert not wrong, "\n".join(wrong)


def test_cuda_asked_for_where_there_is_none_is_one_line(fx, capsys):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a CUDA device")
    for argv in (["evaluate", "--policy", "expert", "--out", f"{fx}/x", "--device", "cuda"],
                 ["perceive", f"{fx}/unperceived.mcap", "--device", "cuda"],
                 ["perceive", f"{fx}/unperceived.mcap", f"{fx}/two_frames.mcap", "--device",
                  "cuda", "--workers", "2"],  # said by the command, not by its workers
                 ["train", "inspection", "--data", f"{fx}/data_none", "--out", f"{fx}/x",
                  "--device", "cuda"]):
        code, err = _run_in_process(argv, capsys)
        _one_clear_line(code, err, ["device 'cuda' is not available", "--device cpu or auto"])
