"""Layering real motion capture: a stationary upper-body clip (CMU 02_05, punch and strike)
added over a walk (CMU 02_01), both on the 100-joint CC rig, read from ../shared/mocap
through the BVH importer and solved end to end."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel

from mocapedit.usd import bvh_usd
from mocapedit.solve import layering
from mocapedit.pipeline.processor import solve

from conftest import SHARED_MOCAP, world_joints

WALK = SHARED_MOCAP / "cc_cmu02_01_walk.bvh"
PUNCH = SHARED_MOCAP / "cc_cmu02_05_punch_strike.bvh"

pytestmark = [pytest.mark.realdata,
              pytest.mark.skipif(not (WALK.exists() and PUNCH.exists()), reason="../shared/mocap is absent")]


def _angle(a, b):
    """Rotation angle (radians) between (...,4) quaternions, whatever their signs."""
    d = np.abs(np.sum(np.asarray(a, np.float64) * b, -1))
    return 2 * np.arccos(np.clip(d, 0, 1))


def _local_rotations(stage, agent, times):
    """(T,J,4) joint-local rotations (x, y, z, w) of an agent's animation, and its joints."""
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetPrimAtPath(agent)), Usd.PrimDefaultPredicate)
    anim = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath(agent + "/Skel"))).GetAnimQuery()
    rot = [[[*q.GetImaginary(), q.GetReal()] for q in anim.ComputeJointLocalTransformComponents(Usd.TimeCode(t))[1]]
           for t in times]
    return np.array(rot, dtype=np.float64), [str(j) for j in anim.GetJointOrder()]


def test_a_stationary_upper_body_clip_added_over_a_walk_stays_sound(tmp_path):
    walk = bvh_usd.import_bvh(str(WALK), str(tmp_path / "walk.usda"), bvh_usd.ImportSettings(agent=True))
    bvh_usd.import_bvh(str(PUNCH), str(tmp_path / "punch.usda"))
    stage = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(walk.fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(walk.frames - 1)
    stage.DefinePrim("/World/walker").GetReferences().AddReference("./walk.usda")
    stage.DefinePrim("/Layers/Punch").GetReferences().AddReference("./punch.usda", "/Skel/Anim")
    weight = {20.0: 0.0, 60.0: 1.0, 120.0: 1.0, 160.0: 0.0}
    layer = stage.DefinePrim("/Layers/Strike", "MocapAnimationLayer")
    layer.CreateRelationship("agents").SetTargets([Sdf.Path("/World/walker")])
    layer.CreateRelationship("animation").SetTargets([Sdf.Path("/Layers/Punch")])
    layer.GetAttribute("joint").Set("CC_Base_Waist")  # a bare name: the two rigs root differently
    layer.GetAttribute("wrap").Set("clamp")
    for t, w in weight.items():
        layer.GetAttribute("weight").Set(w, t)
    stage.GetRootLayer().Save()

    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usdc"), composed=str(tmp_path / "c.usda"))
    assert result.report.stats["layeredAgents"] == 1
    out = Usd.Stage.Open(str(tmp_path / "c.usda"))
    times = np.arange(walk.frames, dtype=np.float64)
    rot, joints = _local_rotations(out, "/World/walker", times)
    source, _ = _local_rotations(Usd.Stage.Open(str(tmp_path / "shot.usda")), "/World/walker", times)
    world = world_joints(out, "/World/walker/Skel", times)

    # Finite and normalised.
    assert np.all(np.isfinite(rot)) and np.all(np.isfinite(world))
    np.testing.assert_allclose(np.linalg.norm(rot, axis=-1), 1.0, atol=2e-6)

    # The waist's subtree changed where the weight is up; the legs did not change at all.
    sub = np.array(["CC_Base_Waist" in j.split("/") for j in joints])
    assert 30 < sub.sum() < len(joints) - 20
    assert _angle(rot[90][sub], source[90][sub]).max() > 0.3
    np.testing.assert_array_equal(rot[:, ~sub], source[:, ~sub])
    np.testing.assert_array_equal(rot[:20], source[:20])

    # No flips: a frame-to-frame step of a layered joint is at most the source's step plus the
    # step of the weighted delta (triangle inequality in the rotation group), which moves by
    # the delta's own step and by the change of weight times the delta's angle.
    punch = result.data.clips[result.data.layers[0].clip_key]
    punch_of = {j.rsplit("/", 1)[-1]: k for k, j in enumerate(punch.joints)}
    cols = [punch_of[j.rsplit("/", 1)[-1]] for j in np.array(joints)[sub]]
    p = punch.rotations[:walk.frames, cols].astype(np.float64)
    delta = layering.quat_multiply(p, p[0] * [-1, -1, -1, 1])
    w = np.interp(times, sorted(weight), [weight[k] for k in sorted(weight)])[:, None]
    bound = (_angle(source[1:, sub], source[:-1, sub]) + _angle(delta[1:], delta[:-1])
             + np.abs(np.diff(w, axis=0)) * _angle(delta[1:], [0, 0, 0, 1]) + 1e-3)
    step = _angle(rot[1:, sub], rot[:-1, sub])
    assert np.all(step <= bound), f"largest excess {np.max(step - bound):.3g} rad"
    assert step.max() < np.radians(45)
