"""The BVH parser and converter on files the tests write (no USD here)."""
from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapedit.formats import bvh
from mocapedit.geometry import kinematics
from mocapedit.model.errors import MocapEditError

from bvhgen import Rig, random_motion, random_rig, write_bvh


def _fk(pose, translations, rotations):
    return kinematics.skel_space(kinematics.compose_trs(translations, rotations), pose.parents)[..., 3, :3]


def _one_joint(channels, values, offset=(0.0, 0.0, 0.0)):
    return Rig(names=["root"], parents=[-1], offsets=np.array([offset]), channels=[channels],
               end_sites={0: np.array([0.0, 1.0, 0.0])}), np.atleast_2d(values)


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_each_euler_order_is_an_intrinsic_rotation_in_the_listed_order(tmp_path, order):
    rng = np.random.default_rng(1)
    angles = rng.uniform(-300, 300, (20, 3))
    rig, values = _one_joint([f"{a}rotation" for a in order], angles)
    write_bvh(tmp_path / "r.bvh", rig, values)
    motion = bvh.load(tmp_path / "r.bvh")
    np.testing.assert_allclose(motion.values, angles, atol=1e-6)
    pose, _, q = bvh.convert(motion)
    # scipy: upper-case axes are intrinsic rotations, applied in the order given.
    expect = Rotation.from_euler(order, motion.values, degrees=True).as_matrix()  # column vectors
    got = np.swapaxes(kinematics.quat_to_matrix3(q[:, 0]), -1, -2)            # row -> column convention
    np.testing.assert_allclose(got, expect, atol=1e-9)


def test_channel_order_within_a_joint_does_not_matter_only_the_rotation_order(tmp_path):
    rng = np.random.default_rng(2)
    pos, rot = rng.uniform(-50, 50, (10, 3)), rng.uniform(-180, 180, (10, 3))
    results = []
    for labels in (["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"],
                   ["Zrotation", "Xposition", "Xrotation", "Zposition", "Yrotation", "Yposition"],
                   ["Zrotation", "Xrotation", "Yrotation", "Yposition", "Zposition", "Xposition"]):
        cols = {"Xposition": pos[:, 0], "Yposition": pos[:, 1], "Zposition": pos[:, 2],
                "Zrotation": rot[:, 0], "Xrotation": rot[:, 1], "Yrotation": rot[:, 2]}
        rig, values = _one_joint(labels, np.stack([cols[c] for c in labels], 1))
        write_bvh(tmp_path / "c.bvh", rig, values)
        _, t, q = bvh.convert(bvh.load(tmp_path / "c.bvh"), position_mode="absolute")
        results.append((t, q))
    for t, q in results[1:]:
        np.testing.assert_allclose(t, results[0][0], atol=1e-12)
        np.testing.assert_allclose(q, results[0][1], atol=1e-12)
    np.testing.assert_allclose(results[0][0][:, 0], pos, atol=1e-5)


def test_a_root_spinning_past_360_degrees_gives_continuous_quaternions(tmp_path):
    frames = 400
    spin = np.linspace(0, 1500, frames)                 # four turns and more
    wobble = 20 * np.sin(np.linspace(0, 9, frames))
    rig, values = _one_joint(["Zrotation", "Yrotation", "Xrotation"], np.stack([wobble, spin, -wobble], 1))
    # Written wrapped to [-180, 180), as many exporters do: the Euler values jump by 360.
    values = (values + 180.0) % 360.0 - 180.0
    write_bvh(tmp_path / "spin.bvh", rig, values)
    motion = bvh.load(tmp_path / "spin.bvh")
    assert np.abs(np.diff(motion.values[:, 1])).max() > 300, "the file must hold wrapped angles"
    _, _, q = bvh.convert(motion)
    dots = np.sum(q[1:, 0] * q[:-1, 0], axis=-1)
    assert dots.min() > 0.99, "neighbouring frames must sit in the same quaternion hemisphere"
    expect = Rotation.from_euler("ZYX", motion.values, degrees=True).as_matrix()
    got = np.swapaxes(kinematics.quat_to_matrix3(q[:, 0]), -1, -2)
    np.testing.assert_allclose(got, expect, atol=1e-9)


