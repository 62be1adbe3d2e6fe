"""The ground plane of a stage, from its upAxis.

Ground coordinates ``(u, v)`` are chosen so that ``u x v = up``: headings measured with
``atan2(v, u)`` turn counter-clockwise about the up axis.
- Y-up: ``u = x``, ``v = -z``
- Z-up: ``u = x``, ``v = y``
"""
from __future__ import annotations

import numpy as np


def up_token(up_axis) -> str:
    """``"Y"`` or ``"Z"`` (either case accepted); ValueError for anything else."""
    token = str(up_axis).upper()
    if token not in ("Y", "Z"):
        raise ValueError(f"up axis must be 'Y' or 'Z', got {up_axis!r}")
    return token


def up_index(up_axis: str) -> int:
    return 2 if up_axis == "Z" else 1


def ground_axes(up_axis) -> tuple[int, tuple[int, float], tuple[int, float]]:
    """Where the up axis and the two ground coordinates sit in a 3D point.

    Returns ``(up_index, (u_index, u_sign), (v_index, v_sign))`` such that the ground coordinates of
    point ``p`` are ``(u_sign * p[u_index], v_sign * p[v_index])``: ``(x, -z)`` for ``"Y"`` up and
    ``(x, y)`` for ``"Z"`` up. Both frames are right-handed seen from above, so angles in the ground
    plane are counter-clockwise about up.
    """
    if up_token(up_axis) == "Y":
        return 1, (0, 1.0), (2, -1.0)
    return 2, (0, 1.0), (1, 1.0)


def plane_indices(up_axis) -> tuple[int, int]:
    """The two axes of a 3D point (or of an object's own frame) that span the ground plane:
    ``(0, 2)`` for Y up, ``(0, 1)`` for Z up."""
    _, (iu, _), (iv, _) = ground_axes(up_axis)
    return iu, iv


def to_ground(points, up_axis) -> np.ndarray:
    """(...,3) world points -> (...,2) ground coordinates, float64.

    Raises ValueError unless the points are ``(..., 3)`` and the up axis is Y or Z (either case).
    """
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ValueError(f"to_ground expects points of shape (..., 3), got {p.shape}")
    if up_token(up_axis) == "Z":
        return p[..., [0, 1]].copy()
    return np.stack([p[..., 0], -p[..., 2]], axis=-1)


def from_ground(uv, height, up_axis) -> np.ndarray:
    """(...,2) ground coordinates and heights along up (broadcast) -> (...,3) world points.

    Raises ValueError unless the points are ``(..., 2)`` and the up axis is Y or Z (either case).
    """
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape[-1:] != (2,):
        raise ValueError(f"from_ground expects ground points of shape (..., 2), got {uv.shape}")
    h = np.broadcast_to(np.asarray(height, dtype=np.float64), uv.shape[:-1])
    if up_token(up_axis) == "Z":
        return np.stack([uv[..., 0], uv[..., 1], h], axis=-1)
    return np.stack([uv[..., 0], h, -uv[..., 1]], axis=-1)


def height(points: np.ndarray, up_axis: str) -> np.ndarray:
    """(...,3) world points -> (...) heights, a copy: a view would keep every joint matrix
    the points were sliced from alive (10,000 trajectories: 350 MB)."""
    return np.asarray(points, dtype=np.float64)[..., up_index(up_axis)].copy()
