"""The edit's transform op written as the fewest USD ops: translate and a turn about up where the
agent's parent is upright, the whole matrix otherwise; USD composes them back to the same matrix."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom

from mocapedit.geometry import kinematics, trajectory


def _usd_local(ops, k: int) -> np.ndarray:
    """The local matrix USD composes from the ops' k-th values, in their order."""
    stage = Usd.Stage.CreateInMemory()
    xf = UsdGeom.Xform.Define(stage, "/A")
    for kind, values in ops:
        v = values[k]
        if kind == "translate":
            xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble, "mocapEdit").Set(Gf.Vec3d(*map(float, v)))
        elif kind == "rotateY":
            xf.AddRotateYOp(UsdGeom.XformOp.PrecisionDouble, "mocapEdit").Set(float(v))
        elif kind == "rotateZ":
            xf.AddRotateZOp(UsdGeom.XformOp.PrecisionDouble, "mocapEdit").Set(float(v))
        else:
            xf.AddTransformOp(UsdGeom.XformOp.PrecisionDouble, "mocapEdit").Set(Gf.Matrix4d(v.tolist()))
    return np.array(xf.GetLocalTransformation())


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_an_upright_edit_is_a_translate_and_a_turn_about_up(up):
    rng = np.random.default_rng(4)
    yaw = rng.uniform(-7.0, 7.0, 6)          # unwrapped: several turns
    shift = rng.normal(0.0, 30.0, (6, 3))
    shift[:, 1 if up == "Y" else 2] = rng.normal(0.0, 0.1, 6)   # a lowered pelvis rides along
    op = kinematics.yaw_matrix(yaw, up) @ kinematics.translation_matrix(shift)
    ops = trajectory.xform_ops(op, up)
    assert [kind for kind, _ in ops] == ["translate", f"rotate{up}"]
    for k in range(len(op)):
        assert np.abs(_usd_local(ops, k) - op[k]).max() < 1e-12


def test_an_edit_under_a_tilted_parent_stays_a_matrix():
    op = kinematics.yaw_matrix(np.array([0.3, 0.4]), "Y") @ kinematics.translation_matrix(np.ones((2, 3)))
    tilt = np.eye(4)
    tilt[:3, :3] = kinematics.quat_to_matrix3(np.array([np.sin(0.2), 0.0, 0.0, np.cos(0.2)]))
    tilted = tilt @ op @ np.linalg.inv(tilt)
    ops = trajectory.xform_ops(tilted, "Y")
    assert [kind for kind, _ in ops] == ["transform"]
    assert np.abs(_usd_local(ops, 1) - tilted[1]).max() < 1e-12


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_a_turn_through_a_half_turn_plays_smoothly_between_samples(up):
    """USD interpolates a rotate op's angle linearly between time samples: the angles are
    written unwrapped, so a heading that passes 180 degrees between two samples turns by the
    small step between them. Wrapped to (-180, 180], it read about 0 halfway and the whole
    agent swung half round its parent's origin for that instant (a CMU take on a path curve,
    at its clip's 120 fps samples: its hips 10 m away)."""
    yaw = np.radians(np.linspace(170.0, 190.0, 9))
    op = kinematics.yaw_matrix(yaw, up) @ kinematics.translation_matrix(np.zeros((9, 3)))
    ops = trajectory.xform_ops(op, up)
    stage = Usd.Stage.CreateInMemory()
    xf = UsdGeom.Xform.Define(stage, "/A")
    rotate = xf.AddRotateYOp if up == "Y" else xf.AddRotateZOp
    attr = rotate(UsdGeom.XformOp.PrecisionDouble, "mocapEdit")
    for k, v in enumerate(ops[1][1]):
        attr.Set(float(v), float(k))
    for k in range(8):
        halfway = np.array(xf.GetLocalTransformation(k + 0.5))
        expected = kinematics.yaw_matrix(np.array([0.5 * (yaw[k] + yaw[k + 1])]), up)[0]
        assert np.abs(halfway - expected).max() < 1e-9
