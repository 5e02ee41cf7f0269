"""A short session simulated once and recorded to MCAP, shared by the recordings tests."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from irl.demonstrations import StepTruth
from recordings import SessionWriter
from robot.camera import intrinsics
from robot.labels import Frame
from robot.simulation import SessionConfig, SortingSession, expert_model


def step_tuples(steps) -> list[tuple]:
    """Steps as (step, state, action, next_state, occluded) tuples, whoever made them."""
    return [(s.step, s.state, s.action, s.next_state, s.occluded) for s in steps]


@dataclass
class Recorded:
    path: object
    steps: list[StepTruth]
    frames: list[Frame]
    config: SessionConfig


def record(path, n_steps=12, occlusion=0.3, seed=4, frames_per_step=2) -> Recorded:
    policy, initial = expert_model()
    config = SessionConfig(n_steps=n_steps, occlusion=occlusion, frames_per_step=frames_per_step)
    frames = []
    with SortingSession(config, policy, initial, seed) as session, SessionWriter(
        path, {"seed": seed, "config": config.to_dict()}, intrinsics(config.camera),
        intrinsics(config.inspection), frames_per_step=frames_per_step,
    ) as writer:
        for frame in session.frames():
            writer.write_frame(frame)
            frames.append(frame)
    return Recorded(path, list(session.steps), frames, config)


@pytest.fixture(scope="session")
def recorded(tmp_path_factory) -> Recorded:
    return record(tmp_path_factory.mktemp("rec") / "session.mcap")
