"""The body's facing after an edit: the source heading turned by the rotation the edit applies
to the path around each frame (trajectory.deformation_turns), never the edited path's tangent."""
from __future__ import annotations

import numpy as np
import pytest

from mocapedit.geometry import trajectory
from mocapedit.solve import path_edit


def _rotate(points, angle, centre=(0.0, 0.0)):
    c, s = np.cos(angle), np.sin(angle)
    p = np.asarray(points) - centre
    return np.stack((c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]), axis=1) + centre


def _walk_stand_walk(n=120, stand=(40, 80), seed=0):
    """A walk along +u with a sway, standing (with capture jitter) over ``stand``."""
    rng = np.random.default_rng(seed)
    speed = np.ones(n)
    speed[stand[0]:stand[1]] = 0.0
    u = np.concatenate([[0.0], np.cumsum(speed[:-1])]) * 0.05
    v = 0.02 * np.sin(u * 2 * np.pi / 1.2)                # sway by the step, none standing
    path = np.stack((u, v), axis=1)
    path[stand[0]:stand[1]] += rng.normal(scale=1e-4, size=(stand[1] - stand[0], 2))
    return path


def test_an_unedited_path_turns_by_exactly_zero():
    src = _walk_stand_walk()
    turn = trajectory.deformation_turns(src, src.copy(), [0, len(src)], window=2, min_travel=0.01)
    assert np.all(turn == 0.0)


@pytest.mark.parametrize("angle", [0.3, -2.5, 3.0])
def test_a_rigidly_turned_path_turns_by_its_angle_everywhere(angle):
    src = _walk_stand_walk()
    turned = _rotate(src, angle, centre=(1.0, -2.0)) + (4.0, 5.0)
    turn = trajectory.deformation_turns(src, turned, [0, len(src)], window=3, min_travel=0.01)
    np.testing.assert_allclose(turn, angle, atol=1e-9)


def test_a_stand_turns_smoothly_between_the_walks_around_it():
    """The stand's jitter is bent about wildly by the edit: its tangent would spin, the facing
    goes from the turn before the stand to the turn after it, by frame."""
    src = _walk_stand_walk()
    edited = src.copy()
    edited[80:] = _rotate(src[80:], 0.8, centre=src[80]) + (src[79] - src[80]) * 0.0
    rng = np.random.default_rng(3)
    edited[40:80] += rng.normal(scale=5e-4, size=(40, 2))
    turn = trajectory.deformation_turns(src, edited, [0, len(src)], window=2, min_travel=0.01)
    assert np.abs(turn[:36]).max() < 1e-9
    np.testing.assert_allclose(turn[84:], 0.8, atol=1e-9)
    assert np.abs(np.diff(turn)).max() < 0.8 / 30           # spread over the stand, no jump
    assert np.all(np.diff(turn[38:82]) >= -0.005)             # and (up to the jitter) monotonic


def test_a_side_step_keeps_its_relation_to_the_path():
    """Walking sideways (along +v, facing +u): a bend of the path turns the facing with the
    path, so it stays at right angles to the walk."""
    n = 60
    src = np.stack((np.zeros(n), 0.04 * np.arange(n)), axis=1)
    edited = _rotate(src, 0.5)
    turn = trajectory.deformation_turns(src, edited, [0, n], window=2, min_travel=0.01)
    np.testing.assert_allclose(turn, 0.5, atol=1e-12)


def test_fixed_ranges_turn_rigidly_by_their_own_angle_and_blocks_are_independent():
    a, b = _walk_stand_walk(seed=1), _walk_stand_walk(n=90, stand=(10, 30), seed=2)
    ea, eb = _rotate(a, 0.2), _rotate(b, -0.4, centre=(1.0, 1.0))
    src, edi = np.concatenate([a, b]), np.concatenate([ea, eb])
    fixed = [(0, 40, 79), (1, 10, 29)]
    both = trajectory.deformation_turns(src, edi, [0, 120, 210], fixed, [0.25, -0.45], window=2, min_travel=0.01)
    np.testing.assert_array_equal(both[40:80], 0.25)
    np.testing.assert_array_equal(both[130:150], -0.45)
    one = trajectory.deformation_turns(a, ea, [0, 120], [(0, 40, 79)], [0.25], window=2, min_travel=0.01)
    two = trajectory.deformation_turns(b, eb, [0, 90], [(0, 10, 29)], [-0.45], window=2, min_travel=0.01)
    np.testing.assert_allclose(both, np.concatenate([one, two]), atol=1e-12)
    np.testing.assert_allclose(one[:30], 0.2, atol=1e-9)      # away from the range, the path's turn
    with pytest.raises(ValueError):
        trajectory.deformation_turns(a, ea[:-1], [0, 119])


