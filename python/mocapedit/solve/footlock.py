"""Foot locking: plant positions for foot contacts and two-bone leg IK (numpy, no USD).

After every other edit, each foot contact of the source clip gets one world plant: the
source foot carried by one rigid ground motion (a turn about the up axis and a ground
translation) chosen where the edited motion puts the foot during the contact, so that the
correction is the smallest (least squares). Inside the contact the foot follows its own
source motion (heel and toe roll) under that single motion, so it slides no more than the
source foot; over a few frames before and after, the weight ramps from 0 to 1.

The legs then reach their targets by the solver's ``FootLockJob`` (``_solver.lock_feet``):
pelvis lowered only where a leg cannot reach, analytic two-bone IK in the knee's plane,
the foot's world orientation blended towards its planted one. :func:`lock_feet_numpy` is
the same job in numpy: the benchmark measures the solver against it and the tests compare
them.

Arrays of the job, for #N poses (the output frames of all agents, agent after agent) and
two legs: positions (N,2,3) world, rotations (N,2,4) world quaternions (x, y, z, w) in
the Hamilton convention (``a * b`` rotates by b, then a), weights (N,2) in [0, 1].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry.animation import slerp
from mocapedit.geometry.kinematics import cross3, quat_conjugate, quat_multiply, quat_rotate

#: The fraction of a leg's full length beyond which a reach is softened (never snaps straight).
SOFT_REACH = 0.97
#: The largest fraction of a leg's full length an IK leg ever reaches.
MAX_REACH = 0.9995
#: Knee bends (sine of the angle between thigh and shin) below BEND_NOISE take their plane from
#: the hinge axis; above BEND_NOISE + BEND_TRUST, from the pose; in between, a blend.
BEND_NOISE = 0.05
BEND_TRUST = 0.2


@dataclass
class LegInputs:
    """The inputs of the foot-locking job for #N poses of #A agents, two legs each."""
    offsets: np.ndarray        # (A+1,) int64: agent a owns poses offsets[a]:offsets[a+1]
    smooth: np.ndarray         # (A,) int64: frames over which an agent's pelvis drop eases in and out
    up: np.ndarray             # (3,) world up, unit
    hip: np.ndarray            # (N,2,3) world positions before locking
    knee: np.ndarray
    ankle: np.ndarray
    parent_rot: np.ndarray     # (N,2,4) world rotation of each hip joint's parent
    hip_rot: np.ndarray        # (N,2,4) world rotations before locking
    knee_rot: np.ndarray
    ankle_rot: np.ndarray
    target: np.ndarray         # (N,2,3) planted ankle position
    target_rot: np.ndarray     # (N,2,4) planted ankle rotation
    weight: np.ndarray         # (N,2) how much of the plant to reach, in [0, 1]
    hinge: np.ndarray          # (N,2,3) the knee's hinge axis in world space (the normal of its bend plane)
    keep: np.ndarray | None = None  # (N,) uint8: poses the pelvis drop must not touch (stationary ranges)

    def arrays(self) -> dict[str, np.ndarray]:
        """The keyword arguments of ``_solver.lock_feet``, C-contiguous."""
        keep = np.zeros(len(self.hip), np.uint8) if self.keep is None else self.keep.astype(np.uint8)
        named = dict(offsets=self.offsets, smooth=self.smooth, up=self.up, hip=self.hip, knee=self.knee,
                     ankle=self.ankle, parent_rot=self.parent_rot, hip_rot=self.hip_rot, knee_rot=self.knee_rot,
                     ankle_rot=self.ankle_rot, target=self.target, target_rot=self.target_rot, weight=self.weight,
                     hinge=self.hinge, keep=keep)
        return {k: np.ascontiguousarray(v) for k, v in named.items()}


@dataclass
class LegOutputs:
    hip_local: np.ndarray      # (N,2,4) new joint-local rotations
    knee_local: np.ndarray
    ankle_local: np.ndarray
    drop: np.ndarray           # (N,) how far the pelvis is lowered along -up, stage units
    reached: np.ndarray        # (N,2,3) world ankle position after locking


def lock_feet(inputs: LegInputs) -> LegOutputs:
    """Runs the solver's FootLockJob (all agents, both legs)."""
    out = _solver.lock_feet(**inputs.arrays())
    return LegOutputs(out.hip_local, out.knee_local, out.ankle_local, out.drop, out.reached)


# ---- the job in numpy --------------------------------------------------------------------------


