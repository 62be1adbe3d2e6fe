"""Quality measures for edited crowd motion ("what good means, measured").

Two families of functions live here:

* plain numpy measures of trajectories and time maps (path length, constraint residuals, shape
  change, rigidity of stationary ranges, capsule separation, positive time intervals);
* measures of joints' world positions and matrices (foot skate, plausibility of the body's
  turning and walking direction), which :mod:`mocapedit.usd.evaluate` computes from a composed
  stage by UsdSkel forward kinematics; :mod:`mocapedit.tools.measure` measures a stage in one call,
  so an edited stage is judged by what plain UsdSkel plays.

Conventions: positions are world space in stage units; quaternions, where they appear, are
``(x, y, z, w)``. The ground plane follows the stage's ``upAxis``: for Y-up the ground coordinates
of a point are ``(x, -z)``, for Z-up ``(x, y)``, so in both cases a heading angle is
counter-clockwise about the up axis.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from mocapedit.geometry.ground import from_ground, ground_axes, to_ground
from mocapedit.geometry.ground import up_token as _up_token
from mocapedit.geometry import stationary as _stationary
from mocapedit.solve import collisions
from mocapedit.geometry.shape import as_points as _points
from mocapedit.geometry.shape import length_ratio, local_coordinates, path_length, shape_change
from mocapedit.model.names import default_facing_joint, default_foot_joints

__all__ = [
    "ground_axes", "to_ground", "from_ground",
    "path_length", "length_ratio", "position_residuals",
    "local_coordinates", "shape_change", "rigidity_error", "neighbour_distance_change",
    "Separation", "capsule_clearance", "min_separation",
    "time_intervals_positive",
    "default_foot_joints", "FootSkate", "on_ground",
    "SPIN_DEGREES_AT_60FPS", "CHORD_SECONDS", "default_facing_joint",
    "body_facing", "facing_change_per_second", "spin_threshold", "spins", "direction_deviation",
    "Plausibility", "plausibility_of", "foot_skate_of_positions", "worst_plausibility",
]

# ---------------------------------------------------------------------------------------------
# Trajectory measures
# ---------------------------------------------------------------------------------------------


def position_residuals(points, targets) -> np.ndarray:
    """Euclidean distance of each point to its target: ``(N, d)``, ``(N, d)`` -> ``(N,)``."""
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(targets, dtype=np.float64)
    if p.shape != t.shape or p.ndim != 2:
        raise ValueError(f"points {p.shape} and targets {t.shape} must both be (N, d)")
    return np.linalg.norm(p - t, axis=1)


def _range_array(ranges, n: int) -> np.ndarray:
    r = np.asarray(ranges, dtype=np.int64)
    if r.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    r = r.reshape(-1, 2) if r.ndim == 1 and r.shape == (2,) else r
    if r.ndim != 2 or r.shape[1] != 2:
        raise ValueError(f"ranges must be (start, end) pairs, got shape {r.shape}")
    bad = (r[:, 0] < 0) | (r[:, 1] >= n) | (r[:, 0] > r[:, 1])
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"frame range {tuple(int(v) for v in r[k])} is not inside 0..{n - 1}")
    return r


def rigidity_error(source, edited, ranges) -> np.ndarray:
    """How far each stationary range is from moving by one rigid transform.

    ``source`` and ``edited`` are ``(N, 2)`` ground paths; ``ranges`` a sequence of inclusive
    ``(start, end)`` frame pairs. For each range the best rotation and translation (no scale, no
    reflection; least squares) taking the source points onto the edited ones is found, and the
    largest distance between a moved source point and its edited point is returned: ``(R,)``.
    """
    s = _points(source, "source", dims=(2,))
    e = _points(edited, "edited", dims=(2,))
    if s.shape != e.shape:
        raise ValueError(f"source {s.shape} and edited {e.shape} must have the same shape")
    r = _range_array(ranges, len(s))
    out = np.empty(len(r))
    for k, (a, b) in enumerate(r):
        ss, ee = s[a:b + 1], e[a:b + 1]
        sc, ec = ss - ss.mean(axis=0), ee - ee.mean(axis=0)
        cross = np.sum(sc[:, 0] * ec[:, 1] - sc[:, 1] * ec[:, 0])
        dot = np.sum(sc * ec)
        angle = np.arctan2(cross, dot)
        c, sn = np.cos(angle), np.sin(angle)
        fitted = np.stack((c * sc[:, 0] - sn * sc[:, 1], sn * sc[:, 0] + c * sc[:, 1]), axis=1)
        out[k] = np.max(np.linalg.norm(fitted - ec, axis=1))
    return out


def neighbour_distance_change(source, edited, neighbours: int = 3) -> np.ndarray:
    """How much a group's formation changed: relative change of neighbour distances.

    ``source`` and ``edited`` are ``(A, T, 2)`` ground positions of A agents at T shared times.
    At each time, each agent's ``neighbours`` nearest agents in the source are its neighbours;
    the result is ``(T, A, neighbours)`` of ``|d_edited - d_source| / d_source`` (take the mean
    for the average change). Pairs that coincide in the source are NaN.
    """
    s = np.asarray(source, dtype=np.float64)
    e = np.asarray(edited, dtype=np.float64)
    if s.shape != e.shape or s.ndim != 3 or s.shape[2] != 2:
        raise ValueError(f"source {s.shape} and edited {e.shape} must both be (agents, times, 2)")
    k = min(int(neighbours), s.shape[0] - 1)
    if k < 1:
        return np.zeros((s.shape[1], s.shape[0], 0))
    s, e = np.swapaxes(s, 0, 1), np.swapaxes(e, 0, 1)                  # (T, A, 2)
    ds = np.linalg.norm(s[:, :, None] - s[:, None], axis=-1)             # (T, A, A)
    de = np.linalg.norm(e[:, :, None] - e[:, None], axis=-1)
    far = np.where(np.eye(s.shape[1], dtype=bool), np.inf, ds)
    near = np.argsort(far, axis=2, kind="stable")[:, :, :k]
    d0 = np.take_along_axis(ds, near, axis=2)
    d1 = np.take_along_axis(de, near, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(d0 > 0, np.abs(d1 - d0) / np.where(d0 > 0, d0, 1.0), np.nan)


def time_intervals_positive(time_map, min_interval: float = 0.0) -> bool:
    """True when every interval of a time map is longer than ``min_interval`` (default: positive).

    ``time_map`` gives the shot time at which each source frame plays: ``(N,)`` for one agent or
    ``(A, N)`` for several (intervals along the last axis). A map with fewer than two frames has no
    interval and passes. NaN fails.
    """
    t = np.asarray(time_map, dtype=np.float64)
    if t.ndim not in (1, 2):
        raise ValueError(f"time_map must be (N,) or (A, N), got {t.shape}")
    if t.shape[-1] < 2:
        return True
    return bool(np.all(np.diff(t, axis=-1) > min_interval))


# ---------------------------------------------------------------------------------------------
# Capsule separation
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Separation:
    """Result of :func:`min_separation`.

    ``clearance``: smallest capsule clearance over all agent pairs and time samples, stage units
    (negative = the capsules overlap by that much; ``inf`` when no two agents are ever present at
    the same sample). ``agents``: the pair ``(a, b)``, ``a < b``, where it happens, and
    ``time_index`` the sample; both ``None`` with ``inf``. ``overlaps``: number of (pair, sample)
    combinations with negative clearance.
    """

    clearance: float
    agents: tuple[int, int] | None
    time_index: int | None
    overlaps: int


def _resting_base(base, radius, height):
    """Bases for the detection, whose capsules shorter than their diameter are spheres half way
    up, so that such a capsule is a sphere resting on its base here."""
    radius, height = np.asarray(radius, dtype=np.float64), np.asarray(height, dtype=np.float64)
    return base + np.where(height < 2.0 * radius, radius - 0.5 * height, 0.0)


def capsule_clearance(ground_a, base_a, radius_a, height_a, ground_b, base_b, radius_b, height_b):
    """Clearance between vertical capsules (broadcasting; stage units, negative = overlap).

    A capsule stands on ``base`` (its height along up), has total height ``height`` (at least
    ``2 * radius``: a shorter one is a sphere resting on its base) and radius ``radius``;
    ``ground`` is its ``(..., 2)`` ground position.
    """
    return collisions.capsule_clearance(ground_a, _resting_base(base_a, radius_a, height_a), radius_a, height_a,
                                        ground_b, _resting_base(base_b, radius_b, height_b), radius_b, height_b)


def min_separation(positions, radius, height, up_axis) -> Separation:
    """Smallest clearance between agents' vertical capsules over all time samples.

    ``positions`` ``(A, T, 3)``: each agent's capsule base (its ground point) per sample, world
    space; non-finite rows mean the agent is absent at that sample. ``radius`` and ``height``:
    ``(A,)`` or scalars, stage units, positive; a capsule spans ``height`` along up from its base
    (at least ``2 * radius``: a shorter one is a sphere resting on its base). The solve's detection
    (:func:`mocapedit.solve.collisions.detect_at`, a grid per sample) measures it: the clearances
    it finds are exact up to a reach, widened until some pair is within it.
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3:
        raise ValueError(f"positions must be (A, T, 3), got {p.shape}")
    n_agents, n_times = p.shape[:2]
    rad = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n_agents,))
    hgt = np.broadcast_to(np.asarray(height, dtype=np.float64), (n_agents,))
    if not (np.all(np.isfinite(rad)) and np.all(rad > 0) and np.all(np.isfinite(hgt)) and np.all(hgt > 0)):
        raise ValueError("capsule radius and height must be finite and positive")
    present = np.all(np.isfinite(p), axis=2)
    ground = to_ground(np.where(present[..., None], p, 0.0), up_axis)
    base = _resting_base(p[..., ground_axes(up_axis)[0]], rad[:, None], hgt[:, None])
    runs = collisions.sample_runs(present, base)
    if not runs:
        return Separation(float("inf"), None, None, 0)

    def detect(first, last, idx, margin, reach):
        return collisions.detect_at(np.ascontiguousarray(ground[idx, first:last].transpose(1, 0, 2)),
                                    rad[idx], hgt[idx], margin, report_distance=reach, base=base[idx, first])

    # At this reach every pair present at a sample is within it: the search ends there at the latest.
    widest = float(np.hypot(np.hypot(*np.ptp(ground[present], axis=0)), np.ptp(base[present]) + hgt.max()))
    reach, overlaps = 3.0 * float(rad.max()), None
    while True:
        best, at, count = np.inf, None, 0       # the smallest clearance, at its earliest sample
        for first, last, idx in runs:
            found = detect(first, last, idx, 0.0, reach)
            count += int(found.colliding_samples)
            c = float(found.min_clearance.min())
            if np.isfinite(c):
                t = first + int(found.min_clearance_sample[found.min_clearance == c].min())
                if c < best or (c == best and t < at[0]):
                    best, at = c, (t, idx)
        overlaps = count if overlaps is None else overlaps     # the same at every reach
        if at is not None or reach >= widest:
            break
        reach = min(8.0 * reach, widest)
    if at is None:
        return Separation(float("inf"), None, None, 0)
    # The pair itself: the intervals at that sample whose clearance is not above the minimum
    # (the first pair of the deepest when several tie).
    t, idx = at
    pairs = detect(t, t + 1, idx, 0.0 if best < 0 else float(np.nextafter(best, np.inf)), 0.0)
    k = int(np.argmax(pairs.depth))
    return Separation(best, (int(idx[pairs.agent_a[k]]), int(idx[pairs.agent_b[k]])), t, overlaps)