def test_a_path_that_never_moves_does_not_turn():
    src = np.zeros((30, 2))
    turn = trajectory.deformation_turns(src, src + 1.0, [0, 30], window=2, min_travel=0.01)
    assert np.all(turn == 0.0)


@pytest.mark.parametrize("speed", [0.12, 0.2])
def test_a_slow_shuffle_nudged_sideways_barely_turns(speed):
    """Avoidance nudges a shuffling agent 4 cm sideways for a moment: a displacement, not a
    turn of the body (its own turn of the windows said 30 degrees at 0.12 m/s)."""
    fps = 60.0
    t = np.arange(0.0, 4.0, 1.0 / fps)
    src = np.stack((speed * t, 0.0 * t), axis=1)
    edited = src + np.stack((0.0 * t, 0.04 * np.exp(-0.5 * ((t - 2.0) / 0.15) ** 2)), axis=1)
    args = path_edit.turn_settings(fps, 1.0)
    turn = trajectory.deformation_turns(src, edited, [0, len(src)], window=args["turn_window"],
                                        min_travel=args["turn_min_travel"])
    assert np.degrees(np.abs(turn).max()) < 7.0
    assert np.degrees(np.abs(np.diff(turn)).max()) * fps < 50.0          # degrees per second
    # The same nudge of a walk is a turn, as before.
    walk = np.stack((1.4 * t, 0.0 * t), axis=1)
    bent = trajectory.deformation_turns(walk, walk + (edited - src), [0, len(src)], window=args["turn_window"],
                                        min_travel=args["turn_min_travel"])
    assert 2.0 < np.degrees(np.abs(bent).max()) < 4.0


@pytest.mark.parametrize("speed", [0.12, 0.2, 0.5])
def test_a_slow_path_turned_rigidly_still_turns_by_its_angle(speed):
    fps = 60.0
    args = path_edit.turn_settings(fps, 1.0)
    src = _walk_stand_walk() * (speed / 1.4)
    turned = _rotate(src, 1.1, centre=(0.3, 0.2)) + (2.0, -1.0)
    turn = trajectory.deformation_turns(src, turned, [0, len(src)], window=args["turn_window"],
                                        min_travel=args["turn_min_travel"])
    np.testing.assert_allclose(turn, 1.1, atol=1e-9)


def _wander(seconds=12.0, fps=60.0, reach=0.08):
    """A root that moves about one spot (a boxer's bounce, an idle's shuffle): within ``reach``
    metres of where it starts, at 10 to 30 cm/s."""
    t = np.arange(0.0, seconds, 1.0 / fps)
    u = reach * (0.6 * np.sin(1.3 * t) + 0.4 * np.sin(3.1 * t + 1.0))
    v = reach * (0.6 * np.sin(1.7 * t + 0.5) + 0.4 * np.sin(2.3 * t + 2.0))
    return t, np.stack((u - u[0], v - v[0]), axis=1)


def test_a_path_about_one_spot_keeps_its_facing_however_the_edit_turns_its_wiggles():
    """Moved 40 cm sideways by handles, the path solve turns such a path's wiggles by tens of
    degrees to keep their lengths: that rotation is not the body's (a boxer moved aside faced
    45 degrees away, from the first frame on)."""
    fps = 60.0
    t, src = _wander(fps=fps)
    bump = np.stack((0.4 * np.sin(np.pi * t / t[-1]), 0.0 * t), axis=1)
    edited = _rotate(src, -0.7) + bump
    args = path_edit.turn_settings(fps, 1.0)
    kw = dict(window=args["turn_window"], min_travel=args["turn_min_travel"], max_step=args["turn_max_step"])
    turn = trajectory.deformation_turns(src, edited, [0, len(src)], **kw)
    # At most a few degrees where the root goes straight for a moment; 40 before.
    assert np.degrees(np.abs(turn).max()) < 10.0 and np.degrees(np.abs(turn).mean()) < 3.0
    # A group member turns with its formation, about one spot or not.
    member = trajectory.deformation_turns(src, edited, [0, len(src)], keep_spot=[False], **kw)
    assert np.degrees(member.mean()) < -25.0
    # A walk with the same wiggles, edited the same way, turns as before.
    walk = np.stack((1.4 * t, 0.0 * t), axis=1) + src
    bent = [trajectory.deformation_turns(walk, _rotate(walk, -0.7) + bump, [0, len(src)], keep_spot=[keep], **kw)
            for keep in (True, False)]
    np.testing.assert_array_equal(bent[0], bent[1])
    assert np.degrees(bent[0].mean()) < -30.0
