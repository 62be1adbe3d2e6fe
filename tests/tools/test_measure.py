"""Tests for mocapedit.tools.measure: foot skate and plausibility measured on stages by UsdSkel FK."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel

from mocapedit.inspect import metrics as M
from mocapedit.tools import measure

from skel_stages import build_agent, define_animation, define_skeleton, foot, new_stage, walk


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_foot_skate_planted_feet_is_zero(tmp_path, up):
    n = 20
    stage = new_stage(tmp_path, f"planted_{up}.usda", up=up, tcps=24.0)
    # Left foot planted for 10 frames, then swings forward fast in the air; right foot planted.
    u = np.where(np.arange(n) < 10, 0.2, 0.2 + 0.4 * (np.arange(n) - 9))
    h = np.where(np.arange(n) < 10, 0.0, 0.5)
    # Each foot has its own lowest height: the right one stays on a 0.3 high step.
    left, right = foot(n, u, 0.1, h), foot(n, 0.5, -0.1, 0.3)
    build_agent(stage, "/Agent", walk(n, up, left, right, root_speed=0.05))
    skate = measure.foot_skate(stage, "/Agent")
    assert skate.joints == ("Root/Hips/LeftFoot", "Root/Hips/RightFoot")
    np.testing.assert_allclose(skate.speeds, [0.0, 0.0], atol=1e-4)
    assert skate.mean == pytest.approx(0.0, abs=1e-4)
    np.testing.assert_array_equal(skate.contact[:, 0], np.arange(n) < 10)
    assert skate.contact[:, 1].all()
    np.testing.assert_allclose(skate.contact_seconds, [9 / 24.0, 19 / 24.0], rtol=1e-12)


@pytest.mark.parametrize("up,tcps", [("Y", 30.0), ("Z", 24.0)])
def test_foot_skate_sliding_foot_known_speed(tmp_path, up, tcps):
    n, v = 24, 0.3  # slides at v units per second during contact
    stage = new_stage(tmp_path, f"slide_{up}.usda", up=up, tcps=tcps)
    k = np.arange(n)
    contact = k < 12
    # Slides along ground v (so Y-up exercises the -z mapping), then flies off fast.
    gv = np.where(contact, v * k / tcps, v * 11 / tcps + 5.0 * (k - 11) / tcps)
    left = foot(n, 0.1, gv, np.where(contact, 0.0, 0.4))
    right = foot(n, -0.1, 0.0, 0.0)
    root, _ = build_agent(stage, "/Agent", walk(n, up, left, right))
    # The agent stands on a floor 2 units up: contact is measured from the feet's lowest point.
    UsdGeom.XformCommonAPI(root).SetTranslate(Gf.Vec3d(*M.from_ground([3.0, -1.0], 2.0, up)))
    skate = measure.foot_skate(stage, "/Agent/Skel")
    np.testing.assert_allclose(skate.speeds, [v, 0.0], atol=1e-4)
    assert skate.mean == pytest.approx(v * 11 / (11 + 23), abs=1e-4)
    only_left = measure.foot_skate(stage, "/Agent", foot_joints=["LeftFoot"])
    assert only_left.mean == pytest.approx(v, abs=1e-4)


def test_foot_skate_counts_a_cut_for_nothing(tmp_path):
    """A take whose first frame is its rest pose 3 m away: the jump from it is a cut (faster than
    anyone moves), not a slide of feet that are on the ground either side of it."""
    n, v, tcps = 24, 0.3, 24.0
    stage = new_stage(tmp_path, "cut.usda", up="Y", tcps=tcps)
    k = np.arange(n)
    left = foot(n, 0.1, np.where(k == 0, -3.0, v * k / tcps), 0.0)
    right = foot(n, -0.1, np.where(k == 0, -3.0, 0.0), 0.0)
    build_agent(stage, "/Agent", walk(n, "Y", left, right))
    skate = measure.foot_skate(stage, "/Agent")
    # The feet on the ground from frame 0 on: the steps after the cut count, as fast as they
    # slide (the 3 m step counted made the left foot slide at 3.4 units/s, the right at 3.1).
    np.testing.assert_allclose(skate.speeds, [v, 0.0], atol=1e-4)


def test_foot_skate_meters_per_unit_scales_default_threshold(tmp_path):
    # Centimetre stage: the foot bobs 0..1.5 cm while sliding at 30 cm/s, then lifts to 8 cm and
    # moves at 100 cm/s. The default 2 cm threshold must become 2 units.
    n, tcps = 20, 25.0
    stage = new_stage(tmp_path, "cm.usda", up="Y", tcps=tcps, mpu=0.01)
    k = np.arange(n)
    contact = k < 10
    h = np.where(contact, np.where(k % 2 == 0, 0.0, 1.5), 8.0)
    gu = np.where(contact, 30.0 * k / tcps, 30.0 * 9 / tcps + 100.0 * (k - 9) / tcps)
    left = foot(n, gu, 10.0, h)
    right = foot(n, 0.0, -10.0, 0.0)
    build_agent(stage, "/Agent", walk(n, "Y", left, right, hip_height=100.0))
    skate = measure.foot_skate(stage, "/Agent")
    np.testing.assert_allclose(skate.speeds, [30.0, 0.0], atol=1e-3)
    np.testing.assert_array_equal(skate.contact[:, 0], contact)
    # An explicit threshold overrides the default: 1 unit keeps only the frames on the floor.
    strict = measure.foot_skate(stage, "/Agent", contact_height=1.0)
    assert math.isnan(strict.speeds[0])
    assert strict.mean == pytest.approx(0.0, abs=1e-3)
    # A contact mask from elsewhere (the source stage) replaces the height test.
    mask = np.zeros_like(skate.contact)
    mask[12:, 0] = True
    given = measure.foot_skate(stage, "/Agent", contact=mask)
    assert given.speeds[0] == pytest.approx(100.0, abs=1e-3)
    with pytest.raises(ValueError, match="contact mask"):
        measure.foot_skate(stage, "/Agent", contact=mask[1:])


def test_foot_skate_ignores_times_outside_the_clip(tmp_path):
    # The clip (frames 0..9) plants both feet; after it the animation holds while the SkelRoot's
    # own transform keeps moving: that is not a foot in contact within the clip.
    n = 10
    stage = new_stage(tmp_path, "outside.usda", up="Y")
    feet = foot(n, 0.0, 0.1, 0.0)
    root, _ = build_agent(stage, "/Agent", walk(n, "Y", feet, foot(n, 0.3, 0.0, 0.0)))
    op = UsdGeom.Xformable(root).AddTranslateOp()
    for t in range(n, n + 6):
        op.Set(Gf.Vec3d(0.5 * (t - n + 1), 0.0, 0.0), float(t))
    op.Set(Gf.Vec3d(0.0, 0.0, 0.0), float(n - 1))
    skate = measure.foot_skate(stage, "/Agent", times=range(n + 6))
    assert not skate.contact[n:].any()
    np.testing.assert_allclose(skate.speeds, [0.0, 0.0], atol=1e-4)


def test_foot_skate_composed_times_with_layer_offset_and_bound_skeleton(tmp_path):
    n, tcps, v = 16, 24.0, 0.25
    clip = Usd.Stage.CreateNew(str(tmp_path / "clip.usda"))
    k = np.arange(n)
    left = foot(n, v * k / tcps, 0.0, 0.0)
    world = walk(n, "Y", left, foot(n, 0.0, 0.3, 0.0))
    define_animation(clip, "/Anim", world)
    clip.SetDefaultPrim(clip.GetPrimAtPath("/Anim"))
    clip.Save()

    stage = new_stage(tmp_path, "shot.usda", up="Y", tcps=tcps)
    root = UsdSkel.Root.Define(stage, "/Agent")
    anim = stage.DefinePrim("/Agent/Anim")
    anim.GetReferences().AddReference(
        Sdf.Reference("./clip.usda", layerOffset=Sdf.LayerOffset(100.0)))
    skel = define_skeleton(stage, "/Agent/Skel", anim.GetPath())
    # A second, unused skeleton: the agent's own binding picks the right one.
    other = define_skeleton(stage, "/Agent/Other", anim.GetPath())
    other.CreateJointsAttr(["A"])
    with pytest.raises(ValueError, match="several skeletons"):
        measure.foot_skate(stage, "/Agent")
    UsdSkel.BindingAPI.Apply(root.GetPrim()).CreateSkeletonRel().SetTargets([skel.GetPath()])
    skate = measure.foot_skate(stage, "/Agent")
    np.testing.assert_allclose(skate.times, 100.0 + k)
    np.testing.assert_allclose(skate.speeds, [v, 0.0], atol=1e-4)


@pytest.fixture(scope="module")
def walker_stage(tmp_path_factory):
    from mocapedit.data import examples, walker
    tmp = tmp_path_factory.mktemp("plausible")
    clip = walker.walk(frames=96, fps=24.0, speed=1.3, name="straight")
    stage = examples.build_crowd_stage(tmp / "shot.usda", [examples.AgentSpec("a", clip)], fps=24.0,
                                       clips_dir=tmp / "clips")
    stage.GetRootLayer().Save()
    return stage.GetRootLayer().realPath


def _turned(path, yaw_of_time):
    """The stage at ``path`` with agent a turned about its origin by yaw_of_time(t) degrees."""
    stage = Usd.Stage.Open(path)
    stage.SetEditTarget(stage.GetSessionLayer())
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Crowd/a")).AddRotateYOp(opSuffix="edit")
    for t in range(96):
        op.Set(float(yaw_of_time(t)), float(t))
    return stage


def test_plausibility_of_an_unedited_agent(walker_stage):
    src = Usd.Stage.Open(walker_stage)
    p = measure.plausibility(src, _turned(walker_stage, lambda t: 0.0), "/World/Crowd/a")
    assert abs(p.max_extra_facing_rate) < 1e-6 and p.spin_frames == 0 and not p.spins
    assert p.max_direction_deviation < 1e-6 and not p.reverses
    assert math.isclose(p.length_ratio, 1.0, rel_tol=1e-9)
    assert p.time_warp == pytest.approx((1.0, 1.0))
    assert math.isclose(p.foot_skate_ratio, 1.0, rel_tol=1e-6)
    assert p.source_max_facing_rate < M.spin_threshold()


def test_plausibility_catches_a_spin_and_a_reversal(walker_stage):
    src = Usd.Stage.Open(walker_stage)
    # One frame turns the body by 100 degrees (2,400 degrees per second at 24 fps): a spin, and the
    # walk after it (turned about the start) goes off by 100 degrees.
    p = measure.plausibility(src, _turned(walker_stage, lambda t: 100.0 if t >= 50 else 0.0), "/World/Crowd/a")
    assert p.spin_frames == 1 and p.spins
    assert p.max_extra_facing_rate == pytest.approx(100.0 * 24.0, rel=0.05)
    assert p.reverses and 95.0 < p.max_direction_deviation <= 180.0
    # A constant turn of the whole agent is no spin, and its direction is off by that turn.
    q = measure.plausibility(src, _turned(walker_stage, lambda t: 30.0), "/World/Crowd/a")
    assert q.spin_frames == 0 and abs(q.max_extra_facing_rate) < 1e-3
    assert q.max_direction_deviation == pytest.approx(30.0, abs=1e-3)
    assert q.length_ratio == pytest.approx(1.0, abs=1e-6)
    worst = M.worst_plausibility([p, q])
    assert worst["spinningAgents"] == 1 and worst["reversingAgents"] == 1
    assert worst["maxExtraTurnPerFrameAt60fps"] == pytest.approx(p.max_extra_facing_rate / 60.0)
    assert M.worst_plausibility([]) == {"agents": 0}