# ---------------------------------------------------------------------------------------------
# Forward kinematics on the composed stage
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FootSkate:
    """Result of :func:`foot_skate_of_positions` (and :func:`mocapedit.tools.measure.foot_skate`).

    ``joints``: the measured foot joints (paths in the skeleton). ``speeds``: per foot, mean
    horizontal speed while in contact, stage units per second (NaN without contact).
    ``contact_seconds``: per foot, how long it was measured in contact. ``contact``: ``(T, F)``
    contact flag per sample time. ``times``: the sample times used. ``mean``: over all feet, total
    horizontal slide during contact divided by total contact time (NaN when no foot touches).
    """

    joints: tuple[str, ...]
    speeds: np.ndarray
    contact_seconds: np.ndarray
    contact: np.ndarray
    times: np.ndarray
    mean: float


def foot_skate_of_positions(pos: np.ndarray, t: np.ndarray, up, meters_per_unit: float,
                            time_codes_per_second: float, joints: tuple[str, ...] = (),
                            in_clip: np.ndarray | None = None, contact_height: float | None = None,
                            contact: np.ndarray | None = None) -> FootSkate:
    """Foot skate (:func:`mocapedit.tools.measure.foot_skate`) of feet whose world positions are
    known: ``pos`` (T, F, 3) stage units at increasing time codes ``t`` (T,); ``in_clip`` (T,) marks the samples inside
    the clip (default: all). The other arguments are :func:`mocapedit.tools.measure.foot_skate`'s."""
    t = np.asarray(t, dtype=np.float64)
    if contact_height is None:
        contact_height = 0.02 / meters_per_unit
    seconds_per_code = 1.0 / time_codes_per_second
    in_clip = np.ones(len(t), dtype=bool) if in_clip is None else np.asarray(in_clip, dtype=bool)
    height = pos[..., ground_axes(up)[0]]
    if contact is not None:
        contact = np.asarray(contact, dtype=bool)
        if contact.shape != height.shape:
            raise ValueError(f"contact mask has shape {contact.shape}; expected {height.shape} "
                             "(times, feet)")
    elif in_clip.any():
        contact = np.zeros(height.shape, dtype=bool)
        lowest = height[in_clip].min(axis=0)
        contact = in_clip[:, None] & (height - lowest <= contact_height)
    else:
        contact = np.zeros(height.shape, dtype=bool)

    ground = to_ground(pos, up)
    step = np.linalg.norm(np.diff(ground, axis=0), axis=2)          # (T-1, F)
    dt = (np.diff(t) * seconds_per_code)[:, None]                    # (T-1, 1)
    both = contact[1:] & contact[:-1]
    slide = np.where(both, step, 0.0).sum(axis=0)
    duration = np.where(both, dt, 0.0).sum(axis=0)
    speeds = np.where(duration > 0, slide / np.where(duration > 0, duration, 1.0), np.nan)
    total = float(duration.sum())
    mean = float(slide.sum() / total) if total > 0 else float("nan")
    return FootSkate(tuple(joints), speeds, duration, contact, t, mean)


