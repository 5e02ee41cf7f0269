"""Another camera (perception.camera_shift): drawn from a seed, applied as a pure image function."""

import numpy as np
import pytest

from perception.camera_shift import (
    RANGES,
    REFERENCE_TEMPERATURE_K,
    CameraShift,
    white_balance_gains,
)


def _image(seed: int = 0, shape=(48, 64, 3)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = rng.integers(20, 235, shape, dtype=np.uint8)
    img[8:24, 8:40] = (180, 120, 60)  # a flat patch: a colour cast shows plainly on it
    return img


def test_a_camera_is_reproducible_from_its_seed():
    for seed in (0, 7, (2026, 1, 3)):
        a, b = CameraShift.draw(seed), CameraShift.draw(seed)
        assert a == b
        img = _image()
        np.testing.assert_array_equal(a.apply(img), b.apply(img))
        np.testing.assert_array_equal(a.apply(img), a.apply(img.copy()))


def test_different_seeds_give_different_cameras_and_pictures():
    img = _image()
    cameras = [CameraShift.draw((2026, 0, k)) for k in range(20)]
    assert len({c.temperature_k for c in cameras}) == 20
    pictures = [c.apply(img) for c in cameras[:5]]
    for i in range(5):
        for j in range(i):
            assert not np.array_equal(pictures[i], pictures[j])
    # every setting within its declared range, both signs of white balance and exposure drawn
    mired = np.array([1e6 / c.temperature_k - 1e6 / REFERENCE_TEMPERATURE_K for c in cameras])
    assert ((np.abs(mired) >= RANGES["mired_shift"][0] - 1e-9)
            & (np.abs(mired) <= RANGES["mired_shift"][1] + 1e-9)).all()
    assert (mired < 0).any() and (mired > 0).any()
    ev = np.array([c.exposure_ev for c in cameras])
    assert (ev < 0).any() and (ev > 0).any()
    for c in cameras:
        assert RANGES["gamma"][0] <= c.gamma <= RANGES["gamma"][1]
        assert RANGES["defocus_px"][0] <= c.defocus_px <= RANGES["defocus_px"][1]
        assert RANGES["noise"][0] <= c.noise <= RANGES["noise"][1]
        assert RANGES["jpeg_quality"][0] <= c.jpeg_quality <= RANGES["jpeg_quality"][1]


def test_apply_is_pure_and_each_frame_gets_noise_of_its_own():
    camera = CameraShift.draw(3)
    a, b = _image(1), _image(2)
    kept = a.copy()
    out = camera.apply(a)
    np.testing.assert_array_equal(a, kept)  # its input untouched
    assert out.shape == a.shape and out.dtype == np.uint8
    noisy = CameraShift(noise=4.0, seed=(3,))
    # the same flat patch in two frames: the same camera, noise drawn afresh for each frame
    assert not np.array_equal(noisy.apply(a)[8:24, 8:40], noisy.apply(b)[8:24, 8:40])
    np.testing.assert_array_equal(noisy.apply(a), noisy.apply(a))


def test_the_reference_camera_changes_nothing_and_white_balance_turns_the_picture():
    img = _image()
    np.testing.assert_array_equal(CameraShift().apply(img), img)
    np.testing.assert_allclose(white_balance_gains(REFERENCE_TEMPERATURE_K), 1.0)
    warm_set, cool_set = white_balance_gains(5000.0), white_balance_gains(9000.0)
    assert warm_set[2] > 1.0 > warm_set[0]  # set for warmer light: the picture turns blue
    assert cool_set[0] > 1.0 > cool_set[2]
    patch = CameraShift(temperature_k=5000.0).apply(img)[10:22, 10:38].reshape(-1, 3).mean(0)
    assert patch[2] > 60 + 5 and patch[0] < 180 - 8
    # exposure brightens, gamma > 1 darkens the mid-tones, defocus smooths
    assert CameraShift(exposure_ev=0.5).apply(img).mean() > img.mean() + 5
    assert CameraShift(gamma=1.2).apply(img).mean() < img.mean() - 3
    assert np.abs(np.diff(CameraShift(defocus_px=1.0).apply(img).astype(float), axis=1)
                  ).mean() < np.abs(np.diff(img.astype(float), axis=1)).mean() / 2


@pytest.mark.parametrize("seed, error, words", [
    (-1, ValueError, "non-negative"), ((3, -2), ValueError, "non-negative"),
    ("7", TypeError, "'7'"), (True, TypeError, "True"), ((), TypeError, "()"),
    (1.5, TypeError, "1.5"), ([1, "a"], TypeError, "'a'")])
def test_bad_seeds_are_refused(seed, error, words):
    with pytest.raises(error, match="seed must be") as info:
        CameraShift.draw(seed)
    assert words in str(info.value)


def test_bad_settings_and_images_are_refused():
    with pytest.raises(ValueError, match="gamma must be in"):
        CameraShift(gamma=0.0)
    with pytest.raises(ValueError, match=r"temperature_k must be in \[1667.0, 25000.0\]; got 500"):
        CameraShift(temperature_k=500.0)
    with pytest.raises(ValueError, match="jpeg_quality must be"):
        CameraShift(jpeg_quality=3)
    with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8 RGB; got shape \(4, 4\)"):
        CameraShift().apply(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="dtype float64"):
        CameraShift().apply(np.zeros((4, 4, 3)))


def test_a_dataset_gives_each_session_and_line_up_a_camera_of_its_own():
    from onionsort.stages.cameras import SessionCameras

    cameras = SessionCameras(5)
    frame = {"session": 2, "source": "human", "frame": 7}
    assert cameras.camera(frame) == cameras.camera({"session": 2, "frame": 0})  # its views too
    assert cameras.camera(frame) == CameraShift.draw((5, 0, 2))
    assert cameras.camera({"source": "robot", "lineup": 2, "session": 9}) == \
        CameraShift.draw((5, 1, 2))
    assert cameras.camera(frame) != cameras.camera({"session": 3})
    assert cameras.camera(frame) != SessionCameras(6).camera(frame)
    img = _image()
    np.testing.assert_array_equal(cameras(img, frame), CameraShift.draw((5, 0, 2)).apply(img))
    for bad in (-1, True, 1.5, "3"):
        with pytest.raises(ValueError, match="camera_shift must be a seed, an int >= 0"):
            SessionCameras(bad)
