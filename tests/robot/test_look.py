"""Domain randomization of the look: drawn from the session's seed, the same seed renders the
same, off renders exactly as without it, and it never changes what happens in a session."""

from __future__ import annotations

import numpy as np
import pytest

from robot.look import SURFACES, draw_look, look_rng
from robot.simulation import SessionConfig, SortingSession, expert_model
from robot.station import robot_inspection_views


@pytest.fixture(scope="module")
def expert():
    return expert_model()


def _frames(expert, seed=5, **kwargs):
    config = SessionConfig(n_steps=3, occlusion=0.5, frames_per_step=2, **kwargs)
    with SortingSession(config, *expert, seed=seed) as session:
        return list(session.frames())


def _images(frames):
    return [(f.color, f.depth, f.inspection) for f in frames]


def _same(a, b) -> bool:
    return all(all((x is None and y is None) or np.array_equal(x, y) for x, y in zip(p, q,
                                                                                    strict=True))
               for p, q in zip(_images(a), _images(b), strict=True))


def test_a_look_is_drawn_from_its_seed_and_seeds_differ():
    a, b = draw_look(look_rng(3)), draw_look(look_rng(3))
    assert a == b
    looks = [draw_look(look_rng(s)) for s in range(8)]
    assert len({look.lighting for look in looks}) == 8
    assert len({look.gains for look in looks}) == 8
    for look in looks:
        assert set(look.surfaces) == set(SURFACES)
        assert all(0 <= v <= 1 for rgb in look.surfaces.values() for v in rgb)
        assert all(0 <= v <= 1 for v in look.lighting.color)
    # the look's generator is a stream of its own: drawing it leaves the session's seed alone
    seq = np.random.SeedSequence(3)
    look_rng(seq).random(5)
    assert seq.n_children_spawned == 0
    rgb = np.full((4, 4, 3), 100, np.uint8)
    bright = [look for look in looks if min(look.gains) > 1.05]
    assert bright and all(look.camera(rgb).min() > 100 for look in bright)


def test_the_same_seed_renders_the_same_and_off_renders_as_without_it(expert):
    plain = _frames(expert)
    off = _frames(expert, randomize_look=False)
    assert _same(plain, off)  # off: exactly today's world (the default)
    assert SessionConfig().randomize_look is False
    a = _frames(expert, randomize_look=True)
    b = _frames(expert, randomize_look=True)
    assert _same(a, b)
    other = _frames(expert, seed=6, randomize_look=True)
    assert not np.array_equal(a[0].color, other[0].color)
    # the look changes the pictures, never the session: states, actions, labels, depth
    assert [f.step for f in a] == [f.step for f in plain]
    assert [[o.box for o in f.onions] for f in a] == [[o.box for o in f.onions] for f in plain]
    assert all(np.array_equal(x.depth, y.depth) for x, y in zip(a, plain, strict=True))
    assert not any(np.array_equal(x.color, y.color) for x, y in zip(a, plain, strict=True))
    # at a difficulty level too: the level's own effects are drawn as without the look
    hard = _frames(expert, difficulty="hard", randomize_look=True)
    assert [f.step for f in hard] == [f.step for f in plain]


@pytest.mark.slow
def test_the_robot_views_follow_the_look_and_keep_their_labels():
    def views(**kwargs):
        return list(robot_inspection_views(1, 4, "clean", inspection_views=2, **kwargs))

    plain, off, on, again = views(), views(randomize_look=False), views(randomize_look=True), \
        views(randomize_look=True)
    for (i, k, rgb, labels), (j, m, rgb2, labels2) in zip(plain, off, strict=True):
        assert (i, k, labels) == (j, m, labels2) and np.array_equal(rgb, rgb2)
    for (_, _, rgb, _), (_, _, rgb2, _) in zip(on, again, strict=True):
        assert np.array_equal(rgb, rgb2)
    assert [(i, k) for i, k, _, _ in on] == [(i, k) for i, k, _, _ in plain]
    assert [[lab[:3] for lab in labels] for *_, labels in on] == \
        [[lab[:3] for lab in labels] for *_, labels in plain]
    assert not np.array_equal(on[0][2], plain[0][2])
