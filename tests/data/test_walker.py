"""Tests of the procedural clips: skeleton, planted feet, travel, units, quaternions."""
from __future__ import annotations

import numpy as np
import pytest

from mocapedit.data import walker

FPS = 24.0


def _up(clip: walker.Clip) -> int:
    return 1 if clip.up_axis == "Y" else 2


def _horizontal(clip: walker.Clip) -> list[int]:
    return [0, 2] if clip.up_axis == "Y" else [0, 1]


def _foot_positions_m(clip: walker.Clip) -> np.ndarray:
    """(F, 4, 3) skeleton-space foot joint positions in metres."""
    idx = [clip.joint_index(j) for j in clip.foot_joints]
    return walker.joint_world_positions(clip)[:, idx] * clip.meters_per_unit


CLIPS = {
    "walk": lambda: walker.walk(120, FPS),
    "walk_slow": lambda: walker.walk(120, FPS, speed=0.8),
    "walk_fast_30fps": lambda: walker.walk(150, 30.0, speed=2.0),
    "run": lambda: walker.run(120, FPS),
    "turn": lambda: walker.turn(120, FPS),
    # 300 degrees in all: the root's quaternion passes w = 0 and must not flip.
    "turn_full_circle": lambda: walker.turn(240, FPS, turn_rate=-30.0),
    "idle": lambda: walker.idle(120, FPS),
    "walk_idle_walk": lambda: walker.walk_idle_walk(240, FPS)[0],
    "walk_zup_cm": lambda: walker.walk(120, FPS, up="Z", meters_per_unit=0.01),
    "run_zup_cm": lambda: walker.run(120, FPS, up="Z", meters_per_unit=0.01),
}


def test_invalid_arguments_are_rejected():
    with pytest.raises(ValueError, match="frames"):
        walker.walk(0)
    with pytest.raises(ValueError, match="fps"):
        walker.walk(10, fps=0.0)
    with pytest.raises(ValueError, match="up"):
        walker.walk(10, up="X")
    with pytest.raises(ValueError, match="meters_per_unit"):
        walker.idle(10, meters_per_unit=0.0)
    with pytest.raises(ValueError, match="speed"):
        walker.run(10, speed=0.0)
    with pytest.raises(ValueError, match="standing range"):
        walker.walk_idle_walk(100, stop_frame=0)
    with pytest.raises(ValueError, match="standing range"):
        walker.walk_idle_walk(100, stop_frame=60, idle_frames=40)
    with pytest.raises(ValueError, match="standing range"):
        walker.walk_idle_walk(100, idle_frames=0)


def test_skeleton_layout():
    clip = walker.walk(10)
    assert 18 <= clip.num_joints <= 31
    assert clip.joints[0] == "Root" and clip.parents[0] == -1
    assert clip.joints[1] == "Root/Hips" and clip.parents[1] == 0
    for j, path in enumerate(clip.joints[1:], start=1):
        parent = clip.parents[j]
        assert 0 <= parent < j, "parents must come before their children"
        assert path.rsplit("/", 1)[0] == clip.joints[parent], "UsdSkel joint paths"
    names = {p.rsplit("/", 1)[-1] for p in clip.joints}
    for side in ("Left", "Right"):
        assert {side + n for n in ("UpLeg", "Leg", "Foot", "Toe", "Shoulder", "Arm",
                                   "ForeArm", "Hand")} <= names
    assert {"Spine", "Chest", "Neck", "Head"} <= names
    assert len(clip.foot_joints) == 4 and all(j in clip.joints for j in clip.foot_joints)
    assert clip.joint_index("LeftFoot") == clip.joints.index(clip.foot_joints[0])
    with pytest.raises(KeyError):
        clip.joint_index("Tail")


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_arrays_have_documented_shapes_and_types(name):
    clip = CLIPS[name]()
    f, j = clip.num_frames, clip.num_joints
    assert clip.translations.shape == (f, j, 3) and clip.translations.dtype == np.float32
    assert clip.rotations.shape == (f, j, 4) and clip.rotations.dtype == np.float32
    assert clip.rest_translations.shape == (j, 3) and clip.rest_rotations.shape == (j, 4)
    assert clip.parents.shape == (j,)
    assert clip.foot_contacts.shape == (f, 4) and clip.foot_contacts.dtype == bool
    assert np.all(np.isfinite(clip.translations)) and np.all(np.isfinite(clip.rotations))
    # Only the root and the hips move away from their rest offsets.
    np.testing.assert_array_equal(clip.translations[:, 2:], np.broadcast_to(
        clip.rest_translations[2:], (f, j - 2, 3)))


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_quaternions_are_unit_and_sign_continuous(name):
    clip = CLIPS[name]()
    norms = np.linalg.norm(clip.rotations.astype(np.float64), axis=-1)
    assert np.abs(norms - 1.0).max() < 1e-5
    assert np.abs(np.linalg.norm(clip.rest_rotations, axis=-1) - 1.0).max() < 1e-6
    dots = np.einsum("fjk,fjk->fj", clip.rotations[1:], clip.rotations[:-1])
    assert dots.min() > 0.0, "a quaternion flips sign between frames"
    # And no joint turns more than 90 degrees in one frame (a swapped solution).
    assert dots.min() > np.cos(np.radians(45.0))


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_feet_are_planted_during_contact(name):
    clip = CLIPS[name]()
    feet = _foot_positions_m(clip)
    hor = _horizontal(clip)
    step = np.linalg.norm(np.diff(feet[..., hor], axis=0), axis=-1) * clip.fps
    both = clip.foot_contacts[1:] & clip.foot_contacts[:-1]
    assert both.any(axis=0).all(), "every foot joint is in contact at some point"
    assert step[both].max() < 0.01, "planted feet slide (m/s)"
    vertical = np.abs(np.diff(feet[..., _up(clip)], axis=0)) * clip.fps
    assert vertical[both].max() < 0.01
    # Planted joints sit on their rest heights above the ground: ankle 8 cm, toe 2 cm.
    heights = feet[..., _up(clip)]
    for k, rest_height in enumerate((0.08, 0.02, 0.08, 0.02)):
        on_ground = heights[clip.foot_contacts[:, k], k]
        np.testing.assert_allclose(on_ground, rest_height, atol=1e-4)
    assert heights.min() > 0.015, "a foot goes through the ground"
    if name != "idle":
        # The check above only means something if the feet also swing.
        assert (~clip.foot_contacts).any(axis=0).all()
        assert step[~clip.foot_contacts[1:] & ~clip.foot_contacts[:-1]].max() > 0.5


