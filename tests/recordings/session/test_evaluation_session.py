"""``onionsort evaluate``'s outputs in 3D: the robot's run as a session MCAP (read back with
mcap's CRC-validating reader, the project's reader and ``rerun mcap check``) and its ``.rrd``
(the Sawyer's meshes and per-step joint transforms, ``rerun rrd verify``)."""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from irl.domains.onion_sorting import onion_sorting
from recordings import SessionWriter, open_session, strip_ground_truth
from recordings.session.rewrite import rewrite_session
from recordings.session.schema import Topic
from recordings.session.world import read_joint_states, read_transforms
from tests.recordings.session.test_world import SCHEMAS, mcap_check, messages, robot_session

SAWYER_JOINTS = [f"right_j{k}" for k in range(7)]
K = np.array([[100.0, 0.0, 16.0], [0.0, 100.0, 12.0], [0.0, 0.0, 1.0]])


@dataclass
class Evaluated:
    run: Path
    summary: dict
    n_steps: int

    @property
    def mcap(self) -> Path:
        return self.run / "evaluation.mcap"

    @property
    def rrd(self) -> Path:
        return self.run / "evaluation.rrd"


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory) -> Evaluated:
    """The expert's policy sorting 3 onions (2 blemished) with perfect inspection."""
    from onionsort.stages import EvaluateConfig, evaluate

    run = tmp_path_factory.mktemp("evaluate") / "run"
    run.mkdir()
    expert = onion_sorting().expert_policy().argmax(axis=1)
    (run / "model.json").write_text(json.dumps({"method": "expert",
                                                "policy_indices": [int(a) for a in expert]}))
    result, summary = evaluate(EvaluateConfig(run=run, onions=3, blemished=2, seed=1,
                                              ground_truth_inspection=True))
    return Evaluated(run, summary, result.n_steps)


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory):
    return robot_session(tmp_path_factory.mktemp("robot") / "robot.mcap")


def test_the_outputs_are_complete_and_nothing_temporary_is_left(evaluated):
    assert {p.name for p in evaluated.run.iterdir()} == {
        "model.json", "evaluation.json", "evaluation.rrd", "evaluation.mcap", "tally.csv"}
    assert evaluated.summary["n_steps"] == evaluated.n_steps == 12  # claim, pick, inspect, place


@pytest.mark.parametrize("which", ["recorded robot session", "evaluation"])
def test_both_sessions_have_tf_joint_states_and_scene_in_foxglove_schemas(which, evaluated,
                                                                          robot_run):
    path = robot_run.path if which == "recorded robot session" else evaluated.mcap
    n = len(robot_run.q) if which == "recorded robot session" else evaluated.n_steps
    got = messages(path, list(SCHEMAS))
    for topic, schema in SCHEMAS.items():
        assert [s for s, _, _ in got[topic]] == [schema] * n, topic
        assert [seq for _, seq, _ in got[topic]] == list(range(n)), topic
    for _, _, data in got[Topic.TF]:
        tf = read_transforms(data)
        assert tf["camera"][0] == "world" and tf["right_arm_base_link"][0] == "world"
        assert {f"right_l{k}" for k in range(7)} <= set(tf)
    for _, _, data in got[Topic.JOINT_STATES]:
        assert list(read_joint_states(data)) == SAWYER_JOINTS
    mcap_check(path)


def test_the_evaluation_session_reads_back_step_by_step(evaluated):
    session = open_session(evaluated.mcap)
    n = evaluated.n_steps
    assert (session.status, session.n_frames, len(session.steps)) == ("complete", n, n)
    assert session.frames_per_step == 1 and session.has_ground_truth and session.has_depth
    assert session.metadata["source"] == "onionsort evaluate"
    assert session.robot["joints"] == SAWYER_JOINTS
    # the decisions are the ground-truth steps, and each step starts where the last one ended
    assert sorted(session.decisions) == sorted(session.sorting_counts) == list(range(n))
    decisions = [session.decisions[t] for t in range(n)]
    assert [(d["state"], d["action"], d["next_state"]) for d in decisions] == [
        (s.state, s.action, s.next_state) for s in session.steps]
    assert all(a["next_state"] == b["state"] for a, b in itertools.pairwise(decisions))
    assert [d["action_name"] for d in decisions[:3]] == ["claim", "pick", "inspect"]
    assert decisions[3]["action_name"] == {"bin": "place_in_bin",
                                           "line": "place_on_conveyor"}[decisions[3]["fate"]]
    # the inspection view is on the frames of the steps that inspected, with what was seen
    frames = list(session.frames())
    inspected = [f.index for f in frames if f.inspection is not None]
    assert inspected == [t for t, d in enumerate(decisions) if d["action_name"] == "inspect"]
    assert all(decisions[t]["perceived"] in ("good", "bad") for t in inspected)
    # the running counts end at evaluation.json's; each onion gets one fate
    last = session.sorting_counts[n - 1]
    assert {k: last[k] for k in ("tp", "fp", "tn", "fn", "precision", "recall")} == {
        k: evaluated.summary[k] for k in ("tp", "fp", "tn", "fn", "precision", "recall")}
    assert sum(d["fate"] is not None for d in decisions) == last["decided"] == 3
    assert [session.sorting_counts[t]["decided"] for t in range(n)] == sorted(
        session.sorting_counts[t]["decided"] for t in range(n))
    # the 3D side shows only the onions in the world, in their true classes
    for f in frames:
        onions = {f"onions/{o['onion_id']}": o for o in f.onions}
        scene = {item.name: item for item in f.scene}
        assert {"workcell/belt", "workcell/pedestal", "gate"} <= set(scene)
        assert {name for name in scene if name.startswith("onions/")} == set(onions)
        for name, o in onions.items():
            assert scene[name].class_id == int(o["blemished"])
            np.testing.assert_allclose(scene[name].position, o["position"], atol=1e-4)
            assert o["position"][2] > 0  # none parked out of the world


