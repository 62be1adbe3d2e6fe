"""The ground plane of a stage, from its upAxis.

Ground coordinates ``(u, v)`` are chosen so that ``u x v = up``: headings measured with
``atan2(v, u)`` turn counter-clockwise about the up axis.
- Y-up: ``u = x``, ``v = -z``
- Z-up: ``u = x``, ``v = y``
"""
from __future__ import annotations

import numpy as np


def up_index(up_axis: str) -> int:
    return 2 if up_axis == "Z" else 1


def to_ground(points: np.ndarray, up_axis: str) -> np.ndarray:
    """(...,3) world points -> (...,2) ground coordinates."""
    p = np.asarray(points, dtype=np.float64)
    if up_axis == "Z":
        return p[..., [0, 1]].copy()
    return np.stack([p[..., 0], -p[..., 2]], axis=-1)


def from_ground(uv: np.ndarray, height: np.ndarray | float, up_axis: str) -> np.ndarray:
    """(...,2) ground coordinates and heights -> (...,3) world points."""
    uv = np.asarray(uv, dtype=np.float64)
    h = np.broadcast_to(np.asarray(height, dtype=np.float64), uv.shape[:-1])
    if up_axis == "Z":
        return np.stack([uv[..., 0], uv[..., 1], h], axis=-1)
    return np.stack([uv[..., 0], h, -uv[..., 1]], axis=-1)


def height(points: np.ndarray, up_axis: str) -> np.ndarray:
    """(...,3) world points -> (...) heights, a copy: a view would keep every joint matrix
    the points were sliced from alive (10,000 trajectories: 350 MB)."""
    return np.asarray(points, dtype=np.float64)[..., up_index(up_axis)].copy()
