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
from mocapedit.geometry.trajectory import is_cut
from mocapedit.solve import collisions
from mocapedit.solve import plausibility as _plausibility
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
    "Plausibility", "plausibility_of", "plausibilities_of", "foot_skate_of_positions", "worst_plausibility",
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
    the clip (default: all). The other arguments are :func:`mocapedit.tools.measure.foot_skate`'s.
    Leading axes (``pos`` (..., T, F, 3), ``t`` and ``in_clip`` (..., T), ``contact`` (..., T, F))
    measure many agents at once, each on its own: the result's fields get the same leading
    axes, ``mean`` too (an array). A step faster than ``trajectory.CUT_SPEED_M`` is a cut, not
    a slide (a clip whose first frame is its rest pose at the origin): it counts for nothing."""
    t = np.asarray(t, dtype=np.float64)
    if contact_height is None:
        contact_height = 0.02 / meters_per_unit
    seconds_per_code = 1.0 / time_codes_per_second
    in_clip = np.ones(t.shape, dtype=bool) if in_clip is None else np.asarray(in_clip, dtype=bool)
    height = pos[..., ground_axes(up)[0]]
    if contact is not None:
        contact = np.asarray(contact, dtype=bool)
        if contact.shape != height.shape:
            raise ValueError(f"contact mask has shape {contact.shape}; expected {height.shape} "
                             "(times, feet)")
    else:
        # Within contact_height of the lowest height inside the clip (no contact without samples).
        lowest = np.where(in_clip[..., None], height, np.inf).min(axis=-2, keepdims=True, initial=np.inf)
        contact = in_clip[..., None] & (height - lowest <= contact_height)

    ground = to_ground(pos, up)
    step = np.linalg.norm(np.diff(ground, axis=-3), axis=-1)        # (..., T-1, F)
    dt = (np.diff(t, axis=-1) * seconds_per_code)[..., None]         # (..., T-1, 1)
    cut = is_cut(step, dt, meters_per_unit)
    both = contact[..., 1:, :] & contact[..., :-1, :] & ~cut
    slide = np.where(both, step, 0.0).sum(axis=-2)
    duration = np.where(both, dt, 0.0).sum(axis=-2)
    speeds = np.where(duration > 0, slide / np.where(duration > 0, duration, 1.0), np.nan)
    total = duration.sum(axis=-1)
    mean = np.where(total > 0, slide.sum(axis=-1) / np.where(total > 0, total, 1.0), np.nan)
    return FootSkate(tuple(joints), speeds, duration, contact, t, float(mean) if mean.ndim == 0 else mean)


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
    faces. Two clips of the same joint that differ by a yaw pick the same axis. Leading axes
    (..., T, 4, 4) are bodies measured each on its own: (..., T)."""
    return np.unwrap(_stationary.facing(np.asarray(matrices, dtype=np.float64), _up_token(up_axis)), axis=-1)


def facing_change_per_second(facing, seconds) -> np.ndarray:
    """(T-1,) unsigned turning rate of a facing between consecutive samples, degrees per second.
    ``facing`` (T,) radians; ``seconds`` (T,) increasing sample times in seconds. Leading axes:
    (..., T) -> (..., T-1)."""
    f, s = np.asarray(facing, dtype=np.float64), np.asarray(seconds, dtype=np.float64)
    if f.shape != s.shape or f.ndim < 1:
        raise ValueError(f"facing {f.shape} and seconds {s.shape} must both be (T,)")
    return _plausibility.turning_rates(f, s)


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


