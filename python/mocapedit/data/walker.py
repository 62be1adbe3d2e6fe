"""Procedural humanoid clips: walk, run, idle, turn, and walk-stop-walk.

The clips stand in for motion capture in tests, examples and benchmarks. They
are built like captured locomotion is edited later on: a root joint that
carries the ground-plane motion and the heading, a hip joint that carries the
pelvis height, and legs solved with analytic two-bone IK towards planned
footsteps, so a stance foot stays exactly where it was planted.

Conventions (shared with the rest of mocapedit):

- Quaternions are numpy ``(x, y, z, w)`` float32, the layout of
  ``Vt.QuatfArray.FromNumpy``.
- Joint paths follow UsdSkel: ``Root``, ``Root/Hips``, ``Root/Hips/Spine``...
- Frames are 0-based sample indices; frame ``i`` is at ``i / fps`` seconds.
- Matrices returned here use column vectors (``p_world = M @ p_local``), the
  transpose of Gf's row-vector matrices.

The skeleton is built Y-up in metres. The character faces root-local +Z and
its left is root-local +X; a heading of ``theta`` rotates +Z towards +X about
the up axis. A Z-up clip is the same skeleton with a +90 degree rotation about
X folded into the root joint, so root-local +Y is world +Z there; lengths are
divided by ``meters_per_unit``.

This module uses numpy only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = [
    "Clip",
    "JOINTS",
    "walk",
    "run",
    "idle",
    "turn",
    "walk_idle_walk",
    "local_matrices",
    "rest_local_matrices",
    "rest_world_transforms",
    "world_transforms",
    "joint_world_positions",
    "quat_from_matrix",
    "quat_to_matrix",
]

# --- skeleton --------------------------------------------------------------

# (path, rest translation in metres, Y-up, parent frame). Rest rotations are
# identity: every bone frame is aligned with the root, legs and arms hang down.
_SKELETON: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("Root", (0.0, 0.0, 0.0)),
    ("Root/Hips", (0.0, 0.97, 0.0)),
    ("Root/Hips/LeftUpLeg", (0.09, -0.07, 0.0)),
    ("Root/Hips/LeftUpLeg/LeftLeg", (0.0, -0.42, 0.0)),
    ("Root/Hips/LeftUpLeg/LeftLeg/LeftFoot", (0.0, -0.40, 0.0)),
    ("Root/Hips/LeftUpLeg/LeftLeg/LeftFoot/LeftToe", (0.0, -0.06, 0.13)),
    ("Root/Hips/RightUpLeg", (-0.09, -0.07, 0.0)),
    ("Root/Hips/RightUpLeg/RightLeg", (0.0, -0.42, 0.0)),
    ("Root/Hips/RightUpLeg/RightLeg/RightFoot", (0.0, -0.40, 0.0)),
    ("Root/Hips/RightUpLeg/RightLeg/RightFoot/RightToe", (0.0, -0.06, 0.13)),
    ("Root/Hips/Spine", (0.0, 0.10, -0.01)),
    ("Root/Hips/Spine/Chest", (0.0, 0.20, 0.0)),
    ("Root/Hips/Spine/Chest/Neck", (0.0, 0.22, 0.0)),
    ("Root/Hips/Spine/Chest/Neck/Head", (0.0, 0.10, 0.01)),
    ("Root/Hips/Spine/Chest/LeftShoulder", (0.03, 0.18, 0.0)),
    ("Root/Hips/Spine/Chest/LeftShoulder/LeftArm", (0.14, 0.0, 0.0)),
    ("Root/Hips/Spine/Chest/LeftShoulder/LeftArm/LeftForeArm", (0.0, -0.28, 0.0)),
    ("Root/Hips/Spine/Chest/LeftShoulder/LeftArm/LeftForeArm/LeftHand", (0.0, -0.25, 0.0)),
    ("Root/Hips/Spine/Chest/RightShoulder", (-0.03, 0.18, 0.0)),
    ("Root/Hips/Spine/Chest/RightShoulder/RightArm", (-0.14, 0.0, 0.0)),
    ("Root/Hips/Spine/Chest/RightShoulder/RightArm/RightForeArm", (0.0, -0.28, 0.0)),
    ("Root/Hips/Spine/Chest/RightShoulder/RightArm/RightForeArm/RightHand", (0.0, -0.25, 0.0)),
)

JOINTS: tuple[str, ...] = tuple(p for p, _ in _SKELETON)
_INDEX = {p.rsplit("/", 1)[-1]: i for i, p in enumerate(JOINTS)}
_PARENTS = np.array([-1 if "/" not in p else JOINTS.index(p.rsplit("/", 1)[0])
                     for p in JOINTS], dtype=np.int32)
_REST_T = np.array([t for _, t in _SKELETON], dtype=np.float64)

_THIGH = float(np.linalg.norm(_REST_T[_INDEX["LeftLeg"]]))
_SHIN = float(np.linalg.norm(_REST_T[_INDEX["LeftFoot"]]))
# Ankle height above the ground with the foot flat (rest pose standing).
_ANKLE_HEIGHT = float(_REST_T[_INDEX["Hips"], 1] + _REST_T[_INDEX["LeftUpLeg"], 1]
                      - _THIGH - _SHIN)
# Stance legs never straighten fully: a straight knee is a singular IK pose.
_LEG_REACH = 0.99 * (_THIGH + _SHIN)

_FOOT_JOINTS = ("LeftFoot", "LeftToe", "RightFoot", "RightToe")


@dataclass
class Clip:
    """One skeletal animation clip on the procedural skeleton.

    Attributes:
        name: clip name, also the clip layer's file stem.
        joints: J joint paths, parents before children.
        parents: (J,) int32, index of each joint's parent, -1 for the root.
        rest_translations: (J, 3) float32 joint-local rest translations.
        rest_rotations: (J, 4) float32 joint-local rest rotations (x, y, z, w).
        translations: (F, J, 3) float32 joint-local translations per frame.
        rotations: (F, J, 4) float32 joint-local unit quaternions (x, y, z, w),
            sign-continuous from frame to frame.
        fps: samples per second; frame i is at time i / fps seconds.
        up_axis: "Y" or "Z", the up axis the clip is authored for.
        meters_per_unit: length of one translation unit in metres.
        foot_joints: paths of the joints that touch the ground (ankles, toes).
        foot_contacts: (F, len(foot_joints)) bool, True while that joint is
            planted (its position is then fixed in the clip's space).
    """

    name: str
    joints: list[str]
    parents: np.ndarray
    rest_translations: np.ndarray
    rest_rotations: np.ndarray
    translations: np.ndarray
    rotations: np.ndarray
    fps: float
    up_axis: str = "Y"
    meters_per_unit: float = 1.0
    foot_joints: tuple[str, ...] = ()
    foot_contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))

    @property
    def num_frames(self) -> int:
        return int(self.translations.shape[0])

    @property
    def num_joints(self) -> int:
        return len(self.joints)

    def joint_index(self, name: str) -> int:
        """Index of a joint given its full path or its last path element."""
        if name in self.joints:
            return self.joints.index(name)
        for i, path in enumerate(self.joints):
            if path.rsplit("/", 1)[-1] == name:
                return i
        raise KeyError(f"clip {self.name!r} has no joint {name!r}")


# --- small rotation helpers (numpy, vectorised over leading axes) ----------

def _rot_x(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1),
                     np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def _rot_y(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1),
                     np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def _rot_z(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1),
                     np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (x, y, z, w) -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions (x, y, z, w).

    Picks, per matrix, the largest of the four squared components to divide
    by, so it is stable for every rotation; the result has w >= 0.
    """
    m = np.asarray(m, dtype=np.float64)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    sq = np.stack([1 + m00 - m11 - m22, 1 - m00 + m11 - m22,
                   1 - m00 - m11 + m22, 1 + m00 + m11 + m22], -1)
    k = np.argmax(sq, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(sq, k[..., None], -1)[..., 0], 1e-300))
    d21 = m[..., 2, 1] - m[..., 1, 2]
    d02 = m[..., 0, 2] - m[..., 2, 0]
    d10 = m[..., 1, 0] - m[..., 0, 1]
    a01 = m[..., 0, 1] + m[..., 1, 0]
    a02 = m[..., 0, 2] + m[..., 2, 0]
    a12 = m[..., 1, 2] + m[..., 2, 1]
    cands = [
        np.stack([s / 4, a01 / s, a02 / s, d21 / s], -1),
        np.stack([a01 / s, s / 4, a12 / s, d02 / s], -1),
        np.stack([a02 / s, a12 / s, s / 4, d10 / s], -1),
        np.stack([d21 / s, d02 / s, d10 / s, s / 4], -1),
    ]
    q = np.choose(k[..., None], cands)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def _continuous(q: np.ndarray) -> np.ndarray:
    """Flip signs of (F, J, 4) quaternions so consecutive frames agree."""
    if q.shape[0] < 2:
        return q
    dots = np.einsum("fjk,fjk->fj", q[1:], q[:-1])
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    out = q.copy()
    out[1:] *= flips[..., None]
    return out


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _smooth(signal: np.ndarray, sigma_frames: float) -> np.ndarray:
    """Gaussian smoothing along axis 0 with edge padding."""
    if sigma_frames <= 0:
        return signal
    r = int(np.ceil(3 * sigma_frames))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_frames) ** 2)
    k /= k.sum()
    padded = np.concatenate([np.repeat(signal[:1], r, 0), signal, np.repeat(signal[-1:], r, 0)])
    return np.convolve(padded, k, mode="valid")


