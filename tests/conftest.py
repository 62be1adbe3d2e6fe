"""Shared fixtures: small hand-built UsdSkel stages whose answers are known exactly."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

import mocapedit  # noqa: F401  (registers the schema plugin)

REPO = Path(__file__).resolve().parents[1]
# The CMU clips, when present; MOCAPEDIT_MOCAP_DIR points elsewhere.
SHARED_MOCAP = Path(os.environ.get("MOCAPEDIT_MOCAP_DIR", REPO.parent / "shared" / "mocap"))


def shot_over_clip(path: Path, clip: Usd.Stage, up: str, meters_per_unit: float = 0.01) -> Usd.Stage:
    """A new shot stage at ``path`` with ``clip``'s frame rate and range (the caller brings the
    clip in, by sublayer or reference)."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(clip.GetTimeCodesPerSecond())
    stage.SetStartTimeCode(clip.GetStartTimeCode())
    stage.SetEndTimeCode(clip.GetEndTimeCode())
    return stage

TOY_JOINTS = ["Root", "Root/Hips", "Root/Hips/LeftFoot", "Root/Hips/RightFoot"]


def toy_clip(frames: int = 48, speed: float = 5.0, sway: float = 10.0):
    """Root walks along the ground's first axis with a lateral sway; body is static."""
    f = np.arange(frames, dtype=np.float64)
    t = np.zeros((frames, 4, 3), np.float32)
    t[:, 0, 0] = f * speed
    t[:, 0, 1] = sway * np.sin(f / 5.0)
    t[:, 1] = (0, 0, 90)
    t[:, 2] = (10, 0, -90)
    t[:, 3] = (-10, 0, -90)
    q = np.zeros((frames, 4, 4), np.float32)
    q[..., 3] = 1
    # A slow yaw on the hips so the body has some rotation to carry.
    a = 0.2 * np.sin(f / 7.0)
    q[:, 1, 2], q[:, 1, 3] = np.sin(a / 2), np.cos(a / 2)
    return t, q


def write_toy_stage(path, agents=3, up_axis="Z", meters_per_unit=0.01, fps=24.0, frames=48,
                    spacing=100.0, time_offsets=None, skip=None) -> Path:
    """A Z-up (or Y-up) stage of toy agents; each has its own SkelAnimation below its Skeleton.

    For Y-up stages the clip's 'up' axis is authored on Y (translations are swizzled).
    ``skip``: None, "skeleton", "animation" or "samples", to make broken agents.
    """
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(frames - 1)
    t, q = toy_clip(frames)
    if up_axis == "Y":  # clip ground (x, v) -> world (x, -z); up -> y
        t = np.stack([t[..., 0], t[..., 2], -t[..., 1]], -1).astype(np.float32)
    UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(stage.GetPrimAtPath("/World"))
    for k in range(agents):
        root = UsdSkel.Root.Define(stage, f"/World/agent{k}")
        xf = UsdGeom.Xformable(root)
        offset = Gf.Vec3d(0, 0, spacing * k) if up_axis == "Y" else Gf.Vec3d(0, spacing * k, 0)
        xf.AddTranslateOp().Set(offset)
        xf.AddRotateXYZOp().Set(Gf.Vec3f(0, 15.0 * k, 0) if up_axis == "Y" else Gf.Vec3f(0, 0, 15.0 * k))
        root.GetPrim().AddAppliedSchema("MocapAgentAPI")
        if skip == "skeleton":
            continue
        skel = UsdSkel.Skeleton.Define(stage, f"/World/agent{k}/Skel")
        skel.GetJointsAttr().Set(TOY_JOINTS)
        skel.GetRestTransformsAttr().Set(Vt.Matrix4dArray([Gf.Matrix4d(1)] * 4))
        skel.GetBindTransformsAttr().Set(Vt.Matrix4dArray([Gf.Matrix4d(1)] * 4))
        if skip == "animation":
            continue
        anim = UsdSkel.Animation.Define(stage, f"/World/agent{k}/Skel/Anim")
        anim.GetJointsAttr().Set(TOY_JOINTS)
        if skip != "samples":
            for i in range(frames):
                anim.GetTranslationsAttr().Set(Vt.Vec3fArray.FromNumpy(t[i]), i)
                anim.GetRotationsAttr().Set(Vt.QuatfArray.FromNumpy(q[i]), i)
            # UsdSkel poses an animation only when translations, rotations and scales are all set.
            anim.GetScalesAttr().Set(Vt.Vec3hArray.FromNumpy(np.ones((4, 3), np.float16)))
        UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    stage.GetRootLayer().Save()
    return Path(path)


