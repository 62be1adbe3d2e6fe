"""Batched rigid-transform math on numpy arrays (no USD).

Conventions, shared by the whole package:
- quaternions are ``(x, y, z, w)``, the layout of ``Vt.QuatfArray`` as numpy;
- 4x4 matrices follow USD's row-vector convention: a point transforms as ``p @ M``,
  the translation sits in ``M[3, :3]`` and a child's world matrix is ``local @ parent``.
"""
from __future__ import annotations

import numpy as np

from mocapedit import _solver


#: Multiplies a quaternion (x, y, z, w) into its conjugate.
_CONJUGATE = np.array([-1.0, -1.0, -1.0, 1.0])


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of (...,4) quaternions (x, y, z, w): rotate by b, then a."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b), -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], -1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """(...,4) conjugates of quaternions (x, y, z, w): the inverse rotations of unit ones."""
    return np.asarray(q) * _CONJUGATE


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...,3) cross products of (...,3) vectors, broadcast: ``np.cross``'s values, without its
    overhead (40% of its time on the few hundred vectors of one agent's legs)."""
    a, b = np.asarray(a), np.asarray(b)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(...,3) vectors ``v`` rotated by (...,4) unit quaternions ``q``."""
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * cross3(u, v)
    return v + w * t + cross3(u, t)


def quat_to_matrix3(q: np.ndarray) -> np.ndarray:
    """(...,4) unit quaternions -> (...,3,3) row-vector rotation matrices (p @ R)."""
    q = np.asarray(q, dtype=np.float64)
    return _rotation_rows(q / np.linalg.norm(q, axis=-1, keepdims=True), np.empty(q.shape[:-1] + (3, 3)))


def _rotation_rows(q: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Writes the row-vector rotation matrices of (...,4) unit quaternions into the top left
    3x3 of ``m`` (...,3 or 4,3 or 4) and returns ``m``: the transpose of the column-vector matrix."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    m[..., 0, 0] = 1 - 2 * (yy + zz)
    m[..., 1, 0] = 2 * (xy - wz)
    m[..., 2, 0] = 2 * (xz + wy)
    m[..., 0, 1] = 2 * (xy + wz)
    m[..., 1, 1] = 1 - 2 * (xx + zz)
    m[..., 2, 1] = 2 * (yz - wx)
    m[..., 0, 2] = 2 * (xz - wy)
    m[..., 1, 2] = 2 * (yz + wx)
    m[..., 2, 2] = 1 - 2 * (xx + yy)
    return m


def compose_trs(translations: np.ndarray, rotations: np.ndarray,
                scales: np.ndarray | None = None) -> np.ndarray:
    """(...,3), (...,4), (...,3) -> (...,4,4) matrices that scale, then rotate, then translate."""
    t = np.asarray(translations, dtype=np.float64)
    q = np.asarray(rotations, dtype=np.float64)
    m = _rotation_rows(q / np.linalg.norm(q, axis=-1, keepdims=True), np.zeros(t.shape[:-1] + (4, 4)))
    if scales is not None:
        m[..., :3, :3] *= np.asarray(scales, dtype=np.float64)[..., :, None]
    m[..., 3, :3] = t
    m[..., 3, 3] = 1.0
    return m


def transform_points(points: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """(...,3) points moved by (...,4,4) row-vector matrices (``p @ M``, broadcast): their rotation
    and scale rows summed in order, then the translation row."""
    r = matrices[..., :3, :3]
    return (points[..., 0, None] * r[..., 0, :] + points[..., 1, None] * r[..., 1, :]
            + points[..., 2, None] * r[..., 2, :] + matrices[..., 3, :3])


def skeleton_space(parents: np.ndarray, columns: np.ndarray, rest: np.ndarray, translations: np.ndarray,
                   rotations: np.ndarray, scales: np.ndarray, joints, with_rotations: bool = False):
    """(T,K,4,4) skeleton-space matrices of the wanted ``joints`` (K,) of (T,C,3/4/3) joint-local
    poses, by the solver's SkeletonSpaceJob: ``parents`` (J,) (-1 for a root, parents first),
    ``columns`` (J,) the pose column of each joint (-1: its ``rest`` (J,4,4) transform).
    ``with_rotations``: (matrices, (T,K,4) their rotations once their scales are divided out, as
    ``mocapedit.solve.layering.trs_from_matrices`` finds them, in float64)."""
    return _solver.skeleton_space(parents=parents, columns=columns, rest=rest, translations=translations,
                                  rotations=rotations, scales=scales, joints=np.asarray(joints, dtype=np.int64),
                                  with_rotations=with_rotations)


def skeleton_space_numpy(parents: np.ndarray, columns: np.ndarray, rest: np.ndarray, translations: np.ndarray,
                         rotations: np.ndarray, scales: np.ndarray, joints) -> np.ndarray:
    """:func:`skeleton_space` in numpy (:func:`compose_trs` and matrix products, joint by joint):
    the same results to within rounding."""
    count = np.shape(translations)[0]
    skel: dict[int, np.ndarray] = {}

    def world(j: int) -> np.ndarray:
        if j not in skel:
            c = int(columns[j])
            local = (compose_trs(translations[:, c], rotations[:, c], scales[:, c]) if c >= 0
                     else np.broadcast_to(rest[j], (count, 4, 4)))
            p = int(parents[j])
            skel[j] = local if p < 0 else local @ world(p)
        return skel[j]

    return np.stack([world(int(j)) for j in joints], axis=1).reshape(count, len(joints), 4, 4)


def chain_to_skel(local: np.ndarray, parents: np.ndarray, joint: int) -> np.ndarray:
    """Skeleton-space matrices of one joint: (...,J,4,4) locals -> (...,4,4)."""
    m = local[..., joint, :, :]
    p = int(parents[joint])
    while p >= 0:
        m = m @ local[..., p, :, :]
        p = int(parents[p])
    return m


def skel_space(local: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(...,J,4,4) joint-local -> skeleton-space matrices; parents precede children."""
    out = np.empty_like(local)
    for j, p in enumerate(parents):
        out[..., j, :, :] = local[..., j, :, :] if p < 0 else local[..., j, :, :] @ out[..., p, :, :]
    return out


def yaw_matrix(angle: np.ndarray, up_axis: str) -> np.ndarray:
    """(...,) angles (radians, counter-clockwise about up) -> (...,4,4) rotations."""
    a = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (4, 4))
    m[..., 3, 3] = 1.0
    if up_axis == "Z":
        # Ground axes (x, y): row-vector rotation about +Z.
        m[..., 0, 0], m[..., 0, 1] = c, s
        m[..., 1, 0], m[..., 1, 1] = -s, c
        m[..., 2, 2] = 1.0
    else:
        # Ground axes (x, -z): counter-clockwise about +Y.
        m[..., 0, 0], m[..., 0, 2] = c, -s
        m[..., 2, 0], m[..., 2, 2] = s, c
        m[..., 1, 1] = 1.0
    return m


def translation_matrix(t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=np.float64)
    m = np.empty(t.shape[:-1] + (4, 4))
    m[...] = np.eye(4)
    m[..., 3, :3] = t
    return m