def test_a_heel_rises_before_its_toe_lifts():
    clip = walker.walk(120)
    ankle, toe = clip.foot_contacts[:, 0], clip.foot_contacts[:, 1]
    assert np.all(toe[ankle]), "the ankle is never down while the toe is up"
    assert np.any(toe & ~ankle), "the foot rolls about the toe before lift-off"


@pytest.mark.parametrize("speed,fps", [(1.4, 24.0), (1.0, 30.0), (2.0, 25.0)])
def test_walk_travels_speed_times_time(speed, fps):
    frames = 100
    clip = walker.walk(frames, fps, speed=speed)
    root = clip.translations[:, 0].astype(np.float64)
    np.testing.assert_allclose(root[0], 0.0, atol=1e-7)
    np.testing.assert_allclose(root[-1], [0.0, 0.0, speed * (frames - 1) / fps], atol=1e-4)
    per_frame = np.linalg.norm(np.diff(root, axis=0), axis=-1) * fps
    np.testing.assert_allclose(per_frame, speed, rtol=1e-4)
    # The root stays on the ground and faces along +Z (its rotation is identity).
    np.testing.assert_allclose(root[:, 1], 0.0, atol=1e-7)
    np.testing.assert_allclose(np.abs(clip.rotations[:, 0, 3]), 1.0, atol=1e-6)
    # The hips travel with it, at a walking height that bobs a few centimetres.
    hips_height = clip.translations[:, 1, 1]
    assert 0.85 < hips_height.min() < hips_height.max() < 0.97
    assert hips_height.max() - hips_height.min() > 0.01


def test_run_travels_and_has_a_flight_phase():
    clip = walker.run(120, FPS, speed=3.5)
    root = clip.translations[:, 0].astype(np.float64)
    np.testing.assert_allclose(root[-1, 2], 3.5 * 119 / FPS, rtol=1e-5)
    flight = ~clip.foot_contacts.any(axis=1)
    assert 10 < flight.sum() < 60
    ankles = _foot_positions_m(clip)[:, [0, 2], 1]
    assert ankles[flight].min() > 0.09, "a foot is down during flight"
    # A walk is never airborne.
    assert walker.walk(120, FPS).foot_contacts.any(axis=1).all()


def test_idle_does_not_travel():
    clip = walker.idle(120, FPS)
    np.testing.assert_array_equal(clip.translations[:, 0], 0.0)
    np.testing.assert_allclose(np.abs(clip.rotations[:, 0, 3]), 1.0, atol=1e-7)
    assert clip.foot_contacts.all()
    # Not frozen: the pelvis sways from side to side.
    hips = clip.translations[:, 1].astype(np.float64)
    assert np.ptp(hips[:, 0]) > 0.02
    other = walker.idle(120, FPS, phase=0.5)
    assert np.abs(other.translations[:, 1, 0] - clip.translations[:, 1, 0]).max() > 0.01