def on_ground(contact: np.ndarray, source: np.ndarray, edited: np.ndarray, up, meters_per_unit: float,
              contact_height: float | None = None) -> np.ndarray:
    """(T, F) the source's ``contact`` mask, less the samples where the edited foot is lifted more
    than ``contact_height`` (default 2 cm in stage units) above the source foot: a foot that an
    edit makes step is in the air there, and a foot in the air does not slide. ``source`` and
    ``edited`` are (T, F, 3) positions at the same samples."""
    if contact_height is None:
        contact_height = 0.02 / meters_per_unit
    axis = ground_axes(up)[0]
    return np.asarray(contact, dtype=bool) & (edited[..., axis] - source[..., axis] <= contact_height)


# ---------------------------------------------------------------------------------------------
# Plausibility: does the edited body turn and walk like its source?
# ---------------------------------------------------------------------------------------------

#: A body turning more than this in one frame at 60 fps spins (scaled with the frame rate:
#: 30 degrees per frame at 30 fps, 7.5 at 120 fps; that is 900 degrees per second).
SPIN_DEGREES_AT_60FPS = 15.0
#: Walking direction is measured on chords of this many seconds.
CHORD_SECONDS = 0.25
#: Ground speed (metres per second) below which the source is said not to walk.
WALKING_SPEED_M = 0.2
#: The turn an edit gives a walk is measured on chords of this many seconds, centred on each
#: frame: long enough to span a gait cycle and a rounded corner's overshoot, short enough to
#: follow a deliberate turn.
EDIT_TURN_SECONDS = 2.0
#: An edit that turns a walk by more than this (degrees) sends it back the way it came: half
#: way between a right-angle turn and a full reversal.
REVERSE_TURN_DEGREES = 135.0