def normalize(v, eps=1e-12):
    """Vectors (or quaternions) along the last axis scaled to unit length (zero ones stay zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, eps)


def _arc(a, b):
    """Shortest-arc unit quaternions taking unit vectors a to b."""
    d = np.sum(a * b, axis=-1, keepdims=True)
    axis = cross3(a, b)
    # Opposite vectors: half a turn about any axis perpendicular to a.
    other = np.where(np.abs(a[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    flip = normalize(cross3(a, other))
    opposite = d < -1.0 + 1e-12
    q = np.where(opposite, np.concatenate([flip, np.zeros_like(d)], -1), np.concatenate([axis, 1.0 + d], -1))
    return normalize(q)


def _twist(axis, a, b):
    """Unit quaternions turning (…,3) a about the unit axis onto b's direction around it: with
    (c, s) the cosine and sine of that angle, (s axis, 1 + c) normalised."""
    c = np.sum(a * b, -1, keepdims=True)
    s = np.sum(cross3(a, b) * axis, -1, keepdims=True)
    r = np.hypot(c, s)
    none = r < 1e-300
    r = np.where(none, 1.0, r)
    c, s = np.where(none, 1.0, c / r), np.where(none, 0.0, s / r)
    half = 1.0 + c < 1e-12
    q = np.where(half, np.concatenate([axis, np.zeros_like(c)], -1), np.concatenate([axis * s, 1.0 + c], -1))
    return normalize(q)


def turn_legs_toward_plants(legs: dict, up: np.ndarray) -> dict:
    """The job's leg inputs (``hip``, ``knee``, ``ankle``, their rotations, ``hinge``,
    ``target_rot``, ``weight``) with each leg turned about ``up`` through its hip by the
    plant's turn against the edited foot, in proportion to ``weight``: a foot planted while the
    body turns over it stays turned with the leg above it, and the leg turns at the hip, as a
    person's does. The IK then only swings the leg to its target. Left turned with the body,
    the shin turned over the planted foot and twisted the ankle about the shin by as much as
    the plant lagged."""
    delta = quat_multiply(legs["target_rot"], quat_conjugate(legs["ankle_rot"]))
    angle = 2.0 * np.arctan2(np.sum(delta[..., :3] * up, axis=-1), delta[..., 3])
    angle = (angle + np.pi) % (2.0 * np.pi) - np.pi
    half = 0.5 * angle * legs["weight"]
    q = np.concatenate([np.sin(half)[..., None] * up, np.cos(half)[..., None]], axis=-1)
    out = dict(legs)
    hip = legs["hip"]
    for key in ("knee", "ankle"):
        out[key] = hip + quat_rotate(q, legs[key] - hip)
    for key in ("hip_rot", "knee_rot", "ankle_rot"):
        out[key] = quat_multiply(q, legs[key])
    out["hinge"] = quat_rotate(q, legs["hinge"])
    return out


def knee_hinge(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, knee_rot: np.ndarray) -> np.ndarray:
    """(...,3) a leg's knee hinge axis in the knee joint's own frame, learned from (T,...,3)
    positions and (T,...,4) world rotations of a clip (legs along the axes after the first): the
    normals of the bend planes, weighted by the square of the bend, so the clearly bent poses
    decide."""
    cross = cross3(knee - hip, ankle - hip)
    local = quat_rotate(quat_conjugate(np.asarray(knee_rot, dtype=np.float64)), cross)
    weight = np.linalg.norm(cross, axis=-1) / np.maximum(
        np.linalg.norm(knee - hip, axis=-1) * np.linalg.norm(ankle - knee, axis=-1), 1e-30)
    axis = np.sum(local * weight[..., None], axis=0)
    return np.where(np.linalg.norm(axis, axis=-1, keepdims=True) > 0, normalize(axis), np.array([1.0, 0.0, 0.0]))


def world_hinge(knee_rot: np.ndarray, local: np.ndarray) -> np.ndarray:
    """(...,3) the knee hinge in world space from (…,4) knee world rotations."""
    return quat_rotate(np.asarray(knee_rot, dtype=np.float64), np.broadcast_to(local, np.shape(knee_rot)[:-1] + (3,)))


def _frame_delta(u0, n0, u1, n1):
    """The rotation taking the orthonormal pair (u0, n0) to (u1, n1)."""
    q1 = _arc(u0, u1)
    return normalize(quat_multiply(_twist(u1, quat_rotate(q1, n0), n1), q1))


def required_drop(hip, target, reach, up):
    """(N,2) how far each hip must go down along ``up`` for its leg to reach its target."""
    v = hip - target
    vu = np.sum(v * up, -1)
    disc = vu * vu - np.sum(v * v, -1) + reach * reach
    s = np.where(disc >= 0, vu - np.sqrt(np.maximum(disc, 0.0)), vu)
    return np.maximum(s, 0.0)


def smooth_drop(required: np.ndarray, frames: int) -> np.ndarray:
    """A drop at least ``required`` everywhere, eased over ``frames``: a running maximum then a
    running mean over the same window (each mean covers its own frame's maximum)."""
    n = len(required)
    if n == 0 or frames <= 0 or not np.any(required > 0):
        return required.copy()
    padded = np.pad(required, frames)
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * frames + 1)
    peak = windows.max(axis=1)
    padded = np.pad(peak, frames, mode="edge")
    return np.convolve(padded, np.full(2 * frames + 1, 1.0 / (2 * frames + 1)), mode="valid")