def test_streaming_in_small_chunks_gives_the_same_clip(tmp_path):
    rng = np.random.default_rng(3)
    rig = random_rig(rng, 12)
    values = random_motion(rng, rig, 157, spin_joints=(0, 3))
    write_bvh(tmp_path / "s.bvh", rig, values)
    skeleton = bvh.read_header(tmp_path / "s.bvh")
    whole = bvh.Converter(skeleton, scale=2.0, up_axis="Z")
    t_all, q_all = whole(bvh.load(tmp_path / "s.bvh").values)
    chunked = bvh.Converter(skeleton, scale=2.0, up_axis="Z")
    parts = [chunked(v) for v in bvh.iter_frames(tmp_path / "s.bvh", chunk_frames=10)]
    assert len(parts) == 16
    np.testing.assert_array_equal(np.concatenate([p[0] for p in parts]), t_all)
    np.testing.assert_array_equal(np.concatenate([p[1] for p in parts]), q_all)


def test_scale_and_z_up_turn_the_world_about_x_at_the_roots(tmp_path):
    rng = np.random.default_rng(4)
    rig = random_rig(rng, 9)
    values = random_motion(rng, rig, 30)
    write_bvh(tmp_path / "u.bvh", rig, values)
    motion = bvh.load(tmp_path / "u.bvh")
    pose_y, t_y, q_y = bvh.convert(motion, position_mode="absolute")
    pose_z, t_z, q_z = bvh.convert(motion, scale=0.5, up_axis="Z", position_mode="absolute")
    y_up, z_up = _fk(pose_y, t_y, q_y), _fk(pose_z, t_z, q_z)
    # (x, y, z) Y-up is (x, -z, y) Z-up.
    np.testing.assert_allclose(z_up, 0.5 * np.stack([y_up[..., 0], -y_up[..., 2], y_up[..., 1]], -1), atol=1e-9)
    # The bind pose is the rest pose in skeleton space.
    np.testing.assert_allclose(pose_z.bind_transforms[:, 3, :3],
                               _fk(pose_z, pose_z.rest_translations[None], pose_z.rest_rotations[None])[0],
                               atol=1e-12)


def test_blocks_written_on_one_line(tmp_path):
    """End Sites and short joints written compactly, '{ OFFSET 0 1 0 }' or 'End Site { OFFSET 0 1 0 }'
    (it said "OFFSET needs 3 values, found 4" over the closing brace)."""
    compact = """    End Site
    { OFFSET 0 -10 0 }
  }
  JOINT Arm
  {
    OFFSET 5 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation }
  JOINT Head
  {
    OFFSET 0 10 0 CHANNELS 3 Zrotation Xrotation Yrotation
    End Site { OFFSET 0 2 0 } }
}
"""
    # GOOD's hierarchy down to the Leg's CHANNELS, then the compact blocks.
    text = "\n".join(_lines()[:9]) + "\n" + compact + "MOTION\nFrames: 1\nFrame Time: 0.0333333\n" + \
        " ".join(["0"] * 15) + "\n"
    (tmp_path / "c.bvh").write_text(text)
    sk = bvh.load(tmp_path / "c.bvh").skeleton
    assert sk.names == ["Hips", "Leg", "Arm", "Head"] and list(sk.parents) == [-1, 0, 0, 0]
    assert [p for p, _ in sk.end_sites] == [1, 3]
    np.testing.assert_allclose([o for _, o in sk.end_sites], [[0, -10, 0], [0, 2, 0]])
    np.testing.assert_allclose(sk.offsets[2], [5, 0, 0])


