"""Poses of a clip sampled at fractional frames, in the clip's own joint order (numpy).

A :class:`Pose` is what the time warp samples and the layering modifies before the
writer bakes it: translations interpolate linearly, rotations by normalised
shortest-arc slerp, scales linearly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import Clip


@dataclass
class Pose:
    joints: list[str]
    translations: np.ndarray   # (T,J,3) float32
    rotations: np.ndarray      # (T,J,4) float32 (x,y,z,w)
    scales: np.ndarray         # (T,J,3) float32


def slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Normalised shortest-arc slerp of (...,4) quaternions by (...) weights."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6
    w0 = np.where(small, 1 - t, np.sin((1 - t) * theta) / np.where(small, 1, sin))
    w1 = np.where(small, t, np.sin(t * theta) / np.where(small, 1, sin))
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def sample_pose(clip: Clip, frames: np.ndarray, loop: bool = False) -> Pose:
    """The clip at fractional frame positions: clamped to the clip, or with ``loop`` taken
    modulo the frame count, the last frame interpolating back to the first."""
    n = clip.frame_count
    if loop:
        f = np.mod(np.asarray(frames, dtype=np.float64), n)
        f = np.where(f >= n, 0.0, f)  # mod of a tiny negative number can round up to n
    else:
        f = np.clip(np.asarray(frames, dtype=np.float64), 0, n - 1)
    i0 = np.floor(f).astype(np.int64)
    i1 = (i0 + 1) % n if loop else np.minimum(i0 + 1, n - 1)
    a = f - i0
    # Whole frames keep their authored values bit for bit; only the others are interpolated.
    tr, rot, sc = clip.translations[i0], clip.rotations[i0], clip.scales[i0]
    part = np.flatnonzero(a != 0)
    if part.size:
        j0, j1, at = i0[part], i1[part], a[part][:, None, None]
        tr[part] = clip.translations[j0] * (1 - at) + clip.translations[j1] * at
        sc[part] = clip.scales[j0] * (1 - at) + clip.scales[j1] * at
        rot[part] = slerp(clip.rotations[j0], clip.rotations[j1],
                          np.broadcast_to(at[..., 0], clip.rotations[j0].shape[:2]))
    return Pose(joints=list(clip.joints), translations=tr.astype(np.float32, copy=False),
                rotations=rot.astype(np.float32, copy=False), scales=sc.astype(np.float32, copy=False))


def interp_frames(values: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Linear interpolation of per-frame (F,...) values at fractional frames (clamped)."""
    n = values.shape[0]
    f = np.clip(np.asarray(frames, dtype=np.float64), 0, n - 1)
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, n - 1)
    a = (f - i0).reshape((-1,) + (1,) * (values.ndim - 1))
    return values[i0] * (1 - a) + values[i1] * a
