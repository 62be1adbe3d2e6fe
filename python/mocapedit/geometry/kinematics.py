"""Batched rigid-transform math on numpy arrays (no USD).

Conventions, shared by the whole package:
- quaternions are ``(x, y, z, w)``, the layout of ``Vt.QuatfArray`` as numpy;
- 4x4 matrices follow USD's row-vector convention: a point transforms as ``p @ M``,
  the translation sits in ``M[3, :3]`` and a child's world matrix is ``local @ parent``.
"""
from __future__ import annotations

import numpy as np


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
