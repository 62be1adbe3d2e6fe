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
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    # Column-vector matrix, then transposed for the row-vector convention.
    m = np.stack([
        np.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], -1),
        np.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], -1),
        np.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], -1),
    ], -2)
    return np.swapaxes(m, -1, -2)


def compose_trs(translations: np.ndarray, rotations: np.ndarray,
                scales: np.ndarray | None = None) -> np.ndarray:
    """(...,3), (...,4), (...,3) -> (...,4,4) matrices that scale, then rotate, then translate."""
    t = np.asarray(translations, dtype=np.float64)
    r = quat_to_matrix3(rotations)
    if scales is not None:
        r = r * np.asarray(scales, dtype=np.float64)[..., :, None]
    m = np.zeros(t.shape[:-1] + (4, 4))
    m[..., :3, :3] = r
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