# --- kinematics ------------------------------------------------------------

def _compose(t: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(..., 3) translations and (..., 3, 3) rotations -> (..., 4, 4)."""
    m = np.zeros(t.shape[:-1] + (4, 4))
    m[..., :3, :3] = r
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


def local_matrices(clip: Clip) -> np.ndarray:
    """(F, J, 4, 4) float64 joint-local matrices (column vectors) of a clip."""
    return _compose(clip.translations.astype(np.float64), quat_to_matrix(clip.rotations))


def rest_local_matrices(clip: Clip) -> np.ndarray:
    """(J, 4, 4) float64 joint-local rest matrices (column vectors)."""
    return _compose(clip.rest_translations.astype(np.float64),
                    quat_to_matrix(clip.rest_rotations))


def _chain(local: np.ndarray, parents: np.ndarray) -> np.ndarray:
    world = np.empty_like(local)
    for j, p in enumerate(parents):
        world[..., j, :, :] = local[..., j, :, :] if p < 0 else (
            world[..., p, :, :] @ local[..., j, :, :])
    return world


def world_transforms(clip: Clip) -> np.ndarray:
    """(F, J, 4, 4) float64 skeleton-space joint matrices (column vectors).

    Skeleton space is the clip's own space (the space of UsdSkel's
    ComputeJointSkelTransforms); compose with an agent's transform to get
    world space.
    """
    return _chain(local_matrices(clip), clip.parents)


def rest_world_transforms(clip: Clip) -> np.ndarray:
    """(J, 4, 4) float64 skeleton-space rest matrices: UsdSkel bindTransforms."""
    return _chain(rest_local_matrices(clip), clip.parents)


def joint_world_positions(clip: Clip) -> np.ndarray:
    """(F, J, 3) float64 skeleton-space joint positions."""
    return world_transforms(clip)[..., :3, 3]


# --- gait description ------------------------------------------------------

@dataclass(frozen=True)
class _Gait:
    speed: float          # nominal root speed (m/s); 0 for standing
    cadence: float        # steps per second (both feet)
    duty: float           # fraction of a cycle each foot is on the ground
    lift: float           # peak ankle lift during swing (m)
    lateral: float        # half the distance between the feet (m)
    toe_out: float        # outward foot yaw (rad)
    height_support: float  # hip height target while a foot is down (m)
    height_flight: float  # hip height target while both feet are up (m)
    lean: float           # forward lean of the pelvis at full speed (rad)
    arm_swing: float      # arm swing per metre of foot separation (rad/m)
    elbow: float          # elbow flexion (rad)
    heel_time: float = 0.0   # how long before lift-off the heel rises (s)
    heel_pitch: float = 0.0  # foot roll about the toe at lift-off (rad)
    plant_at: float = 0.5    # fraction of the stance at which the body is over the ankle

    @property
    def period(self) -> float:
        return 2.0 / self.cadence

    @property
    def swing_time(self) -> float:
        return (1.0 - self.duty) * self.period


def _walk_gait(speed: float) -> _Gait:
    cadence = 1.0 + 0.7 * speed
    duty = 0.58
    return _Gait(speed=speed, cadence=cadence, duty=duty, lift=0.07,
                 lateral=0.1, toe_out=0.05, height_support=0.955, height_flight=0.955,
                 lean=0.03, arm_swing=0.45, elbow=0.25,
                 heel_time=0.4 * duty * 2.0 / cadence, heel_pitch=1.0, plant_at=0.37)


def _run_gait(speed: float) -> _Gait:
    cadence = 2.0 + 0.22 * speed
    duty = float(np.clip(0.5 - 0.04 * speed, 0.25, 0.45))
    return _Gait(speed=speed, cadence=cadence, duty=duty, lift=0.2,
                 lateral=0.07, toe_out=0.03, height_support=0.86, height_flight=0.93,
                 lean=0.07, arm_swing=0.6, elbow=1.35,
                 heel_time=0.5 * duty * 2.0 / cadence, heel_pitch=1.0, plant_at=0.4)


_IDLE_GAIT = _Gait(speed=0.0, cadence=1.0, duty=1.0, lift=0.0, lateral=0.11, toe_out=0.12,
                   height_support=0.955, height_flight=0.955, lean=0.0, arm_swing=0.0,
                   elbow=0.15)

# A root path: times (N,) -> ground position (N, 2) as (x, z), heading (N,), speed (N,).
_RootPath = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


def _arc_path(speed: float, turn_rate: float) -> _RootPath:
    """Constant speed (m/s) and turn rate (rad/s), starting at the origin facing +Z."""
    def path(t):
        theta = turn_rate * t
        if abs(turn_rate) < 1e-12:
            xz = np.stack([np.zeros_like(t), speed * t], -1)
        else:
            r = speed / turn_rate
            xz = np.stack([r * (1.0 - np.cos(theta)), r * np.sin(theta)], -1)
        return xz, theta, np.full_like(t, speed)
    return path


def _stop_go_path(speed: float, t_a: float, t_b: float, t_c: float, t_d: float) -> _RootPath:
    """Straight along +Z: full speed, ease out on [t_a, t_b], stand, ease in on [t_c, t_d]."""
    d1, d2 = t_b - t_a, t_d - t_c
    d_stop = speed * t_a + 0.5 * speed * d1

    def path(t):
        u1 = np.clip((t - t_a) / d1, 0.0, 1.0)
        u2 = np.clip((t - t_c) / d2, 0.0, 1.0)
        dist = np.where(t <= t_a, speed * t, d_stop - 0.5 * speed * d1
                        + speed * d1 * (u1 - (u1 ** 3 - 0.5 * u1 ** 4)))
        dist = np.where(t >= t_c, d_stop + speed * d2 * (u2 ** 3 - 0.5 * u2 ** 4), dist)
        dist = np.where(t >= t_d, d_stop + 0.5 * speed * d2 + speed * (t - t_d), dist)
        v = speed * np.where(t <= t_c, 1.0 - (3 * u1 ** 2 - 2 * u1 ** 3), 3 * u2 ** 2 - 2 * u2 ** 3)
        xz = np.stack([np.zeros_like(t), dist], -1)
        return xz, np.zeros_like(t), v
    return path


@dataclass
class _Stances:
    """Planned footholds of one foot: stance intervals and where it stands."""
    t0: list = field(default_factory=list)   # touch-down times (s)
    t1: list = field(default_factory=list)   # lift-off times (s)
    xz: list = field(default_factory=list)   # ankle ground position (x, z) (m)
    yaw: list = field(default_factory=list)  # foot heading (rad)

    def add(self, t0, t1, xz, yaw):
        self.t0.append(float(t0))
        self.t1.append(float(t1))
        self.xz.append((float(xz[0]), float(xz[1])))
        self.yaw.append(float(yaw))


def _side_offset(theta: np.ndarray, lateral: float) -> np.ndarray:
    """Ground offset (x, z) of `lateral` metres along the character's left."""
    return lateral * np.stack([np.cos(theta), -np.sin(theta)], -1)