def test_syntax_variants_end_sites_windows_lines_and_frame_time_without_zero(tmp_path):
    rng = np.random.default_rng(5)
    rig = random_rig(rng, 6, names=["Hips", "Left Up Leg", "1st joint", "Left Up Leg", "spine.001", "ÄÖÜ"])
    values = random_motion(rng, rig, 12)
    write_bvh(tmp_path / "w.bvh", rig, values, frame_time=".0083333", newline="\r\n", indent="  ")
    motion = bvh.load(tmp_path / "w.bvh")
    sk = motion.skeleton
    assert sk.names == rig.names
    assert sk.frame_count == 12 and sk.frame_time == pytest.approx(0.0083333) and sk.fps == 120.0
    assert len(sk.end_sites) == len(rig.end_sites)
    np.testing.assert_allclose(motion.values, values, atol=1e-6)
    tokens = bvh.joint_tokens(sk.names)
    assert len(set(tokens)) == len(tokens)
    assert all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", t) for t in tokens)
    assert tokens[:4] == ["Hips", "Left_Up_Leg", "_1st_joint", "Left_Up_Leg_2"]
    pose, t, q = bvh.convert(motion, end_sites=True)
    assert len(pose.joints) == 6 + len(rig.end_sites)
    assert all(p.count("/") == pose.joints[i].count("/") for i, p in enumerate(pose.joints))
    assert sk.find("Left Up Leg") == 1 and sk.find("_1st_joint") == 2 and sk.find("nope") is None
    # An end site follows its parent at its offset.
    leaf = next(iter(rig.end_sites))
    world = _fk(pose, t, q)
    parent_world = kinematics.skel_space(kinematics.compose_trs(t, q), pose.parents)[:, leaf]
    end = len(rig.names) + sorted(rig.end_sites).index(leaf)
    offset = dict(sk.end_sites)[leaf]
    np.testing.assert_allclose(offset, rig.end_sites[leaf], atol=1e-6)
    np.testing.assert_allclose(world[:, end], (np.append(offset, 1.0) @ parent_world)[:, :3], atol=1e-9)


def test_old_mac_line_endings_and_several_roots(tmp_path):
    text = ("HIERARCHY\rROOT a\r{\r OFFSET 0 0 0\r CHANNELS 3 Zrotation Xrotation Yrotation\r}\r"
            "ROOT b {\r OFFSET 1 0 0\r CHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation Zrotation\r"
            " JOINT c\r {\r  OFFSET 0 1 0\r  CHANNELS 0\r  End Site\r  {\r   OFFSET 0 1 0\r  }\r }\r}\r"
            "MOTION\rFrames: 2\rFrame Time: 0.5\r1 2 3 4 5 6 7 8 9\r\r9 8 7 6 5 4 3 2 1\r")
    (tmp_path / "m.bvh").write_text(text, newline="")
    motion = bvh.load(tmp_path / "m.bvh")
    assert motion.skeleton.names == ["a", "b", "c"]
    assert motion.skeleton.parents.tolist() == [-1, -1, 1]
    assert motion.values.shape == (2, 9) and motion.skeleton.fps == 2.0


def test_position_modes_read_a_hip_rooted_rig_relative_to_its_offset(tmp_path):
    labels = ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
    frames = 50
    walk = np.stack([np.linspace(0, 400, frames), 3 * np.sin(np.arange(frames)), np.zeros(frames)], 1)
    rig, values = _one_joint(labels, np.hstack([walk, np.zeros((frames, 3))]), offset=(0, 105.0, 0))
    write_bvh(tmp_path / "rel.bvh", rig, values)
    motion = bvh.load(tmp_path / "rel.bvh")
    assert bvh.position_modes(motion.skeleton, motion.values) == ["relative"]
    _, t, _ = bvh.convert(motion)
    np.testing.assert_allclose(t[:, 0, 1], 105.0 + walk[:, 1], atol=1e-5)
    # The same walk written with absolute heights reads absolute.
    absolute = values.copy()
    absolute[:, 1] += 105.0
    write_bvh(tmp_path / "abs.bvh", rig, absolute)
    motion = bvh.load(tmp_path / "abs.bvh")
    assert bvh.position_modes(motion.skeleton, motion.values) == ["absolute"]
    _, t2, _ = bvh.convert(motion)
    np.testing.assert_allclose(t2, t, atol=1e-5)


@pytest.mark.parametrize("written", ["absolute", "relative"])
def test_a_clip_that_falls_and_lies_reads_its_hips_where_its_body_touches_the_ground(tmp_path, written):
    """A humanoid standing for a quarter of a second, then lying for the rest, its hips 10 cm up:
    most of its frames are low, so the median of its Yposition (10) lay nearer zero than its
    OFFSET (95) and an absolute file read relative, standing a metre above the floor. Read so
    that its body reaches the ground, either way the file is written."""
    from bvhgen import _humanoid
    rig = _humanoid()
    frames = 60
    values = np.zeros((frames, sum(len(c) for c in rig.channels)))
    lying = np.arange(frames) >= 15
    values[:, 1] = np.where(lying, 10.0, 95.0) - (95.0 if written == "relative" else 0.0)
    values[:, 4] = np.where(lying, -90.0, 0.0)          # Hips Xrotation: lie on the back
    write_bvh(tmp_path / "fall.bvh", rig, values)
    motion = bvh.load(tmp_path / "fall.bvh")
    assert bvh.position_modes(motion.skeleton, motion.values)[0] == written
    pose, t, r = bvh.convert(motion)
    heights = kinematics.skel_space(kinematics.compose_trs(t, r), pose.parents)[..., 3, 1]
    assert abs(heights.min()) < 6.0 and abs(heights[0].min()) < 6.0
    np.testing.assert_allclose(t[:, 0, 1], np.where(lying, 10.0, 95.0), atol=1e-6)


