"""World joint positions of a BVH file by an independent implementation: the bvhio package.

bvhio (PyPI, pinned in requirements-dev.txt) parses the file itself, turns each joint's
Euler channels into quaternions with SpatialTransform, rebuilds its own joint hierarchy
(it re-orients every joint along its bone) and gives world positions by its own forward
kinematics. It reads position channels as replacing the OFFSET, like our "absolute" mode.

It computes with pyglm's single-precision types. At 4 m from the origin in centimetres
single precision alone resolves 3e-5, and bvhio's longer chain of products loses
about 1.4e-4 there: too coarse for a 1e-4 check. So ``world_positions`` runs bvhio's own
code on pyglm's double-precision types, by giving its modules a ``glm`` namespace whose
vector, quaternion and matrix types are the double ones. Nothing of bvhio's algorithm
changes.
"""
from __future__ import annotations

import sys
import types
import warnings

import numpy as np

from conftest import REPO

#: The real CMU clips: ../shared/mocap beside the repository (or beside the folder of
#: worktrees that holds it); tests skip what needs them when it is absent.
REAL_MOCAP = next((p for p in (REPO.parent / "shared" / "mocap", REPO.parent.parent / "shared" / "mocap")
                   if p.is_dir()), REPO.parent / "shared" / "mocap")

_MODULES = ("SpatialTransform.lib.euler", "SpatialTransform.lib.pose", "SpatialTransform.lib.transform",
            "bvhio.lib.Parser", "bvhio.lib.bvh.BvhJoint", "bvhio.lib.hierarchy.Joint")


def _double_glm():
    import glm

    shim = types.ModuleType("glm_double")
    shim.__dict__.update(glm.__dict__)
    shim.vec3, shim.vec4, shim.quat, shim.mat3, shim.mat4 = glm.dvec3, glm.dvec4, glm.dquat, glm.dmat3, glm.dmat4

    def d(x):
        return glm.dvec3(x) if isinstance(x, (tuple, list, glm.vec3)) else x

    def rotate(a, b, c=None):
        if c is None:
            return glm.rotate(a, b)
        if isinstance(a, glm.dquat):  # glm.rotate(quat, angle, axis) = quat * angleAxis(angle, axis)
            return a * glm.angleAxis(b, glm.normalize(d(c)))
        return glm.rotate(a, b, d(c))

    shim.rotate = rotate
    shim.angleAxis = lambda a, v: glm.angleAxis(a, d(v))
    shim.translate = lambda *a: glm.translate(*[d(x) for x in a])
    shim.scale = lambda *a: glm.scale(*[d(x) for x in a])
    shim.identity = lambda t: glm.identity({glm.mat4: glm.dmat4, glm.mat3: glm.dmat3, glm.quat: glm.dquat}.get(t, t))
    return shim


_READY = False


def _prepare():
    global _READY
    if _READY:
        return
    with warnings.catch_warnings():
        # pyglm 2.8 announces that "import glm" (which bvhio uses) will become "from pyglm import glm".
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio  # noqa: F401  (imports every module patched below)
    shim = _double_glm()
    for name in _MODULES:
        sys.modules[name].glm = shim
    _READY = True


def world_positions(path) -> tuple[list[str], np.ndarray]:
    """(joint names in file order, (F,J,3) world positions) computed by bvhio."""
    _prepare()
    import bvhio
    root = bvhio.readAsHierarchy(str(path))
    joints = [j for j, _, _ in root.layout()]
    frames = len(joints[0].Keyframes)
    out = np.empty((frames, len(joints), 3))
    for f in range(frames):
        root.loadPose(f)
        for k, joint in enumerate(joints):
            p = joint.PositionWorld
            out[f, k] = (p.x, p.y, p.z)
    return [j.Name for j in joints], out