def _plant(path: _RootPath, t_over: float, side: int, gait: _Gait):
    """Foothold beside the root as it is at time t_over: ankle (x, z) and yaw."""
    xz, theta, _ = path(np.array([t_over]))
    sign = 1.0 if side == 0 else -1.0
    return (xz[0] + _side_offset(theta, sign * gait.lateral)[0],
            theta[0] + sign * gait.toe_out)


def _periodic_stances(stances: _Stances, path: _RootPath, gait: _Gait, side: int,
                      phase: float, t_from: float, t_to: float) -> None:
    """Append the stances of a steady gait whose touch-down lies in [t_from, t_to].

    A foot is planted beside the root as it is at gait.plant_at of the
    stance, so the body passes over the ankle then; a little before
    mid-stance, because the heel rises and the foot rolls about the toe
    near the end of the stance.
    """
    period = gait.period
    offset = phase + 0.5 * side
    k = int(np.floor(t_from / period - offset)) - 1
    while True:
        t0 = (k + offset) * period
        k += 1
        if t0 < t_from - 1e-9:
            continue
        if t0 > t_to + 1e-9:
            break
        t1 = t0 + gait.duty * period
        xz, yaw = _plant(path, t0 + gait.plant_at * (t1 - t0), side, gait)
        stances.add(t0, t1, xz, yaw)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _foot_tracks(stances: _Stances, t: np.ndarray, gait: _Gait, root_xz: np.ndarray):
    """Foot targets of one foot at times t.

    Returns ankle position (N, 3), foot yaw (N,), foot pitch (N,), toe bend
    (N,), ankle contact (N,), toe contact (N,) and swing progress (N,; 0 in
    stance). A stance starts flat with the ankle exactly on its foothold;
    near its end the heel rises and the foot rolls about the planted toe;
    during a swing the ankle eases from the lift-off pose to the next foothold
    along an arc, carried along with the root in mid-swing.
    """
    t0 = np.asarray(stances.t0)
    t1 = np.asarray(stances.t1)
    xz = np.asarray(stances.xz)
    yaw = np.unwrap(np.asarray(stances.yaw))
    i = np.searchsorted(t0, t, side="right") - 1
    if np.any(i < 0) or np.any((t > t1[i]) & (i + 1 >= len(t0))):
        raise ValueError("footstep plan does not cover the clip")
    toe_contact = t <= t1[i] + 1e-12
    j = np.minimum(i + 1, len(t0) - 1)
    toe_off = _REST_T[_INDEX["LeftToe"]]
    heel_start = np.maximum(t0, t1 - gait.heel_time)
    ankle_contact = t <= heel_start[i] + 1e-12

    def ankle_on_toe(k, alpha):
        # Ankle position when foot k is rolled by alpha about its planted toe.
        flat = np.stack([xz[k, 0], np.full(len(k), _ANKLE_HEIGHT), xz[k, 1]], -1)
        ry = _rot_y(yaw[k])
        toe = flat + np.einsum("nij,j->ni", ry, toe_off)
        rolled = np.einsum("nij,j->ni", ry @ _rot_x(alpha), toe_off)
        return toe - rolled

    # Stance: roll about the toe from heel_start to lift-off.
    heel_span = np.maximum(t1[i] - heel_start[i], 1e-9)
    alpha = gait.heel_pitch * _smoothstep((t - heel_start[i]) / heel_span)
    stance_pos = ankle_on_toe(i, np.where(toe_contact, alpha, 0.0))

    # Swing: from the lift-off pose to the next foothold.
    span = np.where(toe_contact, 1.0, t0[j] - t1[i])
    u = np.where(toe_contact, 0.0, (t - t1[i]) / span)
    s = u - np.sin(2 * np.pi * u) / (2 * np.pi)   # zero velocity at both ends
    lift_off = ankle_on_toe(i, np.full(len(i), gait.heel_pitch))
    land = np.stack([xz[j, 0], np.full(len(j), _ANKLE_HEIGHT), xz[j, 1]], -1)
    # Interpolating in the world leaves the foot behind the body early in the
    # swing and ahead of it late; interpolating relative to the root follows
    # the body but starts and ends moving. Blend: world at the ends, root-
    # relative in the middle.
    swing_pos = lift_off + s[:, None] * (land - lift_off)
    t_lift = np.where(toe_contact, t, t1[i])
    t_land = np.where(toe_contact, t, t0[j])
    rel0 = lift_off[:, [0, 2]] - np.interp(t_lift, t, root_xz[:, 0])[:, None] * [1, 0] \
        - np.interp(t_lift, t, root_xz[:, 1])[:, None] * [0, 1]
    rel1 = land[:, [0, 2]] - np.interp(t_land, t, root_xz[:, 0])[:, None] * [1, 0] \
        - np.interp(t_land, t, root_xz[:, 1])[:, None] * [0, 1]
    carried = root_xz + rel0 + s[:, None] * (rel1 - rel0)
    b = np.sin(np.pi * u) ** 2
    swing_pos[:, [0, 2]] = (1 - b[:, None]) * swing_pos[:, [0, 2]] + b[:, None] * carried
    swing_pos[:, 1] += gait.lift * np.sin(np.pi * u) ** 2 * (1.0 + 0.5 * np.sin(np.pi * u))
    # Toes stay pointed down after push-off and come up before landing flat.
    swing_pitch = (gait.heel_pitch * (1.0 - _smoothstep(u / 0.5))
                   - 0.25 * u * np.sin(np.pi * u) ** 2)
    swing_toe = gait.heel_pitch * (1.0 - _smoothstep(u / 0.3))

    pos = np.where(toe_contact[:, None], stance_pos, swing_pos)
    pitch = np.where(toe_contact, alpha, swing_pitch)
    toe_bend = np.where(toe_contact, alpha, swing_toe)
    foot_yaw = yaw[i] + s * (yaw[j] - yaw[i])
    return pos, foot_yaw, pitch, toe_bend, ankle_contact, toe_contact, u


