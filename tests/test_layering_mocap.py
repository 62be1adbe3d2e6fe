"""Layering real motion capture: a stationary upper-body clip (CMU 02_05, punch and strike)
added over a walk (CMU 02_01), both on the 100-joint CC rig, read from ../shared/mocap.

The two files are parsed here with a minimal BVH reader (ZYX Euler channels, offsets plus
root position); the clips are written as USD clip layers and solved end to end.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdSkel

from mocapedit import examples, layering, walker
from mocapedit.processor import solve

from conftest import SHARED_MOCAP, world_joints

WALK = SHARED_MOCAP / "cc_cmu02_01_walk.bvh"
PUNCH = SHARED_MOCAP / "cc_cmu02_05_punch_strike.bvh"

pytestmark = [pytest.mark.realdata,
              pytest.mark.skipif(not (WALK.exists() and PUNCH.exists()), reason="../shared/mocap is absent")]


def _axis_quats(axis: str, degrees: np.ndarray) -> np.ndarray:
    half = np.radians(degrees) / 2
    q = np.zeros(degrees.shape + (4,))
    q[..., "XYZ".index(axis)] = np.sin(half)
    q[..., 3] = np.cos(half)
    return q


def read_bvh(path, name, first=0, count=None) -> walker.Clip:
    """A BVH file as a clip: Y-up centimetres, rotations composed in channel order."""
    tokens = path.read_text().split()
    joints, parents, offsets, channels = [], [], [], []
    stack, i = [], 0
    while tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            parent = stack[-1] if stack else -1
            joints.append(tokens[i + 1] if parent < 0 else f"{joints[parent]}/{tokens[i + 1]}")
            parents.append(parent)
            i += 2
        elif tok == "End":
            depth = 0
            while True:  # skip the End Site block
                i += 1
                depth += tokens[i] == "{"
                depth -= tokens[i] == "}"
                if depth == 0 and tokens[i] == "}":
                    break
            i += 1
        elif tok == "{":
            stack.append(len(joints) - 1)
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            offsets.append([float(v) for v in tokens[i + 1:i + 4]])
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels.append(tokens[i + 2:i + 2 + n])
            i += 2 + n
        else:
            i += 1
    frames = int(tokens[i + 2])
    fps = 1.0 / float(tokens[i + 5])
    values = np.array(tokens[i + 6:], dtype=np.float64).reshape(frames, -1)
    count = frames - first if count is None else count
    values = values[first:first + count]
    t = np.broadcast_to(np.array(offsets), (count, len(joints), 3)).copy()
    q = np.zeros((count, len(joints), 4))
    q[..., 3] = 1
    col = 0
    for j, names in enumerate(channels):
        for channel in names:
            v = values[:, col]
            col += 1
            if channel.endswith("position"):
                t[:, j, "XYZ".index(channel[0])] += v
            else:
                q[:, j] = layering.quat_multiply(q[:, j], _axis_quats(channel[0], v))
    flips = np.cumprod(np.where(np.sum(q[1:] * q[:-1], -1) < 0, -1.0, 1.0), axis=0)
    q[1:] *= flips[..., None]
    rest = np.array(offsets, np.float32)
    return walker.Clip(name=name, joints=joints, parents=np.array(parents, np.int32), rest_translations=rest,
                       rest_rotations=np.tile(np.float32([0, 0, 0, 1]), (len(joints), 1)),
                       translations=t.astype(np.float32), rotations=q.astype(np.float32), fps=fps,
                       up_axis="Y", meters_per_unit=0.01)


def _angle(a, b):
    """Rotation angle (radians) between (...,4) quaternions, whatever their signs."""
    d = np.abs(np.sum(np.asarray(a, np.float64) * b, -1))
    return 2 * np.arccos(np.clip(d, 0, 1))


def test_a_stationary_upper_body_clip_added_over_a_walk_stays_sound(tmp_path):
    walk = read_bvh(WALK, "cmu_walk")
    punch = read_bvh(PUNCH, "cmu_punch", count=walk.num_frames)
    path = tmp_path / "shot.usda"
    examples.build_crowd_stage(path, [examples.AgentSpec("walker", walk)], up_axis="Y", meters_per_unit=0.01,
                               fps=walk.fps, clips_dir=tmp_path / "clips")
    examples.write_clip_layer(punch, tmp_path / "clips" / "punch.usda")
    stage = Usd.Stage.Open(str(path))
    stage.DefinePrim("/Layers/Punch").GetReferences().AddReference("./clips/punch.usda", "/Skel/Anim")
    weight = {20.0: 0.0, 60.0: 1.0, 120.0: 1.0, 160.0: 0.0}
    layer = stage.DefinePrim("/Layers/Strike", "MocapAnimationLayer")
    layer.CreateRelationship("agents").SetTargets([Sdf.Path("/World/Crowd/walker")])
    layer.CreateRelationship("animation").SetTargets([Sdf.Path("/Layers/Punch")])
    layer.GetAttribute("joint").Set("CC_Base_Waist")  # a bare name: the two rigs root differently
    layer.GetAttribute("wrap").Set("clamp")
    for t, w in weight.items():
        layer.GetAttribute("weight").Set(w, t)
    stage.GetRootLayer().Save()

    result = solve(str(path), output=str(tmp_path / "e.usdc"), composed=str(tmp_path / "c.usda"))
    out = Usd.Stage.Open(str(tmp_path / "c.usda"))
    assert result.report.stats["layeredAgents"] == 1
    times = np.arange(walk.num_frames, dtype=np.float64)
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(out.GetPrimAtPath("/World/Crowd/walker")), Usd.PrimDefaultPredicate)
    anim = cache.GetSkelQuery(UsdSkel.Skeleton(out.GetPrimAtPath("/World/Crowd/walker/Skel"))).GetAnimQuery()
    joints = [str(j) for j in anim.GetJointOrder()]
    components = [anim.ComputeJointLocalTransformComponents(Usd.TimeCode(t)) for t in times]
    tr = np.array([np.array(c[0]) for c in components])
    rot = np.array([[[q.GetImaginary()[0], q.GetImaginary()[1], q.GetImaginary()[2], q.GetReal()] for q in c[1]]
                    for c in components])
    world = world_joints(out, "/World/Crowd/walker/Skel", times)

    # Finite and normalised.
    assert np.all(np.isfinite(tr)) and np.all(np.isfinite(rot)) and np.all(np.isfinite(world))
    np.testing.assert_allclose(np.linalg.norm(rot, axis=-1), 1.0, atol=2e-6)

    # The waist's subtree changed where the weight is up; the legs did not change at all.
    sub = np.array(["CC_Base_Waist" in j.split("/") for j in joints])
    source = walk.rotations
    assert _angle(rot[90][sub], source[90][sub]).max() > 0.3
    np.testing.assert_array_equal(rot[:, ~sub], source[:, ~sub])
    np.testing.assert_array_equal(rot[:20], source[:20])

    # No flips: a frame-to-frame step of a layered joint is at most the source's step plus the
    # step of the weighted delta (triangle inequality in the rotation group), which moves by
    # the delta's own step and by the change of weight times the delta's angle.
    punch_of = {j.rsplit("/", 1)[-1]: k for k, j in enumerate(punch.joints)}
    cols = [punch_of[j.rsplit("/", 1)[-1]] for j in np.array(joints)[sub]]
    p = punch.rotations[:, cols].astype(np.float64)
    delta = layering.quat_multiply(p, p[0] * [-1, -1, -1, 1])
    w = np.interp(times, sorted(weight), [weight[k] for k in sorted(weight)])[:, None]
    bound = (_angle(source[1:, sub], source[:-1, sub]) + _angle(delta[1:], delta[:-1])
             + np.abs(np.diff(w, axis=0)) * _angle(delta[1:], [0, 0, 0, 1]) + 1e-3)
    step = _angle(rot[1:, sub], rot[:-1, sub])
    assert np.all(step <= bound), f"largest excess {np.max(step - bound):.3g} rad"
    assert step.max() < np.radians(45)