def test_walk_idle_walk_stands_still_in_the_returned_range():
    clip, (first, last) = walker.walk_idle_walk(240, FPS, stop_frame=80, idle_frames=40)
    assert (first, last) == (80, 119)
    root = clip.translations[:, 0].astype(np.float64)
    np.testing.assert_array_equal(root[first:last + 1], np.broadcast_to(root[first], (40, 3)))
    assert np.linalg.norm(root[first - 1] - root[first]) > 1e-5
    assert np.linalg.norm(root[last + 1] - root[last]) > 1e-5
    # Both feet flat on the ground, side by side, while standing.
    assert clip.foot_contacts[first:last + 1].all()
    feet = _foot_positions_m(clip)[first]
    np.testing.assert_allclose(feet[0, 2], feet[2, 2], atol=1e-6)
    np.testing.assert_allclose(feet[0, 0] - feet[2, 0], 0.2, atol=1e-6)
    # It walks at full speed away from the stop.
    speed = np.linalg.norm(np.diff(root, axis=0), axis=-1) * FPS
    np.testing.assert_allclose(speed[:10], 1.4, rtol=1e-4)
    np.testing.assert_allclose(speed[-10:], 1.4, rtol=1e-4)
    assert walker.walk_idle_walk(240, FPS)[1] == (80, 127)


def test_turn_follows_a_circle_facing_along_it():
    rate, speed, frames = 30.0, 1.2, 120
    clip = walker.turn(frames, FPS, speed=speed, turn_rate=rate)
    root = clip.translations[:, 0].astype(np.float64)
    radius = speed / np.radians(rate)
    center = np.array([radius, 0.0, 0.0])   # turning left, towards +X
    np.testing.assert_allclose(np.linalg.norm(root - center, axis=-1), radius, rtol=1e-5)
    q = clip.rotations[:, 0].astype(np.float64)
    yaw = 2 * np.arctan2(q[:, 1], q[:, 3])
    expected = np.radians(rate) * np.arange(frames) / FPS
    np.testing.assert_allclose(np.unwrap(yaw), expected, atol=1e-5)
    travel = np.diff(root, axis=0)
    heading = np.arctan2(travel[:, 0], travel[:, 2])
    np.testing.assert_allclose(heading, 0.5 * (expected[1:] + expected[:-1]), atol=1e-3)


@pytest.mark.parametrize("make", [walker.walk, walker.run, walker.idle])
def test_zup_centimetres_is_the_same_motion(make):
    y = make(60, FPS)
    z = make(60, FPS, up="Z", meters_per_unit=0.01)
    to_z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    py = walker.joint_world_positions(y)
    pz = walker.joint_world_positions(z)
    np.testing.assert_allclose(pz * 0.01, py @ to_z.T, atol=2e-6)
    np.testing.assert_allclose(z.rest_translations * 0.01, y.rest_translations, atol=1e-7)
    np.testing.assert_array_equal(z.rotations[:, 1:], y.rotations[:, 1:])
    np.testing.assert_array_equal(z.foot_contacts, y.foot_contacts)
    # Z-up: the root stays on the z = 0 ground plane and walks along -Y.
    np.testing.assert_allclose(z.translations[:, 0, 2], 0.0, atol=1e-3)
    assert (z.up_axis, z.meters_per_unit) == ("Z", 0.01)


def test_rest_pose_and_forward_kinematics_agree():
    clip = walker.walk(5)
    rest_world = walker.rest_world_transforms(clip)
    ankle = clip.joint_index("LeftFoot")
    np.testing.assert_allclose(rest_world[ankle, :3, 3], [0.09, 0.08, 0.0], atol=1e-6)
    frozen = walker.Clip(
        name="rest", joints=clip.joints, parents=clip.parents,
        rest_translations=clip.rest_translations, rest_rotations=clip.rest_rotations,
        translations=np.repeat(clip.rest_translations[None], 3, 0),
        rotations=np.repeat(clip.rest_rotations[None], 3, 0), fps=clip.fps)
    np.testing.assert_allclose(walker.world_transforms(frozen),
                               np.repeat(rest_world[None], 3, 0), atol=1e-7)
    # One hand-checked chain: a 90 degree turn of the root about Y carries the
    # left ankle from +X to -Z.
    turned = walker.Clip(**{**frozen.__dict__, "rotations": frozen.rotations.copy()})
    turned.rotations[:, 0] = [0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)]
    np.testing.assert_allclose(walker.world_transforms(turned)[0, ankle, :3, 3],
                               [0.0, 0.08, -0.09], atol=1e-6)


def test_quaternion_matrix_round_trip():
    rng = np.random.default_rng(7)
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    # Half-turns about each axis are the cases that break naive conversions.
    q[:3] = np.eye(4)[:3]
    back = walker.quat_from_matrix(walker.quat_to_matrix(q))
    same = np.minimum(np.abs(back - q).max(-1), np.abs(back + q).max(-1))
    assert same.max() < 1e-12
    assert np.all(back[:, 3] >= 0)
    m = walker.quat_to_matrix(q)
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(3), m.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-12)


def test_generators_are_deterministic_and_phase_shifts_the_gait():
    a, b = walker.walk(48, phase=0.3), walker.walk(48, phase=0.3)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.translations, b.translations)
    c = walker.walk(48, phase=0.55)
    assert not np.array_equal(a.foot_contacts, c.foot_contacts)
    np.testing.assert_allclose(c.translations[:, 0], a.translations[:, 0], atol=1e-6)