def _two_bone_ik(hip: np.ndarray, ankle: np.ndarray, pole: np.ndarray):
    """World rotations (N, 3, 3) of thigh and shin reaching ankle from hip.

    Bones point along their local -Y; the knee bends towards `pole` (N, 3)
    about the bones' shared local X axis, so the knee is a pure hinge.
    """
    d = ankle - hip
    dist = np.linalg.norm(d, axis=-1)
    dist_c = np.clip(dist, abs(_THIGH - _SHIN) + 1e-4, (_THIGH + _SHIN) * (1 - 1e-6))
    u = d / dist[:, None]
    a = (_THIGH ** 2 - _SHIN ** 2 + dist_c ** 2) / (2 * dist_c)
    h = np.sqrt(np.maximum(_THIGH ** 2 - a ** 2, 0.0))
    p = _normalize(pole - np.sum(pole * u, -1, keepdims=True) * u)
    knee = hip + a[:, None] * u + h[:, None] * p
    ankle_reached = hip + dist_c[:, None] * u

    def frame(top, bottom):
        y = _normalize(top - bottom)
        z = _normalize(p - np.sum(p * y, -1, keepdims=True) * y)
        x = np.cross(y, z)
        return np.stack([x, y, z], -1)

    return frame(hip, knee), frame(knee, ankle_reached)