def keep_ramp(keep: np.ndarray, frames: int) -> np.ndarray:
    """(T,) 0 at kept poses, rising linearly to 1 over ``frames`` + 1 poses away from them."""
    n = len(keep)
    index = np.arange(n, dtype=np.float64)
    kept = np.flatnonzero(keep)
    if not len(kept):
        return np.ones(n)
    distance = np.abs(index[:, None] - kept[None, :]).min(axis=1)
    return np.minimum(distance / (frames + 1), 1.0)


def lock_feet_numpy(inputs: LegInputs) -> LegOutputs:
    """:func:`lock_feet` in vectorised numpy (float64): the same results to within rounding."""
    up = np.asarray(inputs.up, dtype=np.float64)
    hip, knee, ankle = (np.asarray(a, dtype=np.float64) for a in (inputs.hip, inputs.knee, inputs.ankle))
    w = np.clip(np.asarray(inputs.weight, dtype=np.float64), 0.0, 1.0)[..., None]
    l1 = np.linalg.norm(knee - hip, axis=-1)
    l2 = np.linalg.norm(ankle - knee, axis=-1)
    full = l1 + l2
    target = ankle + w * (np.asarray(inputs.target, dtype=np.float64) - ankle)
    # A leg already stretched further than the soft limit in its own pose keeps that stretch.
    stretch = np.linalg.norm(ankle - hip, axis=-1)
    soft = np.maximum(stretch, SOFT_REACH * full)
    limit = np.maximum(stretch, MAX_REACH * full)

    drop = np.zeros(len(hip))
    required = required_drop(hip, target, soft, up).max(axis=1) if len(hip) else drop
    for a in range(len(inputs.offsets) - 1):
        lo, hi = int(inputs.offsets[a]), int(inputs.offsets[a + 1])
        drop[lo:hi] = smooth_drop(required[lo:hi], int(inputs.smooth[a]))
        if inputs.keep is not None and np.any(inputs.keep[lo:hi]):
            drop[lo:hi] *= keep_ramp(inputs.keep[lo:hi], int(inputs.smooth[a]))
    shift = -drop[:, None, None] * up
    hip, knee, ankle = hip + shift, knee + shift, ankle + shift

    # Reach: beyond the soft limit the excess is squeezed into what is left of the leg.
    to_target = target - hip
    dist = np.linalg.norm(to_target, axis=-1)
    room = np.maximum(limit - soft, 1e-12)
    squeezed = soft + room * (1.0 - np.exp(-(dist - soft) / room))
    reach = np.where(dist > soft, squeezed, dist)
    reach = np.maximum(reach, np.abs(l1 - l2) * 1.0001 + 1e-9)
    d = normalize(to_target)

    # The knee's plane: its normal from the pose before locking, kept perpendicular to the new
    # hip-ankle line; the knee bends to the same side as before (never backwards).
    # A nearly straight knee says little about its plane: there the hinge axis takes over.
    cross = cross3(knee - hip, ankle - hip)
    trust = np.clip((np.linalg.norm(cross, axis=-1) / np.maximum(l1 * l2, 1e-30) - BEND_NOISE) / BEND_TRUST, 0.0, 1.0)
    hinge = normalize(np.asarray(inputs.hinge, dtype=np.float64))
    normal = trust[..., None] * normalize(cross) + (1.0 - trust[..., None]) * hinge
    weak = np.linalg.norm(normal, axis=-1) < 1e-6
    normal = normalize(np.where(weak[..., None], hinge, normal))
    n1 = normalize(normal - np.sum(normal * d, -1, keepdims=True) * d)
    bend = cross3(d, n1)
    along = (l1 * l1 - l2 * l2 + reach * reach) / (2.0 * reach)
    height = np.sqrt(np.maximum(l1 * l1 - along * along, 0.0))
    new_knee = hip + along[..., None] * d + height[..., None] * bend
    new_ankle = hip + reach[..., None] * d

    u0 = normalize(knee - hip)
    n0 = normalize(normal - np.sum(normal * u0, -1, keepdims=True) * u0)
    u1 = normalize(new_knee - hip)
    hip_rot = quat_multiply(_frame_delta(u0, n0, u1, n1), inputs.hip_rot)
    v0 = normalize(ankle - knee)
    m0 = normalize(normal - np.sum(normal * v0, -1, keepdims=True) * v0)
    v1 = normalize(new_ankle - new_knee)
    knee_rot = quat_multiply(_frame_delta(v0, m0, v1, n1), inputs.knee_rot)
    ankle_rot = slerp(inputs.ankle_rot, inputs.target_rot, w[..., 0])

    def local(parent, child):
        q = normalize(quat_multiply(quat_conjugate(np.asarray(parent, dtype=np.float64)), child))
        return np.where(q[..., 3:] < 0, -q, q)

    return LegOutputs(local(inputs.parent_rot, hip_rot), local(hip_rot, knee_rot), local(knee_rot, ankle_rot),
                      drop, new_ankle)


__all__ = ["LegInputs", "LegOutputs", "lock_feet", "lock_feet_numpy", "required_drop", "smooth_drop", "knee_hinge",
           "world_hinge",
           "SOFT_REACH", "MAX_REACH"]
