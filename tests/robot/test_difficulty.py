"""Perception difficulty: clean is today's world bit for bit, every level is reproducible, and
each effect changes the images in the direction it models."""

from __future__ import annotations

import numpy as np
import pytest

from robot.difficulty import DIFFICULTY_LEVELS, Difficulty, ImageEffects, resolve_difficulty
from robot.onions import onion_texture, sample_appearance
from robot.simulation import SessionConfig, SortingSession, expert_model


@pytest.fixture(scope="module")
def expert():
    return expert_model()


def _frames(expert, difficulty=None, seed=5, n_steps=4, occlusion=0.5):
    kwargs = {} if difficulty is None else {"difficulty": difficulty}
    config = SessionConfig(n_steps=n_steps, occlusion=occlusion, frames_per_step=2, **kwargs)
    with SortingSession(config, *expert, seed=seed) as session:
        return list(session.frames()), session


def _same(a, b) -> bool:
    return all(
        np.array_equal(x.color, y.color) and np.array_equal(x.depth, y.depth)
        and (x.inspection is None) == (y.inspection is None)
        and (x.inspection is None or np.array_equal(x.inspection, y.inspection))
        and x.step == y.step and x.occluded_fraction == y.occluded_fraction
        for x, y in zip(a, b, strict=True)
    )


def test_clean_is_bit_identical_to_the_world_without_difficulty(expert):
    plain, _ = _frames(expert)
    clean, _ = _frames(expert, "clean")
    assert _same(plain, clean)
    assert SessionConfig().difficulty == DIFFICULTY_LEVELS["clean"]
    assert SessionConfig().to_dict()["difficulty"]["name"] == "clean"


@pytest.mark.parametrize("level", ["paper"])
def test_a_level_is_reproducible_from_the_seed_and_keeps_the_clean_labels(expert, level):
    a, _ = _frames(expert, level)
    b, _ = _frames(expert, level)
    other, _ = _frames(expert, level, seed=6)
    plain, _ = _frames(expert)
    assert _same(a, b)
    assert not _same(a, other)
    assert [f.step for f in a] == [f.step for f in plain]  # same states, actions, occlusion
    assert not any(np.array_equal(x.color, y.color) for x, y in zip(a, plain, strict=True))


def test_levels_are_named_and_resolvable():
    assert list(DIFFICULTY_LEVELS) == ["clean", "realistic", "paper", "hard"]
    assert DIFFICULTY_LEVELS["clean"].is_clean
    assert not any(DIFFICULTY_LEVELS[k].is_clean for k in ("realistic", "paper", "hard"))
    assert resolve_difficulty("paper") is DIFFICULTY_LEVELS["paper"]
    assert resolve_difficulty(DIFFICULTY_LEVELS["hard"].to_dict()) == DIFFICULTY_LEVELS["hard"]
    with pytest.raises(ValueError, match="unknown difficulty"):
        resolve_difficulty("nightmare")
    with pytest.raises(ValueError, match="read_noise"):
        Difficulty(read_noise=-1.0)


def _effects(**knobs) -> ImageEffects:
    return ImageEffects(Difficulty(**knobs), np.random.default_rng(0))


def test_noise_raises_the_pixel_spread_of_a_flat_region():
    flat = np.full((60, 80, 3), 120, np.uint8)
    assert _effects().color(flat) is flat
    noisy = _effects(read_noise=5.0, shot_noise=0.5).color(flat)
    assert 4.0 < noisy.astype(float).std() < 9.0
    assert abs(noisy.astype(float).mean() - 120) < 1.0


def test_jpeg_blur_and_lighting_change_pixels():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (64, 64, 3)).astype(np.uint8)
    jpeg = _effects(jpeg_quality=20).color(img)
    assert np.abs(jpeg.astype(int) - img).mean() > 10
    blur = _effects(motion_blur_px=8.0)
    assert blur.color(img, moving=False) is not img and np.array_equal(blur.color(img), img)
    assert blur.color(img, moving=True).astype(float).std() < 0.8 * img.astype(float).std()
    light = _effects(lighting_gain=0.3, lighting_drift=0.2)
    assert not np.allclose(light.gain_at(0.0), light.gain_at(40.0))
    depth = np.ones((10, 10), np.float32)
    assert np.array_equal(_effects().depth(depth), depth)
    assert 0.005 < _effects(depth_noise_m=0.01).depth(depth).std() < 0.02


def test_the_hand_covers_part_of_the_onion():
    img = np.zeros((120, 160, 3), np.uint8)
    hand = _effects(hand_cover=0.5, hand_cover_rate=1.0).hand(img, (60, 40, 100, 80),
                                                              (200, 150, 120))
    inside = (hand[40:80, 60:100] > 0).any(axis=2).mean()
    assert 0.05 < inside < 0.6
    assert _effects().hand(img, (60, 40, 100, 80), (200, 150, 120)) is img


def test_subtle_blemishes_have_fewer_rot_pixels():
    def rot_pixels(texture, base):
        return int((np.abs(texture.astype(int) - base.astype(int)).sum(axis=2) > 60).sum())

    for seed in range(4):
        look = sample_appearance(np.random.default_rng(seed), blemished=True)
        good = onion_texture(sample_appearance(np.random.default_rng(seed), blemished=False))
        today = rot_pixels(onion_texture(look), good)
        subtle = rot_pixels(onion_texture(look, subtlety=0.65), good)
        assert today > 0 and subtle < 0.5 * today
        assert np.array_equal(onion_texture(look, subtlety=0.0, one_sided=0.0),
                              onion_texture(look))


def test_a_partial_passer_by_covers_less_than_the_full_one(expert):
    frames, session = _frames(expert, Difficulty(partial_occlusion=1.0), seed=3, n_steps=8,
                              occlusion=0.5)
    assert session.partial.any() and session.occluded.any()
    assert not (session.partial & session.occluded).any()
    full = [f.occluded_fraction for f in frames if session.occluded[f.step.step]]
    part = [f.occluded_fraction for f in frames if session.partial[f.step.step]]
    assert all(not f.step.occluded for f in frames if session.partial[f.step.step])
    assert 0.0 < np.mean(part) < 0.6 * np.mean(full)


def test_the_cli_takes_a_difficulty_and_rejects_an_unknown_one(tmp_path, capsys):
    from onionsort.cli import main

    for command in (["dataset", "--frames", "10"], ["record"]):
        with pytest.raises(SystemExit) as exit_:
            main([*command, "--difficulty", "nightmare", "--out", str(tmp_path / "x")])
        assert exit_.value.code == 2
    with pytest.raises(SystemExit) as exit_:
        main(["evaluate", str(tmp_path), "--difficulty", "nightmare"])
    assert exit_.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
    assert main(["record", "--sessions", "1", "--steps-per-session", "2", "--frames-per-step",
                 "1", "--difficulty", "paper", "--out", str(tmp_path / "rec")]) == 0
    from recordings import open_session

    session = open_session(tmp_path / "rec" / "session_000.mcap")
    assert session.metadata["config"]["difficulty"]["name"] == "paper"