# --- synthesis -------------------------------------------------------------

def _check(frames: int, fps: float, up: str, meters_per_unit: float,
           speed: float | None = None) -> None:
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    if up not in ("Y", "Z"):
        raise ValueError(f"up must be 'Y' or 'Z', got {up!r}")
    if not meters_per_unit > 0:
        raise ValueError(f"meters_per_unit must be positive, got {meters_per_unit}")
    if speed is not None and not speed > 0:
        raise ValueError(f"speed must be positive, got {speed}")


def _synthesize(name: str, frames: int, fps: float, path: _RootPath, gait: _Gait,
                feet: tuple[_Stances, _Stances], up: str, meters_per_unit: float,
                idle_phase: float = 0.0) -> Clip:
    # Work on a padded time grid so smoothing has no edge effects in the clip.
    pad = int(np.ceil(0.6 * fps))
    t = (np.arange(frames + 2 * pad) - pad) / fps
    n = t.shape[0]

    root_xz, theta, speed = path(t)
    moving = np.clip(speed / gait.speed, 0.0, 1.0) if gait.speed > 0 else np.zeros(n)

    tracks = [_foot_tracks(feet[s], t, gait, root_xz) for s in (0, 1)]
    ankles = [tr[0] for tr in tracks]
    contacts = [tr[5] for tr in tracks]   # the toe is down for the whole stance
    support = [_smooth(c.astype(np.float64), 0.12 * fps) for c in contacts]

    forward = np.stack([np.sin(theta), np.zeros(n), np.cos(theta)], -1)
    stride = np.sum((ankles[0] - ankles[1]) * forward, -1)   # left ahead of right (m)

    # Idle life: a slow weight shift, breathing, a little head motion.
    w_idle = 1.0 - moving
    idle_arg = 2 * np.pi * (t / 4.0 + idle_phase)
    idle_sway = 0.025 * np.sin(idle_arg)
    breathe = np.sin(2 * np.pi * (t / 3.3 + 0.37 * idle_phase))

    sway = 0.02 * (support[0] - support[1]) * moving + w_idle * idle_sway
    twist = -0.11 * stride + w_idle * 0.03 * np.sin(idle_arg + 1.1)
    roll = 0.04 * (support[0] - support[1]) * moving + w_idle * 0.5 * idle_sway
    lean = gait.lean * moving
    hips_local_r = _rot_y(twist) @ _rot_z(roll) @ _rot_x(lean)

    root_r = _rot_y(theta)
    root_t = np.stack([root_xz[:, 0], np.zeros(n), root_xz[:, 1]], -1)
    hips_r = root_r @ hips_local_r
    side_off = [_REST_T[_INDEX["LeftUpLeg"]], _REST_T[_INDEX["RightUpLeg"]]]
    # Hip joints with the pelvis at height 0 in the root frame.
    sway_t = np.einsum("nij,nj->ni", root_r, np.stack([sway, np.zeros(n), np.zeros(n)], -1))
    hip0 = [root_t + sway_t + np.einsum("nij,j->ni", hips_r, off) for off in side_off]

    # Pelvis height: the gait's target, lowered wherever a foot target would be
    # out of reach (the lowering is what makes the pelvis bob in a walk). In
    # mid-swing the limit is relaxed (the IK may then fall short of a foot in
    # the air), so that it stays continuous.
    # Eroding before smoothing keeps the smoothed height under the limit.
    any_support = np.maximum(support[0], support[1])
    target = (gait.height_flight + (gait.height_support - gait.height_flight) * any_support)
    target = target + w_idle * 0.004 * breathe
    cap = np.full(n, np.inf)
    for s in (0, 1):
        dh2 = np.sum((ankles[s][:, [0, 2]] - hip0[s][:, [0, 2]]) ** 2, -1)
        reach = ankles[s][:, 1] - hip0[s][:, 1] + np.sqrt(np.maximum(_LEG_REACH ** 2 - dh2, 0.0))
        slack = 0.3 * (1.0 - (1.0 - np.sin(np.pi * tracks[s][6])) ** 4)
        cap = np.minimum(cap, reach + slack)
    sigma = 0.035 * fps
    radius = int(np.ceil(3 * sigma))
    height = np.minimum(target, cap)
    padded = np.concatenate([np.repeat(height[:1], radius), height, np.repeat(height[-1:], radius)])
    eroded = np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1).min(-1)
    height = _smooth(eroded, sigma)

    hips_t_local = np.stack([sway, height, np.zeros(n)], -1)
    hips_world_t = root_t + np.einsum("nij,nj->ni", root_r, hips_t_local)

    world_r = np.empty((n, len(JOINTS), 3, 3))
    local_r = np.empty((n, len(JOINTS), 3, 3))
    local_r[:] = np.eye(3)
    local_r[:, 0] = root_r
    local_r[:, 1] = hips_local_r
    world_r[:, 0] = root_r
    world_r[:, 1] = hips_r
    for s, prefix in ((0, "Left"), (1, "Right")):
        hip = hips_world_t + np.einsum("nij,j->ni", hips_r, side_off[s])
        foot_yaw, pitch, toe_bend = tracks[s][1], tracks[s][2], tracks[s][3]
        pole = np.stack([np.sin(foot_yaw), np.zeros(n), np.cos(foot_yaw)], -1)
        thigh_r, shin_r = _two_bone_ik(hip, ankles[s], pole)
        foot_r = _rot_y(foot_yaw) @ _rot_x(pitch)
        iu, il, iff, it = (_INDEX[prefix + k] for k in ("UpLeg", "Leg", "Foot", "Toe"))
        local_r[:, iu] = np.swapaxes(hips_r, -1, -2) @ thigh_r
        local_r[:, il] = np.swapaxes(thigh_r, -1, -2) @ shin_r
        local_r[:, iff] = np.swapaxes(shin_r, -1, -2) @ foot_r
        local_r[:, it] = _rot_x(-toe_bend)   # the toes stay flat while the heel rises

    # Upper body: counter-rotate the chest against the pelvis, swing the arms
    # against the legs, keep the head steady.
    local_r[:, _INDEX["Spine"]] = (_rot_y(-0.5 * twist)
                                   @ _rot_x(-0.3 * lean + w_idle * 0.01 * breathe))
    local_r[:, _INDEX["Chest"]] = _rot_y(-0.8 * twist) @ _rot_z(-0.6 * roll)
    local_r[:, _INDEX["Neck"]] = _rot_y(0.15 * twist) @ _rot_x(-0.3 * lean)
    look = w_idle * 0.08 * np.sin(idle_arg * 0.7 + 0.4)
    local_r[:, _INDEX["Head"]] = (_rot_y(0.15 * twist + look)
                                  @ _rot_x(-0.4 * lean) @ _rot_z(-0.4 * roll))
    for s, prefix, sign in ((0, "Left", 1.0), (1, "Right", -1.0)):
        swing = sign * gait.arm_swing * stride * moving + w_idle * 0.02 * breathe
        spread = sign * (0.1 + 0.02 * w_idle * breathe)
        local_r[:, _INDEX[prefix + "Arm"]] = _rot_x(swing) @ _rot_z(spread)
        elbow = gait.elbow * (0.4 + 0.6 * moving) + 0.4 * np.maximum(-swing, 0.0)
        local_r[:, _INDEX[prefix + "ForeArm"]] = _rot_x(-elbow)

    keep = slice(pad, pad + frames)
    local_r = local_r[keep]
    translations = np.broadcast_to(_REST_T, (frames, len(JOINTS), 3)).copy()
    translations[:, 0] = root_t[keep]
    translations[:, 1] = hips_t_local[keep]
    contact = np.stack([tracks[0][4], tracks[0][5], tracks[1][4], tracks[1][5]], -1)[keep]
    rest_t = _REST_T.copy()
    rest_r = np.broadcast_to(np.eye(3), (len(JOINTS), 3, 3)).copy()

    if up == "Z":
        # Fold a +90 degree turn about X into the root: Y-up becomes Z-up.
        to_z = _rot_x(np.pi / 2)
        translations[:, 0] = translations[:, 0] @ to_z.T
        local_r[:, 0] = to_z @ local_r[:, 0]
        rest_r[0] = to_z @ rest_r[0]

    scale = 1.0 / meters_per_unit
    rotations = _continuous(quat_from_matrix(local_r)).astype(np.float32)
    return Clip(
        name=name,
        joints=list(JOINTS),
        parents=_PARENTS.copy(),
        rest_translations=(rest_t * scale).astype(np.float32),
        rest_rotations=quat_from_matrix(rest_r).astype(np.float32),
        translations=(translations * scale).astype(np.float32),
        rotations=rotations,
        fps=float(fps),
        up_axis=up,
        meters_per_unit=float(meters_per_unit),
        foot_joints=tuple(JOINTS[_INDEX[k]] for k in _FOOT_JOINTS),
        foot_contacts=contact,
    )


