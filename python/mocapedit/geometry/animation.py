"""Poses of a clip sampled at fractional frames, in the clip's own joint order.

A :class:`Pose` is what the time warp samples and the layering modifies before the
writer bakes it: translations interpolate linearly, rotations by normalised
shortest-arc slerp, scales linearly. The sampling runs in the solver
(:func:`sample_pose`); :func:`sample_pose_numpy` is the same in numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.model.data import Clip


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
    modulo the frame count, the last frame interpolating back to the first.

    Sampled by the solver (``_solver.sample_clip``); whole frames keep their authored
    values bit for bit.
    """
    frames = np.ascontiguousarray(frames, dtype=np.float64).reshape(-1)
    arrays = (clip.translations, clip.rotations, clip.scales)
    if loop:
        n = clip.frame_count
        frames = np.mod(frames, n)
        frames = np.where(frames >= n, 0.0, frames)  # mod of a tiny negative number can round up to n
        arrays = tuple(np.concatenate([a, a[:1]]) for a in arrays)  # frame n is frame 0 again
    t, r, s = _solver.sample_clip(*arrays, frames)
    return Pose(joints=list(clip.joints), translations=t, rotations=r, scales=s)


def sample_pose_numpy(clip: Clip, frames: np.ndarray) -> Pose:
    """:func:`sample_pose` in numpy: the reference the benchmark measures the solver against."""
    f = np.clip(np.asarray(frames, dtype=np.float64), 0, clip.frame_count - 1)
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, clip.frame_count - 1)
    a = (f - i0)
    exact = a == 0
    at = a[:, None, None]
    tr = clip.translations[i0] * (1 - at) + clip.translations[i1] * at
    sc = clip.scales[i0] * (1 - at) + clip.scales[i1] * at
    rot = slerp(clip.rotations[i0], clip.rotations[i1], np.broadcast_to(a[:, None], clip.rotations[i0].shape[:2]))
    # Whole frames keep their authored values bit for bit.
    tr[exact] = clip.translations[i0[exact]]
    sc[exact] = clip.scales[i0[exact]]
    rot = rot.astype(np.float32)
    rot[exact] = clip.rotations[i0[exact]]
    return Pose(joints=list(clip.joints), translations=tr.astype(np.float32), rotations=rot,
                scales=sc.astype(np.float32))


def interp_frames(values: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Linear interpolation of per-frame (F,...) values at fractional frames (clamped).
    Frames (A, T) interpolate the values (A, F, ...) of A agents, each at its own frames."""
    if np.ndim(frames) == 2:
        n = values.shape[1]
        f = np.clip(np.asarray(frames, dtype=np.float64), 0, n - 1)
        i0 = np.floor(f).astype(np.int64)
        i1 = np.minimum(i0 + 1, n - 1)
        a = (f - i0).reshape(f.shape + (1,) * (values.ndim - 2))
        rows = np.arange(len(values))[:, None]
        return values[rows, i0] * (1 - a) + values[rows, i1] * a
    n = values.shape[0]
    f = np.clip(np.asarray(frames, dtype=np.float64), 0, n - 1)
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, n - 1)
    a = (f - i0).reshape((-1,) + (1,) * (values.ndim - 1))
    return values[i0] * (1 - a) + values[i1] * a