def body_facing(matrices, up_axis) -> np.ndarray:
    """(T,) facing of a body from its hip (or root) joint's world matrices ``(T, 4, 4)``:
    the horizontal projection of the joint's local axis that stays the most horizontal over the
    clip (any joint convention works), radians counter-clockwise about up, unwrapped. Taken from
    the skeleton, never from the path: a side step or a turn on the spot faces where the body
    faces. Two clips of the same joint that differ by a yaw pick the same axis."""
    return np.unwrap(_stationary.facing(np.asarray(matrices, dtype=np.float64), _up_token(up_axis)))


def facing_change_per_second(facing, seconds) -> np.ndarray:
    """(T-1,) unsigned turning rate of a facing between consecutive samples, degrees per second.
    ``facing`` (T,) radians; ``seconds`` (T,) increasing sample times in seconds."""
    f = np.unwrap(np.asarray(facing, dtype=np.float64))
    s = np.asarray(seconds, dtype=np.float64)
    if f.shape != s.shape or f.ndim != 1:
        raise ValueError(f"facing {f.shape} and seconds {s.shape} must both be (T,)")
    dt = np.diff(s)
    if np.any(dt <= 0):
        raise ValueError("sample times must increase")
    return np.degrees(np.abs(np.diff(f))) / dt