def _steady(name, frames, fps, speed, turn_rate_deg, phase, up, meters_per_unit, make_gait):
    _check(frames, fps, up, meters_per_unit, speed)
    gait = make_gait(speed)
    path = _arc_path(speed, np.radians(turn_rate_deg))
    t_lo, t_hi = -1.0 - 2 * gait.period, (frames - 1) / fps + 1.0 + gait.period
    feet = (_Stances(), _Stances())
    for side in (0, 1):
        _periodic_stances(feet[side], path, gait, side, phase, t_lo, t_hi)
    return _synthesize(name, frames, fps, path, gait, feet, up, meters_per_unit)


# --- public generators -----------------------------------------------------

def walk(frames: int = 120, fps: float = 24.0, speed: float = 1.4, up: str = "Y",
         meters_per_unit: float = 1.0, turn_rate: float = 0.0, phase: float = 0.0,
         name: str = "walk") -> Clip:
    """A steady walk starting at the origin facing +Z (Y-up) / -Y (Z-up).

    Args:
        frames: number of samples F.
        fps: samples per second.
        speed: root speed in metres per second.
        up: "Y" or "Z".
        meters_per_unit: metres per translation unit (0.01 for centimetres).
        turn_rate: heading change in degrees per second (positive turns
            left); 0 walks straight.
        phase: gait phase at time 0, in cycles (0..1); shifts the footfalls.
        name: clip name.
    """
    return _steady(name, frames, fps, speed, turn_rate, phase, up, meters_per_unit,
                   _walk_gait)