def _paths(source_ground, edited_ground, seconds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two ground paths ``(..., T, 2)`` and their sample times ``(..., T)``, paired by frame."""
    if np.ndim(source_ground) <= 2:
        s = _points(source_ground, "source_ground", dims=(2,))
        e = _points(edited_ground, "edited_ground", dims=(2,))
    else:
        s = np.asarray(source_ground, dtype=np.float64)
        e = np.asarray(edited_ground, dtype=np.float64)
    t = np.asarray(seconds, dtype=np.float64)
    if s.shape != e.shape or s.shape[-1] != 2 or t.shape != s.shape[:-1]:
        raise ValueError(f"source {s.shape}, edited {e.shape} and seconds {t.shape} must pair by frame")
    return s, e, t


def direction_deviation(source_ground, edited_ground, seconds, min_speed: float,
                        chord: float = CHORD_SECONDS, turn=None) -> np.ndarray:
    """(T,) angle (degrees, 0..180) between the edited and the source walking direction.

    The walking direction at frame i is the chord from i to the first frame at least ``chord``
    seconds later (``seconds``: (T,) source sample times). Frames where the source chord is
    slower than ``min_speed`` (stage units per second), and frames without a full chord, are NaN:
    the source does not walk there. Paths are ``(T, 2)`` ground points paired by frame.
    ``turn`` (T,) radians, counter-clockwise: the source direction at each chord's first frame
    is turned by it before comparing (:func:`edit_turn` gives the turn an edit means to make).
    Leading axes (paths (..., T, 2), times and turns (..., T)) are agents measured each on its own."""
    s, e, t = _paths(source_ground, edited_ground, seconds)
    if turn is not None and np.shape(turn) != t.shape:
        raise ValueError(f"turn {np.shape(turn)} must pair with seconds {t.shape}")
    return _plausibility.direction_deviation(s, e, t, min_speed, chord, turn)


def edit_turn(source_ground, edited_ground, seconds, min_speed: float,
              span: float = EDIT_TURN_SECONDS) -> np.ndarray:
    """(T,) the turn (radians, counter-clockwise, unwrapped) an edit gives a walk at each frame:
    the angle from the source's chord to the edited chord over ``span`` seconds centred on the
    frame (cut at the clip's ends). This is the turn the artist asks for (a group turned round a
    corner turns by 90 degrees); a walk that goes back against it over a short chord
    (:func:`direction_deviation` with ``turn``) hooks, zig-zags or loops. Where the source does
    not walk over the span (slower than ``min_speed``) the turn is interpolated from the frames
    around it where it does (held at the ends); 0 everywhere when it never does. A source that
    steps away and back over the span (its chord less than half its path) does not walk there
    either: such a chord points anywhere, and an edit that bends the step had it turn the walk
    by 108 degrees. Paths ``(T, 2)``,
    paired by frame; leading axes (..., T, 2) are agents measured each on its own."""
    s, e, t = _paths(source_ground, edited_ground, seconds)
    return _plausibility.edit_turn(s, e, t, min_speed, span)


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
    back against where the edit sends the agent. Where that turn is a guess (the source stands,
    or steps away and back, over the span: :func:`edit_turn`), the smaller of this and the
    deviation from the source as it is. ``max_edit_turn``: degrees, the largest turn the
    edit gives the walk (:func:`edit_turn`, over every span where the source walks, a step away
    and back included; a walk sent back turns by 180, a loop past it: a take sent round a loop
    where it wanders too).
    ``max_turn_off_curve``: degrees, for an agent on a path curve, the largest turn of its walk
    off the curve's own (:func:`edit_turn` of the path the curve draws against the edited
    path): the way along the curve is the artist's, so that is what a reversal is judged
    against instead of ``max_edit_turn`` (NaN when unknown).
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
    max_turn_off_curve: float = float("nan")

    @property
    def spins(self) -> bool:
        return self.spin_frames > 0

    @property
    def reverses(self) -> bool:
        """Walks back: more than 90 degrees away from its source direction as the edit turns it
        (``max_turned_deviation``: a hook, a zig-zag), or turned by the edit nearer to the way
        it came than to a right angle (``max_edit_turn`` over ``REVERSE_TURN_DEGREES``: sent
        back, or a loop). A deliberate turn of 90 degrees, the overshoot of its rounded corner
        included, is not a reversal. On a path curve the turn is judged off the curve's way
        (``max_turn_off_curve``): a curve drawn back along the take is walked the other way on
        purpose."""
        turn = self.max_turn_off_curve if np.isfinite(self.max_turn_off_curve) else self.max_edit_turn
        return bool(self.max_turned_deviation > 90.0 or turn > REVERSE_TURN_DEGREES)


def _ratio(edited, source):
    """Edited over source foot skate (arrays): NaN unless both are finite; 1 when both are 0."""
    edited, source = np.asarray(edited, dtype=np.float64), np.asarray(source, dtype=np.float64)
    ratio = np.where(source > 0, edited / np.where(source > 0, source, 1.0), np.where(edited == 0, 1.0, np.inf))
    return np.where(np.isfinite(edited) & np.isfinite(source), ratio, np.nan)


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
    :func:`mocapedit.tools.measure.plausibility` measures these on stages by FK;
    :func:`plausibilities_of` measures many agents at once."""
    def one(values):
        return None if values is None else np.asarray(values, dtype=np.float64)[None]
    return plausibilities_of([agent], one(source_seconds), one(source_hip), one(edited_seconds), one(edited_hip),
                             up_axis, meters_per_unit, one(foot_skate_source), one(foot_skate_edited),
                             one(edited_frames))[0]


def _runs(values, count: int, tail: tuple, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-agent arrays ``(T_a,) + tail`` (a sequence, or one array ``(A, T) + tail``) as one
    array of them all, agent after agent, and the (A+1,) offsets of each agent's run."""
    if isinstance(values, np.ndarray) and values.ndim == 2 + len(tail):
        values = np.asarray(values, dtype=np.float64)
        if values.shape[2:] != tail:
            raise ValueError(f"{name}: each agent's must have shape (T,{''.join(f' {d},' for d in tail)})")
        runs = [values.shape[1]] * len(values)
        joined = values.reshape((-1,) + tail)
    else:
        values = [np.asarray(v, dtype=np.float64) for v in values]
        runs = [len(v) for v in values]
        joined = np.concatenate(values).reshape((-1,) + tail) if values else np.zeros((0,) + tail)
        if any(v.shape != (n,) + tail for v, n in zip(values, runs)):
            raise ValueError(f"{name}: each agent's must have shape (T,{''.join(f' {d},' for d in tail)})")
    if len(runs) != count:
        raise ValueError(f"{name}: {len(runs)} agents' values for {count} agents")
    return joined, np.r_[0, np.cumsum(runs, dtype=np.int64)]


def in_shot(times: np.ndarray, start: float | None, end: float | None) -> np.ndarray:
    """(T,) the samples at ``times`` that play in the shot from ``start`` to ``end`` (the stage's
    time codes; None: open). An agent with fewer than two samples in the shot is measured on all
    of them (all True), so that it still has figures."""
    times = np.asarray(times, dtype=np.float64)
    keep = np.ones(times.shape, dtype=bool)
    if start is not None:
        keep &= times >= float(start) - 1e-9
    if end is not None:
        keep &= times <= float(end) + 1e-9
    return keep if keep.sum() >= 2 else np.ones(times.shape, dtype=bool)


def shot_window(keep: np.ndarray, frames: np.ndarray, frame_count: int) -> tuple[int, int]:
    """[first, end) of the source frames that the samples ``keep`` play (``frames``: the source
    frame each sample plays): the whole clip when every sample is kept."""
    if keep.all():
        return 0, frame_count
    played = np.asarray(frames, dtype=np.float64)[keep]
    first = int(np.clip(np.floor(played.min() + 1e-9), 0, frame_count - 1))
    return first, int(np.clip(np.ceil(played.max() - 1e-9), first, frame_count - 1)) + 1


def plausibilities_of(agents: Sequence[str], source_seconds, source_hip, edited_seconds, edited_hip, up_axis,
                      meters_per_unit: float, foot_skate_source=None, foot_skate_edited=None,
                      edited_frames=None) -> list[Plausibility]:
    """:func:`plausibility_of` of A agents at once: the arguments of :func:`plausibility_of`,
    one per agent (``source_seconds`` a sequence of (T,) arrays, ``source_hip`` of (T, 4, 4),
    ...; or arrays with a leading axis A when the agents have as many samples), the foot skate
    means (A,) (NaN by default). The figures, in the order of ``agents``, are those of each agent
    measured on its own, by one call of the solver's job
    (:func:`mocapedit.solve.plausibility.plausibility`)."""
    count = len(agents)
    ss, source_runs = _runs(source_seconds, count, (), "source_seconds")
    ms, hip_runs = _runs(source_hip, count, (4, 4), "source_hip")
    se, edited_runs = _runs(edited_seconds, count, (), "edited_seconds")
    me, edited_hip_runs = _runs(edited_hip, count, (4, 4), "edited_hip")
    if not (np.array_equal(source_runs, hip_runs) and np.array_equal(edited_runs, edited_hip_runs)):
        raise ValueError("each agent's seconds and facing joint matrices must pair sample by sample")
    frames = None
    if edited_frames is not None:
        frames, frame_runs = _runs(edited_frames, count, (), "edited_frames")
        if not np.array_equal(frame_runs, edited_runs):
            raise ValueError("each agent's edited_frames must pair with its edited_seconds")
    nan = np.full(count, np.nan)
    skate_s = nan if foot_skate_source is None else np.asarray(foot_skate_source, np.float64).reshape(count)
    skate_e = nan if foot_skate_edited is None else np.asarray(foot_skate_edited, np.float64).reshape(count)
    f = _plausibility.plausibility(
        source_runs, edited_runs, ss, ms, se, me, up_axis,
        _plausibility.Thresholds(walking_speed=WALKING_SPEED_M / meters_per_unit, chord=CHORD_SECONDS,
                                 edit_turn_span=EDIT_TURN_SECONDS, spin_rate=spin_threshold()),
        edited_frames=frames)
    skate_ratio = _ratio(skate_e, skate_s)
    return [Plausibility(agent=str(name), max_facing_rate=float(f.max_facing_rate[k]),
                         source_max_facing_rate=float(f.source_max_facing_rate[k]),
                         max_extra_facing_rate=float(f.max_extra_facing_rate[k]), spin_frames=int(f.spin_frames[k]),
                         max_direction_deviation=float(f.max_direction_deviation[k]),
                         length_ratio=float(f.length_ratio[k]),
                         time_warp=(float(f.time_warp_min[k]), float(f.time_warp_max[k])),
                         foot_skate_source=float(skate_s[k]), foot_skate_edited=float(skate_e[k]),
                         foot_skate_ratio=float(skate_ratio[k]), worst_turn_frame=int(f.worst_turn_frame[k]),
                         worst_direction_frame=int(f.worst_direction_frame[k]),
                         max_turned_deviation=float(f.max_turned_deviation[k]), max_edit_turn=float(f.max_edit_turn[k]))
            for k, name in enumerate(agents)]


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
