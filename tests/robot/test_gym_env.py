"""The Gymnasium environment ``onionsort/Sorting-v0``: Gymnasium's checker passes, and a fixed
policy rolled out through it counts exactly what ``evaluate`` counts for the same seed."""

from __future__ import annotations

import hashlib
import json
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import robot
from irl.domains.onion_sorting import (
    N_ACTIONS,
    Prediction,
    decode_state,
    encode_state,
    onion_sorting,
    sorting_features,
)
from robot.camera import CameraSpec
from robot.evaluation import evaluate_policy
from robot.gym_env import SortingEnv, sorting_reward

SMALL_CAMERA = CameraSpec(width=64, height=48)


@pytest.fixture(scope="module")
def expert_actions():
    return onion_sorting().expert_policy().argmax(axis=1)


def hash_classifier(views: list[np.ndarray]) -> Prediction:
    """A deterministic classifier that depends on every pixel of the views: GOOD, BAD or
    UNKNOWN (abstain), so perception errors and abstentions depend on the seed."""
    digest = hashlib.sha256(b"".join(v.tobytes() for v in views)).digest()
    return Prediction(digest[0] % 3)


def rollout(env, actions, seed):
    """Observations, infos and rewards of the greedy policy ``actions[s]`` from ``seed``."""
    obs, info = env.reset(seed=seed)
    observations, infos, rewards = [obs], [info], []
    while True:
        obs, reward, terminated, truncated, info = env.step(int(actions[info["state_index"]]))
        observations.append(obs)
        infos.append(info)
        rewards.append(reward)
        if terminated or truncated:
            return observations, infos, rewards, terminated


def test_importing_robot_registers_the_environment():
    assert robot.SORTING_ENV_ID == "onionsort/Sorting-v0"
    assert "onionsort/Sorting-v0" in gymnasium.registry
    env = gymnasium.make("onionsort/Sorting-v0", n_onions=2, n_blemished=1, camera=SMALL_CAMERA)
    try:
        assert isinstance(env.unwrapped, SortingEnv)
        assert env.action_space == gymnasium.spaces.Discrete(5)
        assert env.observation_space["image"].shape == (48, 64, 3)
        assert env.observation_space["state"].nvec.tolist() == [4, 4, 3]
        obs, info = env.reset(seed=0)
        assert obs in env.observation_space
        assert decode_state(info["state_index"]) == tuple(obs["state"])
        assert (info["tp"], info["fp"], info["tn"], info["fn"]) == (0, 0, 0, 0)
    finally:
        env.close()


def test_gymnasiums_env_checker_passes():
    env = gymnasium.make("onionsort/Sorting-v0", n_onions=2, n_blemished=1, move_steps=40,
                         camera=SMALL_CAMERA, render_mode="rgb_array")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the checker warns on what it does not fail
            check_env(env.unwrapped)
        env.reset(seed=1)
        frame = env.render()
        assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8 and frame.any()
    finally:
        env.close()
    env.close()  # closing twice is allowed


@pytest.mark.parametrize("seed", [4, 11])
def test_a_fixed_policy_rollout_counts_what_the_evaluation_counts(expert_actions, seed):
    """Same station, seed and counting as ``evaluate_policy`` (rendering, as ``onionsort
    evaluate`` does by default), under image noise and a classifier that errs and abstains,
    step by step: states, actions, running counts and the main camera's images."""
    kwargs = dict(n_onions=3, n_blemished=2, classify=hash_classifier, difficulty="hard",
                  move_steps=40)
    events = []
    expected = evaluate_policy(expert_actions, seed=seed, render=True, on_step=events.append,
                               **kwargs)
    env = SortingEnv(**kwargs)
    try:
        observations, infos, rewards, terminated = rollout(env, expert_actions, seed)
    finally:
        env.close()
    got = infos[-1]["result"]
    assert got.to_dict() == expected.to_dict()
    assert terminated == (expected.undecided == 0)
    assert len(events) == len(rewards) == expected.n_steps
    true_r = onion_sorting().mdp.reward(onion_sorting().true_theta)
    for e, obs, info, r in zip(events, observations[1:], infos[1:], rewards, strict=True):
        assert info["state_index"] == e.next_state == encode_state(obs["state"])
        assert (info["tp"], info["fp"], info["tn"], info["fn"]) == (e.tp, e.fp, e.tn, e.fn)
        assert info["fate"] == e.fate and info["perceived"] == e.perceived
        assert np.array_equal(obs["image"], e.color)
        assert r == true_r[e.state, e.action]


def test_a_truncated_episode_counts_undecided_onions_as_left_on_the_line(expert_actions):
    # the expert needs 4 actions an onion; 3 an onion leave the last one undecided
    kwargs = dict(n_onions=3, n_blemished=1, max_steps_per_onion=3, move_steps=40)
    expected = evaluate_policy(expert_actions, seed=2, classify="ground-truth", **kwargs)
    env = SortingEnv(camera=SMALL_CAMERA, **kwargs)
    try:
        _, infos, rewards, terminated = rollout(env, expert_actions, seed=2)
        assert not terminated and len(rewards) == 9
        with pytest.raises(RuntimeError, match="call reset"):
            env.step(0)
    finally:
        env.close()
    got = infos[-1]["result"]
    assert got.undecided == expected.undecided == 1
    assert got.to_dict() == expected.to_dict()
    running = sum(infos[-1][k] for k in ("tp", "fp", "tn", "fn"))
    assert running == 2  # the running counts cover decided onions only