def turn(frames: int = 120, fps: float = 24.0, speed: float = 1.2, turn_rate: float = 30.0,
         up: str = "Y", meters_per_unit: float = 1.0, phase: float = 0.0,
         name: str = "turn") -> Clip:
    """A walk along a circular arc: `turn_rate` degrees per second, left if positive."""
    return walk(frames, fps, speed, up, meters_per_unit, turn_rate, phase, name)


def run(frames: int = 120, fps: float = 24.0, speed: float = 3.5, up: str = "Y",
        meters_per_unit: float = 1.0, turn_rate: float = 0.0, phase: float = 0.0,
        name: str = "run") -> Clip:
    """A steady run with a flight phase (both feet off the ground) every step.

    Arguments as for walk().
    """
    return _steady(name, frames, fps, speed, turn_rate, phase, up, meters_per_unit,
                   _run_gait)


def idle(frames: int = 120, fps: float = 24.0, up: str = "Y", meters_per_unit: float = 1.0,
         phase: float = 0.0, name: str = "idle") -> Clip:
    """Standing at the origin facing +Z (Y-up): the root never moves, the feet
    stay planted, the body sways and breathes.

    `phase` (cycles, 0..1) shifts the sway so several idlers differ.
    """
    _check(frames, fps, up, meters_per_unit)
    path = _arc_path(0.0, 0.0)
    t_end = (frames - 1) / fps + 10.0
    feet = (_Stances(), _Stances())
    for side in (0, 1):
        xz, yaw = _plant(path, 0.0, side, _IDLE_GAIT)
        feet[side].add(-10.0, t_end, xz, yaw)
    return _synthesize(name, frames, fps, path, _IDLE_GAIT, feet, up, meters_per_unit,
                       idle_phase=phase)