CROSSROADS_MEET = 60


def write_crossroads(path, marks: bool = True) -> Path:
    """Two walkers cross at the origin at frame 60 (Y-up, metres, 24 fps, collision
    avoidance on) in lanes 0.8 m wide between four blocks (box avoid regions): neither can
    step aside there. With ``marks``, hard position constraints hold each where it is half a
    second before and after the crossing, so neither can slide along its lane either."""
    from mocapedit.data import examples, walker
    from mocapedit.usd import evaluate
    path = Path(path)
    walk = walker.walk(frames=120, fps=24.0, speed=1.4, up="Y", meters_per_unit=1.0, name="walk_x")
    specs = [examples.AgentSpec("agent_0000", walk, (0.0, 0.0, -3.5), 0.0),
             examples.AgentSpec("agent_0001", walk, (-3.5, 0.0, 0.0), 90.0)]
    stage = examples.build_crowd_stage(path, specs, up_axis="Y", meters_per_unit=1.0, fps=24.0,
                                       clips_dir=path.parent / "clips")
    vt = Sdf.ValueTypeNames
    examples.define_mocap_prim(stage, "/World/Settings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (vt.Bool, True), "margin": (vt.Double, 0.05)})
    for k, (x, z) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        block = examples.define_mocap_prim(stage, f"/World/Regions/block{k}", "MocapAvoidRegion", attributes={
            "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(8.0, 1.0, 8.0))})
        UsdGeom.Xformable(block).AddTranslateOp().Set(Gf.Vec3d(x * 4.4, 0.5, z * 4.4))
    for k in range(2 if marks else 0):
        agent = f"/World/Crowd/agent_000{k}"
        for frame in (CROSSROADS_MEET - 12, CROSSROADS_MEET + 12):
            p = evaluate.agent_root_positions(stage, agent, [float(frame)])[0]
            examples.add_position_constraint(stage, f"/World/Marks/a{k}_f{frame}", agent, frame,
                                             (float(p[0]), 0.0, float(p[2])))
    stage.GetRootLayer().Save()
    return path


def world_joints(stage: Usd.Stage, skel_path: str, times) -> np.ndarray:
    """(T,J,3) joint world positions by UsdSkel forward kinematics on a composed stage."""
    cache = UsdSkel.Cache()
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath(skel_path))
    root = UsdSkel.Root.Find(skel.GetPrim())
    cache.Populate(root, Usd.PrimDefaultPredicate)
    query = cache.GetSkelQuery(skel)
    out = []
    for t in times:
        mats = query.ComputeJointWorldTransforms(UsdGeom.XformCache(Usd.TimeCode(float(t))))
        out.append(np.array(mats)[:, 3, :3])
    return np.array(out)


def run_cli(*args, cwd=None, timeout=None):
    """Runs the installed `mocapedit` command and returns the CompletedProcess (``timeout``:
    seconds, after which it raises ``subprocess.TimeoutExpired``)."""
    exe = Path(sys.executable).with_name("mocapedit")
    return subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          env={**os.environ, "PYTHONWARNINGS": "error"}, timeout=timeout)


@pytest.fixture
def budget():
    """Sets the solver's thread budget (``mocapedit.solve.threads.set_budget``) for a test and
    puts the process's back after it."""
    from mocapedit.solve import threads
    yield threads.set_budget
    threads.set_budget(0)


@pytest.fixture
def toy_stage(tmp_path):
    return write_toy_stage(tmp_path / "shot.usda")