def spin_threshold() -> float:
    """Turning rate (degrees per second) above which a body spins: 15 degrees per frame at
    60 fps, scaled with the frame rate."""
    return SPIN_DEGREES_AT_60FPS * 60.0


def spins(source_rate, edited_rate) -> np.ndarray:
    """(T-1,) bool: the edited body turns faster than :func:`spin_threshold` over an interval
    where its source does not (rates from :func:`facing_change_per_second`, paired by frame)."""
    s, e = np.asarray(source_rate, dtype=np.float64), np.asarray(edited_rate, dtype=np.float64)
    if s.shape != e.shape:
        raise ValueError(f"source rates {s.shape} and edited rates {e.shape} must pair by frame")
    limit = spin_threshold()
    return (e > limit) & (s <= limit)


def direction_deviation(source_ground, edited_ground, seconds, min_speed: float,
                        chord: float = CHORD_SECONDS, turn=None) -> np.ndarray:
    """(T,) angle (degrees, 0..180) between the edited and the source walking direction.

    The walking direction at frame i is the chord from i to the first frame at least ``chord``
    seconds later (``seconds``: (T,) source sample times). Frames where the source chord is
    slower than ``min_speed`` (stage units per second), and frames without a full chord, are NaN:
    the source does not walk there. Paths are ``(T, 2)`` ground points paired by frame.
    ``turn`` (T,) radians, counter-clockwise: the source direction at each chord's first frame
    is turned by it before comparing (:func:`edit_turn` gives the turn an edit means to make)."""
    s = _points(source_ground, "source_ground", dims=(2,))
    e = _points(edited_ground, "edited_ground", dims=(2,))
    t = np.asarray(seconds, dtype=np.float64)
    if s.shape != e.shape or t.shape != (len(s),):
        raise ValueError(f"source {s.shape}, edited {e.shape} and seconds {t.shape} must pair by frame")
    out = np.full(len(s), np.nan)
    if len(s) < 2:
        return out
    end = np.searchsorted(t, t + chord - 1e-9, side="left")
    ok = end < len(s)
    i = np.flatnonzero(ok)
    j = end[ok]
    ds, de = s[j] - s[i], e[j] - e[i]
    speed = np.linalg.norm(ds, axis=1) / (t[j] - t[i])
    walk = speed >= min_speed
    if turn is not None:
        a = np.asarray(turn, dtype=np.float64)
        if a.shape != t.shape:
            raise ValueError(f"turn {a.shape} must pair with seconds {t.shape}")
        c, n = np.cos(a[i]), np.sin(a[i])
        ds = np.stack((c * ds[:, 0] - n * ds[:, 1], n * ds[:, 0] + c * ds[:, 1]), axis=1)
    cross = ds[:, 0] * de[:, 1] - ds[:, 1] * de[:, 0]
    dot = np.einsum("ij,ij->i", ds, de)
    angle = np.degrees(np.abs(np.arctan2(cross, dot)))
    out[i[walk]] = angle[walk]
    return out