GOOD = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Leg
  {
    OFFSET 0 -10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: .0333333
0 90 0 0 0 0 10 20 30
1 90 0 5 5 5 11 21 31
"""


def _lines():
    return GOOD.splitlines()


def _edit(line_no, new):
    lines = _lines()
    lines[line_no - 1] = new
    return "\n".join(lines) + "\n"


MALFORMED = {
    "truncated in hierarchy": ("\n".join(_lines()[:9]) + "\n", 10, "truncated"),
    "truncated frames": ("\n".join(_lines()[:19]) + "\n", 20, "truncated"),
    "wrong channel count": (_edit(5, "  CHANNELS 5 Xposition Yposition Zposition Zrotation Xrotation Yrotation"), 5,
                            "declares 5 channels but lists 6"),
    "row with too few values": (_edit(19, "0 90 0 0 0 0 10 20"), 19, "too few values"),
    "row with too many values": (_edit(20, "1 90 0 5 5 5 11 21 31 4"), 20, "too many values"),
    "NaN": (_edit(20, "1 90 0 5 nan 5 11 21 31"), 20, "not a finite number"),
    "infinity": (_edit(19, "0 90 0 0 0 0 10 inf 30"), 19, "not a finite number"),
    "a word in a row": (_edit(19, "0 90 0 zero 0 0 10 20 30"), 19, "'zero' is not a number"),
    "unknown keyword": (_edit(8, "    OFFSET 0 -10 0\n    SCALE 1 1 1"), 9, "unknown keyword 'SCALE'"),
    "unknown channel": (_edit(9, "    CHANNELS 3 Zrotation Xrotation Wrotation"), 9, "unknown channel"),
    "repeated channel": (_edit(9, "    CHANNELS 3 Zrotation Xrotation Zrotation"), 9, "listed twice"),
    "seven channels": (_edit(9, "    CHANNELS 7 Zrotation Xrotation Yrotation Xposition Yposition Zposition "
                               "Zposition"), 9, "at most 6"),
    "offset with two values": (_edit(8, "    OFFSET 0 -10"), 8, "OFFSET needs 3 values"),
    "NaN offset": (_edit(8, "    OFFSET 0 nan 0"), 8, "not a finite number"),
    "missing brace": (_edit(14, ""), 16, "MOTION inside an open block"),
    "extra rows": (GOOD + "2 90 0 5 5 5 11 21 31\n", 21, "more frame rows"),
    "bad frame count": (_edit(17, "Frames: two"), 17, "frame count 'two'"),
    "zero frame time": (_edit(18, "Frame Time: 0"), 18, "positive"),
    "no HIERARCHY": (GOOD.replace("HIERARCHY", "HIERARCHIES"), 1, "expected HIERARCHY"),
    "JOINT without braces": (_edit(7, "    OFFSET 0 -10 0"), 7, "expected '{'"),
    "empty file": ("", None, "empty file"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_files_name_the_file_and_line(tmp_path, case):
    text, line, words = MALFORMED[case]
    path = tmp_path / "broken.bvh"
    path.write_text(text)
    with pytest.raises(MocapEditError) as info:
        bvh.load(path)
    message = str(info.value)
    where = f"{path}:{line}:" if line is not None else f"{path}:"
    assert message.startswith(where), message
    assert words in message, message


def test_the_good_file_behind_the_malformed_ones_parses(tmp_path):
    (tmp_path / "good.bvh").write_text(GOOD)
    motion = bvh.load(tmp_path / "good.bvh")
    assert motion.values.shape == (2, 9) and motion.skeleton.fps == 30.0
