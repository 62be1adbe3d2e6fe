"""Small UsdSkel stages built by hand: agents of four joints (root, hips, two feet) whose world
joint positions are given, for tests of stage evaluation and of the measures made on it."""
from __future__ import annotations

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

from mocapedit.inspect import metrics as M

JOINTS = ["Root", "Root/Hips", "Root/Hips/LeftFoot", "Root/Hips/RightFoot"]


def new_stage(tmp_path, name, up="Y", tcps=24.0, mpu=1.0):
    stage = Usd.Stage.CreateNew(str(tmp_path / name))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    stage.SetTimeCodesPerSecond(tcps)
    return stage


def define_animation(stage, path, world, rotations=None, start=0.0):
    """A SkelAnimation of the 4-joint skeleton whose joints reach ``world`` (T, 4, 3).

    Without rotations every joint's world position is the sum of the translations down its chain,
    so the local translations follow by subtraction from the parent.
    """
    world = np.asarray(world, dtype=np.float64)
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(JOINTS)
    tr_attr, rot_attr, sc_attr = (anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(),
                                  anim.CreateScalesAttr())
    parent = [None, 0, 1, 1]
    for k in range(len(world)):
        local = np.array([world[k, j] - (world[k, parent[j]] if parent[j] is not None else 0.0)
                          for j in range(4)])
        if rotations is not None:
            local = rotations[k]["local"]
        tr_attr.Set(Vt.Vec3fArray.FromNumpy(local.astype(np.float32)), start + k)
        quats = [Gf.Quatf(1.0)] * 4 if rotations is None else rotations[k]["quats"]
        rot_attr.Set(Vt.QuatfArray(quats), start + k)
        sc_attr.Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * 4), start + k)
    return anim


def define_skeleton(stage, path, anim_path):
    skel = UsdSkel.Skeleton.Define(stage, path)
    skel.CreateJointsAttr(JOINTS)
    ident = [Gf.Matrix4d(1.0)] * 4
    skel.CreateRestTransformsAttr(ident)
    skel.CreateBindTransformsAttr(ident)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim_path])
    return skel


def build_agent(stage, root_path, world, bind_on_root=False):
    """SkelRoot ``root_path`` holding Skeleton ``Skel`` bound to SkelAnimation ``Anim``."""
    root = UsdSkel.Root.Define(stage, root_path)
    anim = define_animation(stage, f"{root_path}/Anim", world)
    skel = define_skeleton(stage, f"{root_path}/Skel", anim.GetPath())
    if bind_on_root:
        UsdSkel.BindingAPI.Apply(root.GetPrim()).CreateSkeletonRel().SetTargets([skel.GetPath()])
    return root, skel


def walk(n, up, left, right, root_speed=0.0, hip_height=1.0):
    """World joint positions (n, 4, 3) from ground paths and heights of the two feet.

    ``left``/``right``: (n, 3) arrays of (ground u, ground v, height).
    """
    def place(g):
        g = np.asarray(g, dtype=np.float64)
        return M.from_ground(g[:, :2], g[:, 2], up)

    k = np.arange(n, dtype=np.float64)
    root = M.from_ground(np.stack((root_speed * k, np.zeros(n)), axis=1), 0.0, up)
    hips = root + M.from_ground(np.zeros((n, 2)), hip_height, up)
    return np.stack((root, hips, place(left), place(right)), axis=1)


def foot(n, u, v, h):
    return np.stack([np.broadcast_to(np.asarray(c, float), (n,)) for c in (u, v, h)], axis=1)