def edit_turn(source_ground, edited_ground, seconds, min_speed: float,
              span: float = EDIT_TURN_SECONDS) -> np.ndarray:
    """(T,) the turn (radians, counter-clockwise, unwrapped) an edit gives a walk at each frame:
    the angle from the source's chord to the edited chord over ``span`` seconds centred on the
    frame (cut at the clip's ends). This is the turn the artist asks for (a group turned round a
    corner turns by 90 degrees); a walk that goes back against it over a short chord
    (:func:`direction_deviation` with ``turn``) hooks, zig-zags or loops. Where the source does
    not walk over the span (slower than ``min_speed``) the turn is interpolated from the frames
    around it where it does (held at the ends); 0 everywhere when it never does. Paths ``(T, 2)``, paired by frame."""
    s = _points(source_ground, "source_ground", dims=(2,))
    e = _points(edited_ground, "edited_ground", dims=(2,))
    t = np.asarray(seconds, dtype=np.float64)
    if s.shape != e.shape or t.shape != (len(s),):
        raise ValueError(f"source {s.shape}, edited {e.shape} and seconds {t.shape} must pair by frame")
    if len(s) < 2:
        return np.zeros(len(s))
    a = np.searchsorted(t, t - 0.5 * span, side="left")
    b = np.minimum(np.searchsorted(t, t + 0.5 * span, side="right") - 1, len(s) - 1)
    ds, de = s[b] - s[a], e[b] - e[a]
    dt = np.maximum(t[b] - t[a], 1e-12)
    walk = (b > a) & (np.linalg.norm(ds, axis=1) / dt >= min_speed) & (np.linalg.norm(de, axis=1) > 0)
    if not walk.any():
        return np.zeros(len(s))
    angle = np.unwrap(np.arctan2(ds[walk, 0] * de[walk, 1] - ds[walk, 1] * de[walk, 0],
                                 np.einsum("ij,ij->i", ds[walk], de[walk])))
    return np.interp(np.arange(len(s)), np.flatnonzero(walk), angle)


@dataclass(frozen=True)
class Plausibility:
    """Plausibility figures of one agent, edited against its source (:func:`plausibility_of`).

    Turning rates are degrees per second of the body's facing (:func:`body_facing`):
    ``max_facing_rate`` of the edited body, ``source_max_facing_rate`` of the source,
    ``max_extra_facing_rate`` the largest excess of the edited rate over the source's at the same
    frame (divide by 60 for degrees per frame at 60 fps); ``spin_frames`` how many frames spin
    (:func:`spins`). ``max_direction_deviation``: degrees (:func:`direction_deviation`; NaN when
    the source never walks): against the source's direction as it is, so a group turned 90 degrees
    on purpose measures 90. ``max_turned_deviation``: degrees, against the source's direction
    turned by the edit's own turn (:func:`edit_turn`): a hook, zig-zag or small loop that walks
    back against where the edit sends the agent. ``max_edit_turn``: degrees, the largest turn the
    edit gives the walk (:func:`edit_turn`; a walk sent back turns by 180, a loop past it).
    ``length_ratio``: edited over source ground path of the facing joint.
    ``time_warp``: smallest and largest shot time per source time (from the time map when the
    caller gives ``edited_frames``, else the ratio of edited to source sample intervals). ``foot_skate_source``
    and ``foot_skate_edited``: mean foot speed in contact (stage units per second, over the
    source's contact frames), ``foot_skate_ratio`` their ratio (1 when both are 0).
    ``worst_turn_frame`` and ``worst_direction_frame``: the edited samples where those happen."""

    agent: str
    max_facing_rate: float
    source_max_facing_rate: float
    max_extra_facing_rate: float
    spin_frames: int
    max_direction_deviation: float
    length_ratio: float
    time_warp: tuple[float, float]
    foot_skate_source: float
    foot_skate_edited: float
    foot_skate_ratio: float
    worst_turn_frame: int = -1        # edited sample where the extra turn is largest (interval start)
    worst_direction_frame: int = -1   # edited sample where the direction deviates most (-1: none)
    max_turned_deviation: float = float("nan")
    max_edit_turn: float = 0.0

    @property
    def spins(self) -> bool:
        return self.spin_frames > 0

    @property
    def reverses(self) -> bool:
        """Walks back: more than 90 degrees away from its source direction as the edit turns it
        (``max_turned_deviation``: a hook, a zig-zag), or turned by the edit nearer to the way
        it came than to a right angle (``max_edit_turn`` over ``REVERSE_TURN_DEGREES``: sent
        back, or a loop). A deliberate turn of 90 degrees, the overshoot of its rounded corner
        included, is not a reversal."""
        return bool(self.max_turned_deviation > 90.0 or self.max_edit_turn > REVERSE_TURN_DEGREES)