def test_each_frame_shows_the_station_before_its_action(evaluated):
    """Frame t is the station at rest before action t: its joints are those the Rerun log
    shows after action t - 1 (and the arm rests before the first claim, which moves nothing)."""
    from tests.recordings.rerun.test_rerun import rows

    logged = rows(evaluated.rrd, "evaluate/arm/joints", "Scalars:scalars", "step")
    after = [np.array(q) for _, q in logged]
    session = open_session(evaluated.mcap)
    before = [np.array([f.joints[j] for j in SAWYER_JOINTS]) for f in session.frames()]
    assert len(after) == len(before) == evaluated.n_steps
    np.testing.assert_allclose(before[0], after[0], atol=1e-9)  # a claim moves no joint
    for t in range(1, evaluated.n_steps):
        np.testing.assert_allclose(before[t], after[t - 1], atol=1e-9)
    assert not np.allclose(before[1], before[2])  # the pick moved the arm


def test_the_evaluation_rrd_has_the_sawyers_meshes_and_joint_transforms(evaluated):
    from tests.recordings.rerun.test_rerun import assert_sawyer, summary, verify, views

    s = summary(evaluated.rrd)
    assert_sawyer(s, "evaluate", evaluated.n_steps)
    assert s["evaluate/robot/base"]["static"] == {True}
    assert {"evaluate/scene/workcell/boxes", "evaluate/scene/onions/spheres",
            "evaluate/scene/gate/boxes"} <= set(s)
    assert views(evaluated.rrd) == ["evaluate"]
    verify(evaluated.rrd)


def test_stripping_keeps_the_decisions_and_drops_the_counts(evaluated, tmp_path):
    sensor = open_session(strip_ground_truth(evaluated.mcap, tmp_path / "sensor.mcap"))
    assert not sensor.has_ground_truth and sensor.sorting_counts == {}
    assert sensor.decisions == open_session(evaluated.mcap).decisions
    assert all(f.scene is None and f.joints is not None for f in sensor.frames())
    mcap_check(tmp_path / "sensor.mcap")


def test_sessions_without_the_evaluation_topics_still_open(evaluated, tmp_path):
    old = rewrite_session(evaluated.mcap, tmp_path / "old.mcap",
                          drop_topics=(Topic.DECISION, Topic.COUNTS))
    assert messages(old, [Topic.DECISION, Topic.COUNTS]) == {Topic.DECISION: [],
                                                             Topic.COUNTS: []}
    session = open_session(old)
    assert session.decisions == {} and session.sorting_counts == {}
    assert session.n_frames == evaluated.n_steps


@dataclass(frozen=True)
class Decision:
    step: int
    state: int = 0
    action: int = 0
    next_state: int = 2
    onion: int | None = 0
    blemished: bool | None = True
    perceived: int | None = None
    fate: str | None = None
    tp: int = 0
    fp: int = 0
    tn: int = 0
    fn: int = 0
    precision: float = 0.0
    recall: float = 0.0


def test_write_decision_writes_counts_only_with_ground_truth_and_refuses_bad_values(tmp_path):
    color = np.zeros((24, 32, 3), np.uint8)
    path = tmp_path / "sensor.mcap"
    with SessionWriter(path, {}, K, frames_per_step=1, depth=False,
                       ground_truth=False) as writer:
        writer.write_decision(Decision(0, perceived=1, fate="bin", tp=1, precision=1.0),
                              frame=0, time_ns=0)
        writer.write_sensor_frame(index=0, step=0, phase=0, time_ns=0, color=color)
        with pytest.raises(ValueError, match=r"decision\.fate must be 'bin', 'line' or None"):
            writer.write_decision(Decision(1, fate="floor"), frame=1, time_ns=1)
        with pytest.raises(ValueError, match=r"decision\.next_state must be in \[0, 48\)"):
            writer.write_decision(Decision(1, next_state=48), frame=1, time_ns=1)
        with pytest.raises(ValueError, match=r"action must be in \[0, 5\)"):
            writer.write_decision(Decision(1, action=7), frame=1, time_ns=1)
    session = open_session(path)
    assert session.sorting_counts == {}
    assert session.decisions[0]["perceived"] == "bad" and session.decisions[0]["fate"] == "bin"
    assert sorted(session.decisions) == [0]  # the refused decisions wrote nothing
    got = messages(path, [Topic.DECISION])
    assert [s for s, _, _ in got[Topic.DECISION]] == ["onionsort.Decision"]
    mcap_check(path)

