"""Tests for mocapedit.inspect.metrics: analytic cases and brute-force references."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pxr import Gf

from mocapedit.inspect import metrics as M


# ---------------------------------------------------------------------------------------------
# Ground plane
# ---------------------------------------------------------------------------------------------


def test_ground_axes_and_round_trip():
    assert M.ground_axes("Y") == (1, (0, 1.0), (2, -1.0))
    assert M.ground_axes("z") == (2, (0, 1.0), (1, 1.0))
    np.testing.assert_allclose(M.to_ground([1.0, 2.0, 3.0], "Y"), [1.0, -3.0])
    np.testing.assert_allclose(M.to_ground([1.0, 2.0, 3.0], "Z"), [1.0, 2.0])
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(7, 3))
    for up, iup in (("Y", 1), ("Z", 2)):
        back = M.from_ground(M.to_ground(pts, up), pts[:, iup], up)
        np.testing.assert_allclose(back, pts, atol=1e-15)
    # ground_axes describes the same mapping as mocapedit.geometry.ground.
    from mocapedit.geometry import ground
    for up in ("Y", "Z"):
        iup, (iu, su), (iv, sv) = M.ground_axes(up)
        np.testing.assert_allclose(ground.to_ground(pts, up), np.stack((su * pts[:, iu],
                                                                         sv * pts[:, iv]), 1))
        np.testing.assert_allclose(ground.height(pts, up), pts[:, iup])
    with pytest.raises(ValueError, match="up axis"):
        M.ground_axes("X")
    with pytest.raises(ValueError, match="up axis"):
        M.from_ground([0.0, 0.0], 0.0, "X")
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        M.to_ground(np.zeros((4, 2)), "Y")


@pytest.mark.parametrize("up,axis", [("Y", (0, 1, 0)), ("Z", (0, 0, 1))])
def test_ground_headings_are_counter_clockwise_about_up(up, axis):
    # A positive rotation about up turns ground u into ground v.
    rot = Gf.Rotation(Gf.Vec3d(*axis), 90.0)
    turned = rot.TransformDir(Gf.Vec3d(1, 0, 0))
    np.testing.assert_allclose(M.to_ground(np.array(turned), up), [0.0, 1.0], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Trajectory measures
# ---------------------------------------------------------------------------------------------


def test_path_length_and_ratio():
    assert M.path_length([[0, 0], [3, 4], [3, 0]]) == pytest.approx(9.0)
    assert M.path_length([[0, 0, 0], [1, 2, 2]]) == pytest.approx(3.0)
    assert M.path_length([[5.0, 5.0]]) == 0.0
    assert M.length_ratio([[0, 0], [0, 6]], [[0, 0], [3, 4]]) == pytest.approx(1.2)
    assert M.length_ratio([[1, 1], [1, 1]], [[0, 0], [0, 0]]) == 1.0
    assert M.length_ratio([[1, 1], [1, 2]], [[0, 0], [0, 0]]) == math.inf
    with pytest.raises(ValueError):
        M.path_length(np.zeros((3, 4)))


def test_position_residuals():
    r = M.position_residuals([[0, 0], [1, 1], [2, 2]], [[0, 0], [1, 2], [5, 6]])
    np.testing.assert_allclose(r, [0.0, 1.0, 5.0])
    with pytest.raises(ValueError):
        M.position_residuals(np.zeros((3, 2)), np.zeros((2, 2)))


def test_local_coordinates_hand_case():
    xy = M.local_coordinates([[0, 0], [1, 1], [2, 0]])
    # d = (2, 0), R90 d = (0, -2): P1 = P0 + 0.5 d - 0.5 R90 d.
    np.testing.assert_allclose(xy, [[0.5, -0.5]])


def _curve(n=40):
    s = np.linspace(0.0, 3.0, n)
    return np.stack((3.0 * s, np.sin(2.0 * s) + 0.3 * s * s), axis=1)


def test_shape_change_is_zero_under_similarity_transforms():
    src = _curve()
    a, scale = 0.7, 2.5
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    edited = scale * src @ rot.T + np.array([10.0, -4.0])
    assert M.shape_change(src, edited) == pytest.approx(0.0, abs=1e-12)
    assert M.shape_change(src, src) == 0.0


def test_shape_change_detects_non_similar_edits():
    src = _curve(12)
    stretched = src * np.array([2.0, 1.0])
    mirrored = src * np.array([1.0, -1.0])
    assert M.shape_change(src, stretched) > 0.01
    assert M.shape_change(src, mirrored) > 0.01


def test_shape_change_bend_hand_value():
    src = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [4, 0]], dtype=float)
    bent = src.copy()
    bent[2] = (2.0, 1.0)
    # Changes of (x, y): (-0.1, 0.2), (0, -0.5), (0.1, 0.2).
    assert M.shape_change(src, bent) == pytest.approx(math.sqrt(0.35 / 3.0), rel=1e-12)


def test_shape_change_degenerate_triangles():
    # A pause (repeated points) has no local frame: skipped, so a rigid move still measures 0.
    src = np.array([[0, 0], [1, 0], [2, 0], [2, 0], [2, 0], [3, 1], [4, 1]], dtype=float)
    moved = src @ np.array([[0.0, -1.0], [1.0, 0.0]]).T + 3.0
    assert M.shape_change(src, moved) == pytest.approx(0.0, abs=1e-12)
    # A triangle that exists in the source but collapses in the edit has lost its shape.
    collapsed = src.copy()
    collapsed[2] = collapsed[0]
    assert M.shape_change(src, collapsed) == math.inf


def test_rigidity_error_zero_for_rigid_motion_of_the_range():
    src = _curve(30)
    a = -1.1
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    edited = src.copy()
    edited[5:16] = src[5:16] @ rot.T + np.array([2.0, 7.0])
    edited[20:] *= 1.7  # outside the ranges: does not count
    err = M.rigidity_error(src, edited, [(5, 15), (0, 0), (7, 9)])
    assert err.shape == (3,)
    np.testing.assert_allclose(err, 0.0, atol=1e-12)


def test_rigidity_error_positive_for_bend_and_scale():
    src = np.array([[-1.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    scaled = src * 2.0
    # Best rigid fit of (-1,0),(1,0) onto (-2,0),(2,0) is the identity about the centroid.
    np.testing.assert_allclose(M.rigidity_error(src, scaled, [(0, 1)]), [1.0], atol=1e-12)
    bent = src.copy()
    bent[2] = (1.0, 2.0)
    assert M.rigidity_error(src, bent, [(0, 2)])[0] > 0.1
    assert M.rigidity_error(src, bent, [(0, 1)])[0] == pytest.approx(0.0, abs=1e-12)


def test_rigidity_error_rejects_bad_ranges():
    src = np.zeros((5, 2))
    for bad in ([(0, 5)], [(-1, 2)], [(3, 2)]):
        with pytest.raises(ValueError, match="frame range"):
            M.rigidity_error(src, src, bad)


def test_time_intervals_positive():
    assert M.time_intervals_positive([0.0, 1.0, 1.5, 4.0])
    assert not M.time_intervals_positive([0.0, 1.0, 1.0, 4.0])
    assert not M.time_intervals_positive([0.0, 2.0, 1.0])
    assert not M.time_intervals_positive([0.0, math.nan, 2.0])
    assert M.time_intervals_positive([[0, 1, 2], [5, 6, 9]])
    assert not M.time_intervals_positive([[0, 1, 2], [5, 4, 9]])
    assert M.time_intervals_positive([3.0])
    assert not M.time_intervals_positive([0.0, 0.5, 1.0], min_interval=0.5)


# ---------------------------------------------------------------------------------------------
# Separation
# ---------------------------------------------------------------------------------------------


def _brute_separation(positions, radius, height, up):
    """All pairs at every sample, written independently of the module."""
    iup = M.ground_axes(up)[0]
    p = np.asarray(positions, float)
    n_agents, n_times = p.shape[:2]
    rad = np.broadcast_to(radius, (n_agents,)).astype(float)
    hgt = np.broadcast_to(height, (n_agents,)).astype(float)
    horiz_idx = [k for k in range(3) if k != iup]
    best, where, overlaps = math.inf, None, 0
    iu = np.triu_indices(n_agents, 1)
    for t in range(n_times):
        q = p[:, t]
        ok = np.isfinite(q).all(axis=1)
        flat = q[:, horiz_idx]
        dh = np.sqrt(((flat[:, None, :] - flat[None, :, :]) ** 2).sum(-1))
        bottom = q[:, iup] + rad
        top = q[:, iup] + np.maximum(hgt, 2 * rad) - rad
        gap = np.clip(np.maximum(bottom[None, :] - top[:, None], bottom[:, None] - top[None, :]),
                      0.0, None)
        clear = np.sqrt(dh ** 2 + gap ** 2) - rad[:, None] - rad[None, :]
        c = clear[iu]
        valid = ok[iu[0]] & ok[iu[1]]
        c = np.where(valid, c, np.inf)
        overlaps += int(np.count_nonzero(c < 0))
        k = int(np.argmin(c))
        if c[k] < best:
            best, where = float(c[k]), ((int(iu[0][k]), int(iu[1][k])), t)
    return best, where, overlaps


def test_min_separation_two_capsules_by_hand():
    pos = np.zeros((2, 3, 3))
    pos[1, :, 0] = 0.5
    pos[1, 1, 0] = 0.55
    sep = M.min_separation(pos, 0.3, 1.8, "Y")
    assert sep.clearance == pytest.approx(-0.1, abs=1e-12)
    assert sep.agents == (0, 1)
    assert sep.time_index in (0, 2)
    assert sep.overlaps == 3


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_min_separation_stacked_capsules_use_vertical_gap(up):
    # B stands 3 units above A, straight over it: the axis segments are 1.8 apart.
    pos = np.zeros((2, 1, 3))
    pos[1, 0] = M.from_ground([[0.0, 0.0]], 3.0, up)[0]
    sep = M.min_separation(pos, [0.3, 0.3], [1.8, 1.8], up)
    assert sep.clearance == pytest.approx(1.2, abs=1e-12)
    assert sep.overlaps == 0


def test_min_separation_far_apart_and_degenerate_inputs():
    pos = np.zeros((3, 2, 3))
    pos[1, :, 0] = 100.0
    pos[2, :, 2] = -300.0
    sep = M.min_separation(pos, 0.3, 1.8, "Y")
    assert sep.clearance == pytest.approx(99.4, abs=1e-9)
    assert sep.agents == (0, 1)
    assert M.min_separation(np.zeros((1, 5, 3)), 0.3, 1.8, "Y").agents is None
    lonely = np.full((2, 2, 3), np.nan)
    lonely[0, 0] = 0.0
    lonely[1, 1] = 0.0  # never present at the same sample
    assert M.min_separation(lonely, 0.3, 1.8, "Z").clearance == math.inf
    with pytest.raises(ValueError):
        M.min_separation(np.zeros((2, 3)), 0.3, 1.8, "Y")
    with pytest.raises(ValueError):
        M.min_separation(np.zeros((2, 3, 3)), -0.3, 1.8, "Y")
    with pytest.raises(ValueError):
        M.min_separation(np.zeros((2, 3, 3)), 0.3, 0.0, "Y")


def test_min_separation_is_exact_when_the_first_grid_is_too_fine():
    # Agents on one line: the spacing estimate is tiny, so the search starts with small cells.
    # Pair (0, 1) sits in neighbouring cells of a fine grid; the closer pair (2, 3) may not.
    x = np.array([0.0, 1.3, 50.35, 51.35, 400.0])
    pos = np.zeros((5, 3, 3))
    pos[:, :, 0] = x[:, None]
    sep = M.min_separation(pos, 0.3, 1.8, "Z")
    assert sep.clearance == pytest.approx(0.4, abs=1e-9)
    assert sep.agents == (2, 3)
    assert sep.overlaps == 0


@pytest.mark.parametrize("up,seed", [("Y", 0), ("Z", 1), ("Y", 2)])
def test_min_separation_matches_brute_force(up, seed):
    rng = np.random.default_rng(seed)
    n_agents, n_times = 400, 12
    ground = rng.uniform(-20.0, 20.0, size=(n_agents, 1, 2)) + rng.normal(
        scale=0.3, size=(n_times, n_agents, 2)).cumsum(axis=0).transpose(1, 0, 2)
    raised = rng.random((n_agents, n_times)) < 0.1  # some agents stand on something
    base = np.where(raised, rng.uniform(0, 3, (n_agents, n_times)), 0.0)
    pos = M.from_ground(ground, base, up)
    pos[rng.random((n_agents, n_times)) < 0.05] = np.nan
    radius = rng.uniform(0.2, 0.45, n_agents)
    height = rng.uniform(0.5, 2.0, n_agents)
    sep = M.min_separation(pos, radius, height, up)
    best, (pair, t), overlaps = _brute_separation(pos, radius, height, up)
    assert overlaps > 0
    assert sep.clearance == pytest.approx(best, abs=1e-12)
    assert sep.overlaps == overlaps
    assert (sep.agents, sep.time_index) == (pair, t)


def test_min_separation_dense_crowd_in_runs_matches_brute_force():
    # Samples are measured in runs with the same agents at the same elevations: a run of two,
    # then one where an agent has left, then one where another stands higher.
    rng = np.random.default_rng(3)
    pos = M.from_ground(rng.uniform(0.0, 6.0, size=(80, 5, 2)), 0.0, "Y")
    pos[7, 2:] = np.nan
    pos[9, 3:, 1] = 0.7
    sep = M.min_separation(pos, 0.3, 1.8, "Y")
    best, (pair, t), overlaps = _brute_separation(pos, 0.3, 1.8, "Y")
    assert sep.clearance == pytest.approx(best, abs=1e-12)
    assert sep.overlaps == overlaps > 0
    assert (sep.agents, sep.time_index) == (pair, t)


def test_capsule_clearance_broadcasts():
    ground_b = np.array([[0.5, 0.0], [0.0, 0.0], [3.0, 4.0]])
    clear = M.capsule_clearance([0.0, 0.0], 0.0, 0.3, 1.8, ground_b, [0.0, 3.0, 0.0], 0.3, 1.8)
    np.testing.assert_allclose(clear, [-0.1, 1.2, 4.4], atol=1e-12)
    # Capsules shorter than their diameter are spheres resting on their base: centres at 0.5, 2.5.
    assert M.capsule_clearance([0, 0], 0.0, 0.5, 0.2, [0, 0], 2.0, 0.5, 0.2) == pytest.approx(1.0)


def test_min_separation_sparse_crowd_matches_brute_force():
    # Clustered agents plus stragglers far away: the first grid is too fine and must coarsen.
    rng = np.random.default_rng(5)
    pos = np.zeros((60, 4, 3))
    pos[:, :, 0] = rng.uniform(0, 1000, (60, 1))
    pos[:, :, 2] = rng.uniform(0, 1000, (60, 1))
    pos[:, :, 0] += np.arange(4) * 2.0
    sep = M.min_separation(pos, 0.3, 1.8, "Y")
    best, (pair, t), overlaps = _brute_separation(pos, 0.3, 1.8, "Y")
    assert overlaps == 0 and sep.overlaps == 0
    assert sep.clearance == pytest.approx(best, abs=1e-9)
    assert sep.agents == pair


def test_min_separation_many_agents_matches_brute_force():
    rng = np.random.default_rng(11)
    n_agents, n_times = 1000, 8
    start = rng.uniform(0.0, 40.0, size=(n_agents, 2))
    heading = rng.uniform(0, 2 * np.pi, n_agents)
    vel = 1.4 / 24.0 * np.stack((np.cos(heading), np.sin(heading)), axis=1)
    ground = start[:, None, :] + np.arange(n_times)[None, :, None] * vel[:, None, :]
    pos = M.from_ground(ground, 0.0, "Z")
    sep = M.min_separation(pos, 0.3, 1.8, "Z")
    best, (pair, t), overlaps = _brute_separation(pos, 0.3, 1.8, "Z")
    assert sep.clearance == pytest.approx(best, abs=1e-12)
    assert sep.overlaps == overlaps > 0
    assert (sep.agents, sep.time_index) == (pair, t)


# ---------------------------------------------------------------------------------------------
# Joint names (foot skate on stages: tests/tools/test_measure.py)
# ---------------------------------------------------------------------------------------------


def test_default_foot_joints():
    names = ["Root", "Root/Hips", "Root/Hips/LeftFoot", "Root/Hips/LeftFoot/LeftToeBase",
             "Root/Hips/LeftFoot/LeftToe_End", "Root/Hips/RightAnkle", "Root/Hips/End Site",
             "Root/Football/Spine", "Root/Hips/RIGHTFOOT"]
    assert M.default_foot_joints(names) == [2, 3, 5, 8]


# ---------------------------------------------------------------------------------------------
# Plausibility: facing and walking direction against the source
# ---------------------------------------------------------------------------------------------


def test_facing_change_per_second_and_spin_threshold_scale_with_frame_rate():
    for fps in (24.0, 60.0, 120.0):
        seconds = np.arange(5) / fps
        facing = np.radians([0.0, 1.0, 1.0, -20.0, 340.0 - 360.0])
        rate = M.facing_change_per_second(facing, seconds)
        np.testing.assert_allclose(rate, np.array([1.0, 0.0, 21.0, 0.0]) * fps, atol=1e-9)
        # 15 degrees per frame at 60 fps is the same rate at every frame rate.
        assert math.isclose(M.spin_threshold(), 15.0 * 60.0)
        per_frame = np.degrees(np.abs(np.diff(facing))) * fps
        source = np.zeros(4)
        spun = M.spins(source, rate)
        np.testing.assert_array_equal(spun, per_frame > 900.0)
        assert not M.spins(rate, rate).any()        # the source turning as fast is no spin
    with pytest.raises(ValueError):
        M.facing_change_per_second([0.0, 1.0], [0.0, 0.0])


def test_facing_change_unwraps_across_pi():
    facing = np.radians([170.0, -170.0])            # 20 degrees counter-clockwise, not 340
    np.testing.assert_allclose(M.facing_change_per_second(facing, [0.0, 1.0]), [20.0], atol=1e-9)


def test_direction_deviation_by_hand():
    t = np.arange(41) / 20.0                         # 2 s at 20 fps, chords of 5 frames
    source = np.stack((t, np.zeros_like(t)), axis=1)  # 1 unit per second along +u
    same = M.direction_deviation(source, source + 3.0, t, min_speed=0.5)
    assert np.nanmax(same) < 1e-9 and np.isnan(same[-5:]).all() and np.isfinite(same[:-5]).all()
    back = source.copy()
    back[20:] = source[20] - (source[20:] - source[20])   # walks back after 1 s
    dev = M.direction_deviation(source, back, t, min_speed=0.5)
    assert math.isclose(np.nanmax(dev), 180.0, abs_tol=1e-9)
    assert np.nanmax(dev[:15]) < 1e-9
    side = np.stack((t, t), axis=1)                    # 45 degrees off
    assert math.isclose(np.nanmax(M.direction_deviation(source, side, t, 0.5)), 45.0, abs_tol=1e-9)
    # Where the source stands, nothing is measured however the edit moves.
    stand = np.zeros_like(source)
    assert np.isnan(M.direction_deviation(stand, back, t, min_speed=0.5)).all()


def _walk_along(points, speed=1.0, fps=24.0):
    """Ground samples walking the polyline ``points`` at ``speed`` units per second, and their
    times (s)."""
    pts = np.asarray(points, dtype=np.float64)
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    t = np.arange(0.0, arc[-1] / speed + 1e-9, 1.0 / fps)
    d = t * speed
    return np.stack((np.interp(d, arc, pts[:, 0]), np.interp(d, arc, pts[:, 1])), axis=1), t


def _straight(n, fps=24.0, speed=1.0):
    t = np.arange(n) / fps
    return np.stack((t * speed, np.zeros(n)), axis=1), t


def test_a_turn_the_edit_asks_for_is_no_reversal():
    # A 5 m walk turned 90 degrees left after 5 m by a rounded corner that overshoots to about
    # 120 degrees before it settles: against the unturned source it deviates more than 90
    # degrees, against the turn the edit makes it stays well within.
    a = np.radians(np.linspace(0.0, 120.0, 30))
    bend = np.stack((5.0 + 0.8 * np.sin(a), 0.8 * (1.0 - np.cos(a))), axis=1)
    edited, t = _walk_along(np.vstack(([0.0, 0.0], bend, bend[-1] + [-0.5, 4.0])))
    source, _ = _straight(len(t))
    speed = M.WALKING_SPEED_M
    assert np.nanmax(M.direction_deviation(source, edited, t, speed)) > 100.0
    turn = M.edit_turn(source, edited, t, speed)
    assert abs(turn[0]) < 1e-9 and np.degrees(turn[-1]) == pytest.approx(97.1, abs=1.0)
    assert np.nanmax(M.direction_deviation(source, edited, t, speed, turn=turn)) < 60.0
    # An unedited path turns by exactly 0; a whole path turned by 30 degrees by exactly that.
    np.testing.assert_allclose(M.edit_turn(source, source + 2.0, t, speed), 0.0, atol=1e-12)
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    np.testing.assert_allclose(M.edit_turn(source, source @ np.array([[c, s], [-s, c]]), t, speed),
                               np.radians(30.0), atol=1e-12)
    with pytest.raises(ValueError):
        M.direction_deviation(source, edited, t, speed, turn=turn[:-1])


def test_a_walk_back_or_a_loop_is_still_a_reversal():
    source, t = _straight(97)
    speed = M.WALKING_SPEED_M
    # Walks 2 s, back 1 s along itself, on again: the short chords go against the edit's turn.
    d = np.interp(t, [0.0, 2.0, 3.0, 4.0], [0.0, 2.0, 1.0, 2.0])
    back = np.stack((d, np.zeros_like(d)), axis=1)
    turn = M.edit_turn(source, back, t, speed)
    assert np.nanmax(M.direction_deviation(source, back, t, speed, turn=turn)) > 170.0
    # A full loop of 1 m radius in the middle of a straight walk: the edit turns it round past 180.
    a = np.linspace(0.0, 2.0 * np.pi, 60)
    loop = np.stack((1.5 + np.sin(a), 1.0 - np.cos(a)), axis=1)
    edited, t = _walk_along(np.vstack(([0.0, 0.0], loop, [4.0, 0.0])))
    source, _ = _straight(len(t))
    assert np.degrees(np.abs(M.edit_turn(source, edited, t, speed)).max()) > 180.0


def _step_away_and_back(shift):
    """30 fps ground samples: a slow step east (0.35 m/s, 0.5 s), a quick step 0.8 m east and
    0.9 m back west (0.5 s each), ``shift`` metres north on the way back, then a walk south."""
    fps, pts = 30.0, [np.zeros((1, 2))]
    for velocity, secs in (((0.35, 0.0), 0.5), ((1.6, 0.0), 0.5), ((-1.8, 2.0 * shift), 0.5), ((0.0, -1.3), 2.5)):
        n = int(round(secs * fps))
        pts.append(pts[-1][-1] + np.outer(np.arange(1, n + 1) / fps, velocity))
    ground = np.concatenate(pts)
    return ground, np.arange(len(ground)) / fps


def test_a_step_away_and_back_has_no_direction_for_an_edit_to_turn():
    """A take that steps away and back, pushed 0.4 m aside on the way back: its walking direction
    never deviates 50 degrees from the source's. The 2 s chord of a step away and back is short
    and points anywhere; measured there, the edit's turn was 108 degrees, held back over the
    slow step before, where the edit changes nothing, and that step counted as walking back."""
    source, t = _step_away_and_back(0.0)
    edited, _ = _step_away_and_back(0.4)
    speed = M.WALKING_SPEED_M
    assert np.nanmax(M.direction_deviation(source, edited, t, speed)) < 50.0
    turn = M.edit_turn(source, edited, t, speed)
    assert np.nanmax(M.direction_deviation(source, edited, t, speed, turn=turn)) < 60.0
    zero = np.zeros(len(t))
    figures = M.plausibility_of("a", t, _hips(zero, source), t, _hips(zero, edited), "Y", 1.0)
    assert figures.max_turned_deviation < 60.0 and not figures.reverses


def test_default_facing_joint():
    assert M.default_facing_joint(["Root", "Root/Hips", "Root/Hips/LeftUpLeg"]) == 1
    assert M.default_facing_joint(["pelvis", "pelvis/spine"]) == 0
    assert M.default_facing_joint(["Root", "Root/LeftHip", "Root/mixamorig_Hips"]) == 2
    assert M.default_facing_joint(["Root", "Root/Spine"]) == 0
    # A side's hip joint is not the hips (CMU's LHipJoint before the pelvis of a rig without "Hips").
    assert M.default_facing_joint(["Ref", "Ref/LHipJoint", "Ref/Bip01_Pelvis"]) == 2
    assert M.default_facing_joint(["root", "root/lhipjoint", "root/lhipjoint/lfemur", "root/lowerback"]) == 0




def _hips(headings, points, height=0.9):
    """(T, 4, 4) Y-up facing joint matrices: local axis 0 along each heading, at ground points."""
    c, s = np.cos(headings), np.sin(headings)
    m = np.zeros((len(headings), 4, 4))
    m[:, 0, 0], m[:, 0, 2], m[:, 1, 1], m[:, 2, 0], m[:, 2, 2], m[:, 3, 3] = c, -s, 1.0, s, c, 1.0
    m[:, 3, 0], m[:, 3, 1], m[:, 3, 2] = points[:, 0], height, -points[:, 1]
    return m


def test_many_agents_measured_together_equal_each_measured_alone():
    """plausibilities_of: agents of different lengths in one call (one re-timed with held ends,
    one too short to turn) get the figures plausibility_of gives each alone."""
    rng = np.random.default_rng(4)
    agents = []
    for count, edited_count in ((48, 48), (30, 41), (2, 1), (60, 60)):
        t = np.arange(count) / 24.0
        heading = np.cumsum(rng.normal(0.0, 0.05, count))
        ground = np.cumsum(1.3 / 24.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1), axis=0)
        frames = np.clip(np.linspace(-3.0, count + 2.0, edited_count), 0, count - 1)  # held ends
        bend = np.interp(frames, np.arange(count), np.linspace(0.0, 1.2, count))
        at = np.stack([np.interp(frames, np.arange(count), ground[:, k]) for k in range(2)], axis=1)
        edited = _hips(np.interp(frames, np.arange(count), heading) + bend + rng.normal(0.0, 0.02, edited_count),
                       at + rng.normal(0.0, 0.01, at.shape))
        agents.append((t, _hips(heading, ground), np.arange(edited_count) / 24.0, edited, frames))
    names = [f"a{k}" for k in range(len(agents))]
    skate = rng.uniform(0.0, 0.1, (2, len(agents)))
    together = M.plausibilities_of(names, *[[a[k] for a in agents] for k in range(4)], "Y", 1.0, *skate,
                                   edited_frames=[a[4] for a in agents])
    for name, a, s, e, p in zip(names, agents, *skate, together):
        alone = M.plausibility_of(name, *a[:4], "Y", 1.0, s, e, edited_frames=a[4])
        for field in dataclasses.fields(alone):
            x, y = getattr(alone, field.name), getattr(p, field.name)
            assert x == y or (np.isnan(x).all() and np.isnan(y).all()), (name, field.name, x, y)
    assert len({p.max_facing_rate for p in together}) == len(agents) and together[1].time_warp[0] > 1.0
    assert together[2].max_facing_rate == 0.0 and together[2].worst_turn_frame == -1