def _resample(values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Per-sample ``values`` ``(N, ...)`` linearly interpolated at fractional sample indices."""
    values = np.asarray(values, dtype=np.float64)
    x = np.arange(len(values), dtype=np.float64)
    flat = values.reshape(len(values), -1)
    out = np.stack([np.interp(at, x, flat[:, c]) for c in range(flat.shape[1])], axis=1)
    return out.reshape((len(at),) + values.shape[1:])


def _pair(source: np.ndarray, count: int) -> np.ndarray:
    """Source samples paired with ``count`` edited samples: the same ones when the counts agree,
    else resampled over the clip by frame fraction (an edit that re-sampled the time)."""
    if len(source) == count:
        return source
    return _resample(source, np.linspace(0.0, len(source) - 1.0, count))


def _ratio(edited: float, source: float) -> float:
    if not (np.isfinite(edited) and np.isfinite(source)):
        return float("nan")
    if source > 0:
        return edited / source
    return 1.0 if edited == 0 else float("inf")


def plausibility_of(agent: str, source_seconds, source_hip, edited_seconds, edited_hip, up_axis,
                    meters_per_unit: float, foot_skate_source: float = float("nan"),
                    foot_skate_edited: float = float("nan"), edited_frames=None) -> Plausibility:
    """:class:`Plausibility` from the facing joint's world matrices of the source ``(T, 4, 4)``
    at ``source_seconds`` ``(T,)`` and of the edited agent ``(T', 4, 4)`` at ``edited_seconds``,
    and the two foot skate means (stage units per second). ``edited_frames`` ``(T',)``: the
    (fractional) source frame each edited sample plays, as a time warp knows it; the source is
    then compared at those frames and the time warp is shot time per source time. Without it,
    edited samples pair with source samples by frame (resampled by frame fraction when T'
    differs) and the time warp is the ratio of their intervals.
    :func:`mocapedit.tools.measure.plausibility` measures these on stages by FK."""
    ss, se = np.asarray(source_seconds, np.float64), np.asarray(edited_seconds, np.float64)
    ms, me = np.asarray(source_hip, np.float64), np.asarray(edited_hip, np.float64)
    fs, fe = body_facing(ms, up_axis), body_facing(me, up_axis)
    gs, ge = to_ground(ms[:, 3, :3], up_axis), to_ground(me[:, 3, :3], up_axis)
    if len(se) >= 2 and len(ss) >= 2:
        rate_e = facing_change_per_second(fe, se)
        if edited_frames is None:
            rate_s = _pair(facing_change_per_second(fs, ss), len(rate_e))
            warp = np.diff(se) / _pair(np.diff(ss), len(se) - 1)
            gs_at, ss_at = _pair(gs, len(ge)), _pair(ss, len(se))
        else:
            f = np.asarray(edited_frames, dtype=np.float64)
            if f.shape != se.shape:
                raise ValueError(f"edited_frames {f.shape} must pair with edited_seconds {se.shape}")
            # The source's turn over each edited interval, per second of the source.
            d_frames = np.diff(f)
            moving = d_frames > 1e-9
            src_turn = np.abs(np.diff(_resample(fs, f)))
            src_dt = np.diff(_resample(ss, f))
            rate_s = np.where(moving, np.degrees(src_turn) / np.where(moving, src_dt, 1.0), 0.0)
            warp = (np.diff(se) / np.where(moving, src_dt, 1.0))[moving] if moving.any() else np.ones(1)
            gs_at, ss_at = _resample(gs, f), _resample(ss, f)
        turn_frame = int(np.argmax(rate_e - rate_s))
        extra = float(rate_e[turn_frame] - rate_s[turn_frame])
        spin = int(np.count_nonzero(spins(rate_s, rate_e)))
        # Held ends of a warped clip: measure on the frames that advance.
        keep = np.r_[True, np.diff(ss_at) > 0]
        walking = WALKING_SPEED_M / meters_per_unit
        dev, turned = np.full(len(ge), np.nan), np.full(len(ge), np.nan)
        turn = edit_turn(gs_at[keep], ge[keep], ss_at[keep], walking)
        dev[keep] = direction_deviation(gs_at[keep], ge[keep], ss_at[keep], walking)
        turned[keep] = direction_deviation(gs_at[keep], ge[keep], ss_at[keep], walking, turn=turn)
        dev_frame = int(np.nanargmax(dev)) if np.isfinite(dev).any() else -1
        max_dev = float(dev[dev_frame]) if dev_frame >= 0 else float("nan")
        max_turned = float(np.nanmax(turned)) if np.isfinite(turned).any() else float("nan")
        max_turn = float(np.degrees(np.abs(turn).max(initial=0.0)))
        rates = (float(rate_e.max()), float(rate_s.max()))
        warp_range = (float(warp.min()), float(warp.max()))
    else:
        rates, extra, spin, max_dev, warp_range = (0.0, 0.0), 0.0, 0, float("nan"), (1.0, 1.0)
        max_turned, max_turn = float("nan"), 0.0
        turn_frame, dev_frame = -1, -1
    return Plausibility(agent=str(agent), max_facing_rate=rates[0], source_max_facing_rate=rates[1],
                        max_extra_facing_rate=extra, spin_frames=spin, max_direction_deviation=max_dev,
                        length_ratio=length_ratio(ge, gs),
                        time_warp=warp_range, foot_skate_source=float(foot_skate_source),
                        foot_skate_edited=float(foot_skate_edited),
                        foot_skate_ratio=_ratio(float(foot_skate_edited), float(foot_skate_source)),
                        worst_turn_frame=turn_frame, worst_direction_frame=dev_frame,
                        max_turned_deviation=max_turned, max_edit_turn=max_turn)


def worst_plausibility(figures: Sequence[Plausibility]) -> dict:
    """The shot's worst figures over agents' :class:`Plausibility`: the largest extra facing rate
    (degrees per second, and per frame at 60 fps) and its agent, how many agents spin, the largest
    direction deviation and its agent, the largest deviation from the direction the edit turns the
    walk to (``maxTurnedDirectionDeviation``) and its agent, the largest turn an edit gives a walk
    (``maxEditTurn``), how many agents reverse
    (:attr:`Plausibility.reverses`), the mean and
    extreme path length ratios, the time-warp range, and the mean and largest foot skate ratio."""
    figs = list(figures)
    if not figs:
        return {"agents": 0}
    extra = max(figs, key=lambda f: f.max_extra_facing_rate)
    devs = [f for f in figs if np.isfinite(f.max_direction_deviation)]
    dev = max(devs, key=lambda f: f.max_direction_deviation) if devs else None
    turned = [f for f in figs if np.isfinite(f.max_turned_deviation)]
    back = max(turned, key=lambda f: f.max_turned_deviation) if turned else None
    lengths = np.array([f.length_ratio for f in figs])
    skates = np.array([f.foot_skate_ratio for f in figs])
    skates = skates[np.isfinite(skates)]
    return {
        "agents": len(figs),
        "maxExtraFacingRate": extra.max_extra_facing_rate,
        "maxExtraTurnPerFrameAt60fps": extra.max_extra_facing_rate / 60.0,
        "maxExtraFacingRateAgent": extra.agent,
        "spinningAgents": sum(f.spins for f in figs),
        "maxDirectionDeviation": dev.max_direction_deviation if dev else float("nan"),
        "maxDirectionDeviationAgent": dev.agent if dev else None,
        "maxTurnedDirectionDeviation": back.max_turned_deviation if back else float("nan"),
        "maxTurnedDirectionDeviationAgent": back.agent if back else None,
        "maxEditTurn": max(f.max_edit_turn for f in figs),
        "reversingAgents": sum(f.reverses for f in figs),
        "meanLengthRatio": float(lengths.mean()),
        "lengthRatioRange": (float(lengths.min()), float(lengths.max())),
        "timeWarpRange": (min(f.time_warp[0] for f in figs), max(f.time_warp[1] for f in figs)),
        "meanFootSkateRatio": float(skates.mean()) if len(skates) else float("nan"),
        "maxFootSkateRatio": float(skates.max()) if len(skates) else float("nan"),
    }