def test_the_rollout_matches_the_evaluate_stage_on_a_learned_model(tmp_path):
    from onionsort.stages.evaluate import EvaluateConfig, evaluate

    # a "learned" policy that bins every onion it inspected, whatever it saw
    actions = onion_sorting().expert_policy().argmax(axis=1)
    for s in range(len(actions)):
        if decode_state(s).onion.name == "FACE":
            actions[s] = 4
    (tmp_path / "model.json").write_text(json.dumps(
        {"method": "test", "policy_indices": actions.tolist()}))
    expected, _ = evaluate(EvaluateConfig(run=tmp_path, onions=3, blemished=1, seed=7,
                                          ground_truth_inspection=True, rerun=False))
    env = gymnasium.make("onionsort/Sorting-v0", n_onions=3, n_blemished=1,
                         camera=SMALL_CAMERA)
    try:
        _, infos, _, terminated = rollout(env, actions, seed=7)
    finally:
        env.close()
    assert terminated
    assert infos[-1]["result"].to_dict() == expected.to_dict()
    assert (expected.tp, expected.fp, expected.tn, expected.fn) == (1, 2, 0, 0)


def test_the_reward_is_the_true_one_or_a_learned_models(tmp_path):
    phi = sorting_features()
    true = onion_sorting()
    assert np.array_equal(sorting_reward(), phi @ true.true_theta)
    theta = {name: float(i) - 2.5 for i, name in enumerate(true.task.feature_names)}
    (tmp_path / "model.json").write_text(json.dumps({"method": "x", "theta": theta}))
    learned = phi @ np.array(list(theta.values()))
    assert np.array_equal(sorting_reward(tmp_path / "model.json"), learned)
    assert np.array_equal(sorting_reward(tmp_path), learned)  # a run folder
    env = SortingEnv(n_onions=1, n_blemished=0, reward_model=tmp_path / "model.json",
                     camera=SMALL_CAMERA, move_steps=40)
    try:
        _, info = env.reset(seed=0)
        s = info["state_index"]
        _, reward, *_ = env.step(0)  # CLAIM
        assert reward == learned[s, 0] == theta["claim_new_onion"]
    finally:
        env.close()


@pytest.mark.parametrize("theta, match", [
    ({"good_on_conveyor": 1.0}, "exactly the features"),
    ("not a dict", "not a learned model"),
    ({name: "x" for name in onion_sorting().task.feature_names}, "numeric theta"),
])
def test_a_bad_reward_model_is_refused_naming_it(tmp_path, theta, match):
    (tmp_path / "model.json").write_text(json.dumps({"theta": theta}))
    with pytest.raises(ValueError, match=f"reward_model .*{match}"):
        SortingEnv(reward_model=tmp_path / "model.json")
    with pytest.raises(FileNotFoundError, match="reward_model"):
        SortingEnv(reward_model=tmp_path / "missing.json")


@pytest.mark.parametrize("kwargs, match", [
    (dict(n_onions=0), "n_onions"),
    (dict(n_onions=2, n_blemished=3), "n_blemished"),
    (dict(max_steps_per_onion=0), "max_steps_per_onion"),
    (dict(move_steps=1), "move_steps"),
    (dict(classify="perfect"), "classify"),
    (dict(render_mode="human"), "render_mode"),
    (dict(difficulty="impossible"), "difficulty"),
])
def test_bad_arguments_raise_value_errors_naming_them(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SortingEnv(**kwargs)


def test_steps_need_a_reset_and_a_valid_action():
    env = SortingEnv(n_onions=1, n_blemished=1, camera=SMALL_CAMERA, move_steps=40)
    try:
        with pytest.raises(RuntimeError, match="reset"):
            env.step(0)
        env.reset(seed=0)
        for bad in (N_ACTIONS, -1, 1.5, True):
            with pytest.raises(ValueError, match="action"):
                env.step(bad)
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_the_rollout_matches_onionsort_evaluate_with_the_detector(tmp_path, seed):
    """The acceptance check end to end: the shipped models inspect, on a hard station, and
    ``onionsort evaluate`` records to Rerun (its default, which renders every step). The env
    takes the level's fused calibration, as ``evaluate --difficulty hard`` does."""
    from onionsort.stages.evaluate import EvaluateConfig, evaluate
    from onionsort.stages.models import PerceptionModels

    models = PerceptionModels.load(None)
    actions = onion_sorting().expert_policy().argmax(axis=1)
    (tmp_path / "model.json").write_text(json.dumps(
        {"method": "expert", "policy_indices": actions.tolist()}))
    expected, _ = evaluate(EvaluateConfig(run=tmp_path, onions=4, blemished=2, seed=seed,
                                          difficulty="hard"), models=models)
    env = gymnasium.make("onionsort/Sorting-v0", n_onions=4, n_blemished=2, difficulty="hard",
                         classify=models.at_level("hard").inspector(camera="robot"))
    try:
        _, infos, _, _ = rollout(env, actions, seed)
    finally:
        env.close()
    assert infos[-1]["result"].to_dict() == expected.to_dict()