def walk_idle_walk(frames: int = 240, fps: float = 24.0, speed: float = 1.4,
                   stop_frame: int | None = None, idle_frames: int = 48, up: str = "Y",
                   meters_per_unit: float = 1.0,
                   name: str = "walk_idle_walk") -> tuple[Clip, tuple[int, int]]:
    """Walk, stop and stand, then walk on, all along +Z (Y-up).

    Args:
        stop_frame: first frame of the standing range (default frames // 3).
        idle_frames: number of frames the root stands still.
        Other arguments as for walk().

    Returns:
        (clip, (first, last)): the inclusive frame range during which the root
        does not move at all. The walk eases out into it and eases in after it,
        with both feet side by side while standing.
    """
    _check(frames, fps, up, meters_per_unit, speed)
    first = frames // 3 if stop_frame is None else int(stop_frame)
    last = first + int(idle_frames) - 1
    if not (0 < first <= last < frames - 1):
        raise ValueError(f"standing range ({first}, {last}) must lie inside frames 1..{frames - 2}")
    gait = _walk_gait(speed)
    period, swing = gait.period, gait.swing_time
    # Both feet are flat on the ground from `gap` before the root stops; the
    # heel of the leading foot starts to rise when the root starts again.
    gap, gap_out = 0.1, max(0.1, gait.heel_time)
    t_b, t_c = first / fps, last / fps
    t_a = t_b - (gap + swing + 0.5 * period)
    t_d = t_c + (gap_out + swing + 0.5 * period)
    path = _stop_go_path(speed, t_a, t_b, t_c, t_d)

    # The left foot steps to the stop first, the right one joins it; after the
    # standing range the left foot leads off again.
    right_lift = t_b - gap - swing
    left_lift = right_lift - 0.5 * period
    phase_in = (right_lift / period - 0.5 - gait.duty) % 1.0
    restart = t_c + gap_out + swing
    phase_out = (restart / period) % 1.0
    t_lo = -1.0 - 2 * period
    t_hi = (frames - 1) / fps + 1.0 + period
    feet = (_Stances(), _Stances())
    lifts = (left_lift, right_lift)
    stand_until = (t_c + gap_out, t_c + gap_out + 0.5 * period)
    for side in (0, 1):
        _periodic_stances(feet[side], path, gait, side, phase_in, t_lo,
                          lifts[side] - gait.duty * period)
        xz, yaw = _plant(path, t_b, side, gait)
        feet[side].add(lifts[side] + swing, stand_until[side], xz, yaw)
        _periodic_stances(feet[side], path, gait, side, phase_out,
                          stand_until[side] + swing, t_hi)
    clip = _synthesize(name, frames, fps, path, gait, feet, up, meters_per_unit)
    return clip, (first, last)
