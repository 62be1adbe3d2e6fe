"""Tests for mocapedit.usd.evaluate: UsdSkel forward kinematics on composed stages."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdSkel

from mocapedit.tools import measure
from mocapedit.usd import evaluate

from skel_stages import JOINTS, build_agent, define_animation, define_skeleton, foot, new_stage, walk


def test_joint_world_positions_forward_kinematics(tmp_path):
    stage = new_stage(tmp_path, "fk.usda", up="Y")
    root = UsdSkel.Root.Define(stage, "/Agent")
    UsdGeom.XformCommonAPI(root).SetTranslate(Gf.Vec3d(10.0, 0.0, 5.0))
    q90 = Gf.Quatf(math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0)  # +90 deg about Y
    frames = []
    for k in range(3):
        local = np.array([[k, 0, 0], [1, 1, 0], [0, -1, 0.2], [0, -1, -0.2]], dtype=float)
        frames.append({"local": local, "quats": [q90, Gf.Quatf(1), Gf.Quatf(1), Gf.Quatf(1)]})
    anim = define_animation(stage, "/Agent/Anim", np.zeros((3, 4, 3)), rotations=frames)
    define_skeleton(stage, "/Agent/Skel", anim.GetPath())
    pos = evaluate.joint_world_positions(stage, "/Agent/Skel", [0, 1, 2])
    assert pos.shape == (3, 4, 3)
    for k in range(3):
        root_w = np.array([10.0 + k, 0.0, 5.0])
        hips = root_w + [0.0, 1.0, -1.0]  # (1, 1, 0) turned +90 deg about Y
        np.testing.assert_allclose(pos[k, 0], root_w, atol=1e-5)
        np.testing.assert_allclose(pos[k, 1], hips, atol=1e-5)
        np.testing.assert_allclose(pos[k, 2], hips + [0.2, -1.0, 0.0], atol=1e-5)
        np.testing.assert_allclose(pos[k, 3], hips + [-0.2, -1.0, 0.0], atol=1e-5)
    # The SkelRoot resolves to the same skeleton; default times are the authored samples.
    np.testing.assert_allclose(evaluate.joint_world_positions(stage, "/Agent"), pos, atol=0)


def test_agent_root_positions_single_and_batch(tmp_path):
    stage = new_stage(tmp_path, "roots.usda", up="Z")
    n = 5
    feet = foot(n, 0.0, 0.1, 0.0)
    for a in range(3):
        build_agent(stage, f"/Crowd/A{a}", walk(n, "Z", feet, feet, root_speed=0.1 * (a + 1)))
    paths = [f"/Crowd/A{a}" for a in range(3)]
    batch = evaluate.agent_root_positions(stage, paths, range(n))
    assert batch.shape == (3, n, 3)
    for a in range(3):
        expect = np.stack((0.1 * (a + 1) * np.arange(n), np.zeros(n), np.zeros(n)), axis=1)
        np.testing.assert_allclose(batch[a], expect, atol=1e-6)
    one = evaluate.agent_root_positions(stage, Sdf.Path("/Crowd/A2"), range(n), root_joint="Hips")
    assert one.shape == (n, 3)
    np.testing.assert_allclose(one[:, 2], 1.0, atol=1e-6)
    with pytest.raises(ValueError, match="no joint named 'Neck'"):
        evaluate.agent_root_positions(stage, paths, range(n), root_joint="Neck")


def test_usd_errors_name_the_prim(tmp_path):
    stage = new_stage(tmp_path, "errors.usda")
    with pytest.raises(ValueError, match="/Nope"):
        measure.foot_skate(stage, "/Nope")
    stage.DefinePrim("/Empty", "Xform")
    with pytest.raises(ValueError, match="/Empty: no Skeleton"):
        evaluate.joint_world_positions(stage, "/Empty", [0])
    n = 4
    world = walk(n, "Y", foot(n, 0, 0, 0), foot(n, 0, 0, 0))
    UsdSkel.Root.Define(stage, "/Agent")
    anim = define_animation(stage, "/Agent/Anim", world)
    skel = define_skeleton(stage, "/Agent/Skel", anim.GetPath())
    skel.CreateJointsAttr(["Root", "Root/Hips", "Root/Hips/L", "Root/Hips/R"])
    anim.CreateJointsAttr(["Root", "Root/Hips", "Root/Hips/L", "Root/Hips/R"])
    with pytest.raises(ValueError, match="/Agent/Skel: no joint is named like a foot"):
        measure.foot_skate(stage, "/Agent")
    static = UsdSkel.Root.Define(stage, "/Static")
    sanim = UsdSkel.Animation.Define(stage, "/Static/Anim")
    sanim.CreateJointsAttr(JOINTS)
    define_skeleton(stage, "/Static/Skel", sanim.GetPath())
    with pytest.raises(ValueError, match="no time samples"):
        measure.foot_skate(stage, static.GetPath())
