"""Where planted feet go while an edit drags the body (numpy, no USD).

Foot locking gives each contact one plant: the source foot carried by one turn and one ground
shift. While the edited foot stays within a leash of the plant (as far as the leg reaches,
and a few degrees of turn), the plant stays put. Where an edit drags the body further:

- :func:`leash` lets the plant follow at the leash's length, from the start that slides least
  (the foot then slides that much, which the legs cannot avoid while they bear the weight);
- :func:`replant` lets a foot step instead, the way a person standing still and pushed or
  turned shuffles: while the other foot bears the weight, the foot lifts, moves to where the
  body now is (a little ahead of where it drifts) and is set down, one foot at a time. A foot
  in the air does not slide.

Offsets, plants and radii are in stage units, turns in radians; frames are the agent's.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import kinematics
from mocapedit.solve.footlock import normalize
from mocapedit.geometry.kinematics import quat_conjugate, quat_multiply

__all__ = ["follow", "leash", "leash_rows", "Replant", "replant", "step_profile", "step_frames", "against_hip", "lift_bend",
           "PlantInputs", "PlantOutputs", "plan_feet", "plan_feet_numpy", "place", "place_numpy", "reach", "turn_speed", "yaw_quat"]


def follow(offset: np.ndarray, radius: np.ndarray, run: np.ndarray, start: np.ndarray, out: np.ndarray) -> float:
    """Writes to ``out[run]`` a plant that starts at ``start`` and is dragged along, in the order
    of ``run``, wherever ``offset`` lies further than ``radius`` from it; returns how far it
    slides from the first frame of ``run`` on."""
    current = np.array(start, dtype=np.float64)
    slide = 0.0
    for k, i in enumerate(run):
        v = offset[i] - current
        d = float(np.linalg.norm(v))
        if d > radius[i]:
            moved = offset[i] - v * (radius[i] / d)
            if k:
                slide += float(np.linalg.norm(moved - current))
            current = moved
        out[i] = current
    return slide


def leash(offset: np.ndarray, base: np.ndarray, inside: np.ndarray, rigid: np.ndarray,
          radius: np.ndarray) -> np.ndarray:
    """(T,D) plant shifts (or turns, D = 1) over one contact (frames ``inside``, increasing).

    The plant stays at ``base`` while the edited foot (``offset``, (T,D)) stays within ``radius``
    ((T,) or a number) of it; where the edit drags the body further (a long idle moved by a path
    edit), the plant follows at that distance, so the legs never stretch beyond it, from the
    start that slides least. Frames ``rigid`` (a stationary range, inside the contact) keep
    ``base``, and the plant is followed from them outwards. Frames before and after the contact
    take its first and last plant."""
    out = np.broadcast_to(base, offset.shape).copy()
    radius = np.broadcast_to(radius, offset.shape[:1])
    if not len(inside) or np.all(np.linalg.norm(offset[inside] - base, axis=-1) <= radius[inside]):
        return out
    if len(rigid):
        for run in (inside[inside < rigid[0]][::-1], inside[inside > rigid[-1]]):
            follow(offset, radius, run, base, out)
    else:
        # Followed from ``base``, the plant may slide where another start would let it slide
        # less: the plant where that path ends, followed back to the contact's start, is the
        # start that slides least along a line (a turn is one), and it is kept only where it
        # slides less.
        slide = follow(offset, radius, inside, base, out)
        back = out.copy()
        follow(offset, radius, inside[::-1], out[inside[-1]], back)
        other = out.copy()
        if follow(offset, radius, inside, back[inside[0]], other) < slide - 1e-9 * max(float(radius.max()), 1.0):
            out = other
    out[:inside[0]] = out[inside[0]]
    out[inside[-1] + 1:] = out[inside[-1]]
    return out


def leash_rows(offset: np.ndarray, base: np.ndarray, inside: np.ndarray, rigid: np.ndarray,
               radius: np.ndarray) -> np.ndarray:
    """:func:`leash` for many contacts at once: (C,W,D) offsets, (C,D) bases, (C,W) masks and
    radii (or a number)."""
    out = np.broadcast_to(base[:, None], offset.shape).copy()
    radius = np.broadcast_to(radius, inside.shape)
    far = (inside & (np.linalg.norm(offset - base[:, None], axis=-1) > radius)).any(axis=1)
    for c in np.flatnonzero(far):
        out[c] = leash(offset[c], base[c], np.flatnonzero(inside[c]), np.flatnonzero(rigid[c]), radius[c])
    return out


#: Where a step moves over the ground: between these fractions of its time, while the foot is up.
_MOVE = (0.25, 0.75)


def step_profile(frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(progress, lift) at the ``frames`` + 1 frames of a step, both in [0, 1]: the foot lifts
    (``sin`` squared: it leaves and meets the ground gently, so a straight knee bends gently),
    moves over the ground only while it is well up (a smoothstep over the middle half) and is set
    down."""
    s = np.linspace(0.0, 1.0, frames + 1)
    x = np.clip((s - _MOVE[0]) / (_MOVE[1] - _MOVE[0]), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x), np.sin(np.pi * s) ** 2


def against_hip(step: np.ndarray, drift: np.ndarray) -> float:
    """The ground distance a step moves its foot as the hip sees it at the step's fastest: ``step``
    (D,) from the plant to the landing, while the body drifts by ``drift`` (D,) over the step.
    The foot moves over the ground at up to 1.5 / (width of ``_MOVE``) times its mean speed there,
    the hip at its mean all along, so the peak against the hip is that of ``step`` less
    ``drift`` times (width / 1.5): a foot stepping along with a dragged body moves slower against
    its hip than over the ground."""
    return float(np.linalg.norm(np.asarray(step) - np.asarray(drift) * ((_MOVE[1] - _MOVE[0]) / 1.5)))


def step_frames(distance: float, turn: float, height: float, bend: float, speed: float, spin: float,
                knee_spin: float, seconds: float, shortest: int) -> int:
    """Frames a step takes (at least ``shortest``) so that the foot moves no faster than ``speed``
    (stage units per second) against its hip and turns no faster than ``spin``, and the knee
    bends no faster than ``knee_spin`` (radians per second): the peaks of :func:`step_profile`
    over ``distance`` on the ground (against the hip: :func:`against_hip`), ``height`` up,
    ``turn`` about up and ``bend`` of the knee (the bend that lifts the foot by ``height``)."""
    width = _MOVE[1] - _MOVE[0]
    peak = np.hypot(1.5 * distance / width, np.pi * height)      # times 1 / duration (sin^2 peaks at pi)
    need = max(peak / max(speed, 1e-300), 1.5 * abs(turn) / width / max(spin, 1e-300),
               np.pi * bend / max(knee_spin, 1e-300))
    return max(shortest, int(np.ceil(need / seconds)))


def lift_bend(thigh: np.ndarray, shin: np.ndarray, reach: np.ndarray, height: float) -> np.ndarray:
    """How much more a knee bends (radians) to lift its foot by ``height`` under a hip that stays:
    legs of ``thigh`` and ``shin`` lengths whose hip and ankle lie ``reach`` apart (law of
    cosines)."""
    def interior(d):
        d = np.clip(d, np.abs(thigh - shin) + 1e-9, thigh + shin - 1e-9)
        return np.arccos(np.clip((thigh ** 2 + shin ** 2 - d ** 2) / (2.0 * thigh * shin), -1.0, 1.0))
    return np.maximum(interior(reach) - interior(reach - height), 0.0)


@dataclass
class Replant:
    """What :func:`replant` gives back: per frame and leg, the plant's shift (T,2,D) and turn
    (T,2), and how far the foot is lifted (T,2, 0 to 1 of the step height)."""
    shift: np.ndarray
    yaw: np.ndarray
    lift: np.ndarray
    steps: int


def _angle(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi

#: Rounds that settle a step's length: the body drifts while the foot is in the air, so the
#: landing moves further the longer the step, and the step must be longer to reach it. A steady
#: drift at a quarter of the foot's speed settles in about eight (three left a CMU punch take,
#: bent 40 cm, sliding at the leash where it could step).
STEP_ROUNDS = 12


def _standing(contact: np.ndarray, movable: np.ndarray, frames: int) -> np.ndarray:
    """(T,2) the movable frames of contacts during which the other foot is planted for at least
    ``frames`` frames in a row somewhere (a foot can step there)."""
    out = np.zeros(contact.shape, dtype=bool)
    for k in (0, 1):
        both = (contact[:, k] >= 0) & (contact[:, 1 - k] >= 0)
        # The longest run of both feet planted within each contact of this foot.
        for c in np.unique(contact[movable[:, k], k]):
            mine = contact[:, k] == c
            run = best = 0
            for v in both & mine:
                run = run + 1 if v else 0
                best = max(best, run)
            if best >= frames:
                out[mine, k] = True
    return out


def replant(contact: np.ndarray, movable: np.ndarray, offset: np.ndarray, radius: np.ndarray,
            turn: np.ndarray, shift: np.ndarray, yaw: np.ndarray, turn_radius: float, *, seconds: float,
            shortest: int, longest: int, height: float, bend: np.ndarray, speed: np.ndarray, spin: np.ndarray,
            knee_spin: np.ndarray, stretch: np.ndarray | None = None,
            trigger: float = 0.6, lead: float = 0.5, hold: np.ndarray | None = None) -> Replant:
    """Plants that step instead of sliding, for two legs over T frames ``seconds`` apart.

    ``contact`` (T,2) int: the contact each leg's foot is in at each frame (-1: none); ``movable``
    (T,2) bool: frames of contacts that the leash lets slide, outside stationary ranges, where
    a foot may step. ``offset`` (T,2,D) where the edited foot lies against the carried source
    foot, ``radius`` (T,2) how far the leg reaches from it, ``turn`` (T,2) the edit's turn of the
    body (radians); ``shift`` (T,2,D) and ``yaw`` (T,2) the leashed plants (:func:`leash`), which
    all other frames keep.

    Through a movable contact, a plant lands where the edit puts the foot (at most ``lead``
    times the leash towards the leashed plant) and stays put until the edited foot lies
    ``trigger`` times the leash from it (in ground distance, or in turn against
    ``turn_radius``). Then, if the other foot is planted (in a contact, not stepping) from a
    frame before to a frame after, and the contact lasts beyond, the foot steps: it lands where
    the edited foot is then, ``lead`` times the leash further along the way the body drifted
    during the step (and as turned), so the next step comes later. A step lifts the foot by
    ``height`` (for which the knee bends ``bend`` (T,2) more) and takes from ``shortest`` to
    ``longest`` frames: long enough that the foot moves no faster than ``speed`` (2,), turns no
    faster than ``spin`` (2,) and the knee bends no faster than ``knee_spin`` (2,) per second
    (:func:`step_frames`; what the plant job allows each leg: :class:`PlantInputs`), times
    ``stretch`` (2,). Where it may not step, the
    plant follows at the leash's length, as :func:`leash` does: ``hold`` (T,2)'s, where it is
    given (the leash a plant may lie at, from ``radius`` on: a foot steps at ``radius`` and its
    plant is held at ``hold`` while it cannot), else ``radius``'s.
    """
    count = contact.shape[0]
    stretch = np.ones(2) if stretch is None else stretch
    hold = radius if hold is None else hold
    movable = movable & _standing(contact, movable, shortest + 3)
    shift, yaw = shift.copy(), yaw.copy()
    lift = np.zeros(contact.shape)
    stepping = np.zeros(contact.shape, dtype=bool)
    profiles: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    steps = 0
    state: list[dict | None] = [None, None]

    def may_step(k: int, c: int, t: int, t1: int) -> bool:
        window = slice(max(t - 1, 0), min(t1 + 2, count))
        return (t1 + 1 < count and bool(np.all(contact[t:t1 + 2, k] == c)) and bool(movable[t:t1 + 2, k].all())
                and bool(np.all(contact[window, 1 - k] >= 0)) and not stepping[window, 1 - k].any())

    def landing(k: int, t: int, t1: int, ahead: float) -> tuple[np.ndarray, float]:
        drift = offset[t1, k] - offset[t, k]
        norm = float(np.linalg.norm(drift))
        to = offset[t1, k] + (drift * (ahead * radius[t1, k] / norm) if norm > 1e-3 * radius[t, k] else 0.0)
        spun = _angle(turn[t1, k] - turn[t, k])
        y1 = float(turn[t1, k]) + (np.sign(spun) * ahead * turn_radius if abs(spun) > 1e-3 * turn_radius else 0.0)
        return to, y1

    for t in range(count):
        for k in (0, 1):
            c = int(contact[t, k])
            if c < 0 or not movable[t, k]:
                state[k] = None
                continue
            s = state[k]
            if s is None or s["contact"] != c:
                o, r = offset[t, k], radius[t, k]
                ahead = shift[t, k] - o
                ahead *= min(1.0, lead * r / max(float(np.linalg.norm(ahead)), 1e-300))
                turned = float(np.clip(_angle(yaw[t, k] - turn[t, k]), -lead * turn_radius, lead * turn_radius))
                s = state[k] = {"contact": c, "plant": o + ahead, "yaw": float(turn[t, k]) + turned, "step": None}
            if s["step"] is not None:
                t0, frm, to, y0, y1 = s["step"]
                n = len(s["profile"][0]) - 1
                i = t - t0
                shift[t, k] = frm + s["profile"][0][i] * (to - frm)
                yaw[t, k] = y0 + s["profile"][0][i] * _angle(y1 - y0)
                lift[t, k] = s["profile"][1][i]
                if i == n:
                    s["step"] = None
                    s["plant"], s["yaw"] = to, y1
                continue
            o, r = offset[t, k], radius[t, k]
            far = np.linalg.norm(o - s["plant"]) > trigger * r
            turned = abs(_angle(turn[t, k] - s["yaw"])) > trigger * turn_radius
            if far or turned:
                plan = None
                # Landing ``lead`` ahead of the drift; where the foot cannot get there in time
                # (a drag nearly as fast as the source's feet move: a boxer's), landing where
                # the foot is then: shorter steps, more of them.
                for ahead in ((lead, 0.0) if lead > 0 else (0.0,)):
                    n = shortest
                    for _ in range(STEP_ROUNDS):   # the landing depends on the step's length, and the length on the landing
                        if n > longest or not may_step(k, c, t, t + n):
                            break
                        to, y1 = landing(k, t, t + n, ahead)
                        need = step_frames(against_hip(to - s["plant"], offset[t + n, k] - offset[t, k]),
                                           _angle(y1 - s["yaw"]), height,
                                           float(bend[t, k]), float(speed[k]), float(spin[k]), float(knee_spin[k]),
                                           seconds, shortest)
                        need = max(shortest, int(np.ceil(need * stretch[k])))
                        if need <= n:
                            plan = (n, to, y1)
                            break
                        n = need
                    if plan is not None:
                        break
                if plan is not None:
                    n, to, y1 = plan
                    s["step"] = (t, s["plant"].copy(), to, s["yaw"], y1)
                    s["profile"] = profiles.setdefault(n, step_profile(n))
                    stepping[t:t + n + 1, k] = True
                    steps += 1
                    shift[t, k], yaw[t, k] = s["plant"], s["yaw"]
                    continue
            # No step here: the plant follows at the leash's length (``hold``'s).
            d = float(np.linalg.norm(o - s["plant"]))
            r = float(hold[t, k])
            if d > r:
                s["plant"] = o - (o - s["plant"]) * (r / d)
            a = _angle(turn[t, k] - s["yaw"])
            if abs(a) > turn_radius:
                s["yaw"] += a - np.sign(a) * turn_radius
            shift[t, k], yaw[t, k] = s["plant"], s["yaw"]
    return Replant(shift, yaw, lift, steps)


# ---- the plants of many agents: the solver's FootPlantJob, and the same in numpy -------------


@dataclass
class PlantInputs:
    """The inputs of the plant job for #N poses of #A agents (their output frames, agent after
    agent), two legs each, and #R contacts. Positions (N,2,3) and rotations (N,2,4) are world
    space; "source" ones are the pose before the edit's ground motion (the posed source), the
    others as edited. Lengths are stage units unless named in metres."""
    offsets: np.ndarray          # (A+1,) int64: agent a owns poses offsets[a]:offsets[a+1]
    frames: np.ndarray           # (N,) the source frame each pose plays
    seconds: np.ndarray          # (N,) the pose's time, seconds
    stationary: np.ndarray       # (N,) bool: inside a stationary range of the source
    turn: np.ndarray             # (N,) the edit's turn of the body about up (radians)
    hip: np.ndarray              # (N,2,3) edited
    knee: np.ndarray
    ankle: np.ndarray
    ankle_rot: np.ndarray        # (N,2,4) edited
    source_hip: np.ndarray       # (N,2,3) posed source
    source_ankle: np.ndarray
    source_hip_rot: np.ndarray   # (N,2,4) posed source
    source_knee_rot: np.ndarray
    source_ankle_rot: np.ndarray
    contact_offsets: np.ndarray  # (2A+1,) int64: leg k of agent a owns contacts [2a+k]:[2a+k+1]
    contacts: np.ndarray         # (R,2) inclusive source frame ranges of the foot contacts
    blend: np.ndarray            # (A,) frames a lock eases in and out over (at least)
    stretch: np.ndarray          # (A,2) how much longer each leg's steps are made
    turn_leash: np.ndarray       # (A,) how many times leash_degrees each agent's plants may lag the turn
    reach_leash: np.ndarray      # (A,) how many times max_leash_m they may lie from the edited foot (>= 1)
    #: (A,) how many times max_leash_m a foot may lie from its plant before it steps (1 to
    #: reach_leash): below reach_leash, a foot steps as at the shorter leash and only where it
    #: cannot is its plant held as far as reach_leash lets it (a body dragged faster than one
    #: foot at a time can step)
    step_leash: np.ndarray
    up: np.ndarray               # (3,) +Y or +Z
    meters_per_unit: float
    leash_m: float               # the least leash
    max_leash_m: float           # the longest leash
    max_drop_m: float            # how far the pelvis may be lowered for the leash
    leash_degrees: float         # the turn a plant may lag its foot by
    soft_reach: float            # fraction of a leg's length it reaches comfortably
    step_slide_m: float          # a foot steps through contacts that slide further
    step_slide_degrees: float    # ... or turn further
    step_seconds: float          # the shortest step
    step_longest_seconds: float  # the longest step
    step_height_m: float         # how far a stepping foot lifts
    #: A step moves the foot against its hip at most this many times as fast as the source ever
    #: does, and turns the foot and bends the knee at most as fast as the source ever does; where
    #: the source holds a leg nearly still, at least as fast as these (a calm step): metres per
    #: second, radians per second.
    step_foot_speed_ratio: float
    step_min_foot_speed_m: float
    step_min_turn_speed: float
    step_min_knee_speed: float


@dataclass
class PlantOutputs:
    target: np.ndarray       # (N,2,3) where each ankle is planted (the edited ankle where weight is 0)
    target_rot: np.ndarray   # (N,2,4) how it is turned
    weight: np.ndarray       # (N,2) in [0, 1]: how much of the plant to reach
    stepping: np.ndarray     # (N,2) bool: the foot is stepping (in the air)
    steps: np.ndarray        # (A,) int64: steps taken


def plan_feet(inputs: PlantInputs, threads: int = 0) -> PlantOutputs:
    """Runs the solver's FootPlantJob: the plants of all agents' feet at once."""
    out = _solver.plan_feet(**vars(inputs), threads=threads)
    return PlantOutputs(out.target, out.target_rot, out.weight, out.stepping, out.steps)


def _ramp(frames: np.ndarray, first, last, blend, blend_out=None) -> np.ndarray:
    """1 inside [first, last], easing to 0 over ``blend`` frames before and ``blend_out`` (default
    ``blend``) after (smoothstep)."""
    blend_out = blend if blend_out is None else blend_out
    x = np.clip(1.0 - np.maximum(first - frames, 0.0) / blend - np.maximum(frames - last, 0.0) / blend_out, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def yaw_quat(angle: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(T,4) quaternions turning by ``angle`` (radians, counter-clockwise) about the unit ``up``."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)[:, None]
    return np.concatenate([np.sin(half) * up, np.cos(half)], axis=1)


def turn_speed(q: np.ndarray, seconds: np.ndarray) -> np.ndarray:
    """(T-1,) how fast (T,4) rotations turn between samples ``seconds`` (T,) apart, radians per
    second; (T-1,...) for (T,...,4) rotations (many joints at once, each on its own)."""
    q = np.asarray(q, dtype=np.float64)
    dot = np.abs(np.sum(q[1:] * q[:-1], axis=-1)) / np.maximum(
        np.linalg.norm(q[1:], axis=-1) * np.linalg.norm(q[:-1], axis=-1), 1e-300)
    step = np.diff(np.asarray(seconds, dtype=np.float64)).reshape((-1,) + (1,) * (q.ndim - 2))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0)) / np.maximum(step, 1e-300)


def place(placement: np.ndarray, placement_rotation: np.ndarray, motion: np.ndarray, turn: np.ndarray,
          up: np.ndarray, points: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, ...]:
    """Skeleton-space points (N,P,3) and rotations (N,Q,4) of #N poses carried into the world by
    each pose's placement (N,4,4) and its rotation (N,4), then on by an edit's ground motion
    (N,4,4), which turns by ``turn`` (N,) radians about the unit ``up``: (source points, edited
    points, source rotations, edited rotations), by the solver's PlacementJob."""
    return _solver.place(placement=placement, placement_rotation=placement_rotation, motion=motion, turn=turn,
                         up=up, points=points, rotations=rotations)


def place_numpy(placement: np.ndarray, placement_rotation: np.ndarray, motion: np.ndarray, turn: np.ndarray,
                up: np.ndarray, points: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, ...]:
    """:func:`place` in numpy: the same results to within rounding."""
    source = kinematics.transform_points(points, placement[:, None])
    source_rot = quat_multiply(placement_rotation[:, None], rotations)
    return (source, kinematics.transform_points(source, motion[:, None]), source_rot,
            quat_multiply(yaw_quat(turn, up)[:, None], source_rot))




@dataclass
class _Contacts:
    """The contacts of one foot, one row each (C) over the W frames ``at`` its ramp reaches."""
    ranges: np.ndarray      # (C,2) source frames, inclusive
    at: np.ndarray          # (C,W) output frames
    valid: np.ndarray       # (C,W) frames the ramp reaches
    inside: np.ndarray      # (C,W) frames inside the contact
    rigid: np.ndarray       # (C,W) ... and inside a stationary range
    turn: np.ndarray        # (C,W) the edit's turn of the body (radians)
    yaw: np.ndarray         # (C,W) the plant's turn
    foot: np.ndarray        # (C,W,3) the posed source ankle
    pivot: np.ndarray       # (C,3) its mean over the contact, which the plant turns about
    base: np.ndarray        # (C,3) where the pivot goes
    radius: np.ndarray      # (C,W) the leash
    up_axis: str
    offset: np.ndarray | None = None   # (C,W,3) the edited ankle against the carried source foot
    shift: np.ndarray | None = None    # (C,W,3) the plant's ground shift
    lift: np.ndarray | None = None     # (C,W) how far a stepping foot is up (0 to 1 of the step height)
    step_radius: np.ndarray | None = None  # (C,W) the leash a foot steps at
    step_shift: np.ndarray | None = None   # (C,W,3) the plant's ground shift on that leash

    @property
    def carried(self) -> np.ndarray:
        """(C,W,3) the source foot turned by the plant's turn about the pivot, pivot at ``base``."""
        spin = kinematics.yaw_matrix(self.yaw, self.up_axis)[..., :3, :3]
        return np.einsum("cti,ctij->ctj", self.foot - self.pivot[:, None], spin) + self.base[:, None]

    def sliding(self, distance: float, angle: float) -> np.ndarray:
        """(C,) contacts whose leashed plant slides further than ``distance`` or turns further
        than ``angle`` (radians) inside them."""
        both = self.inside[:, 1:] & self.inside[:, :-1]
        slide = np.where(both, np.linalg.norm(np.diff(self.shift, axis=1), axis=-1), 0.0).sum(axis=1)
        turn = np.where(both, np.abs(np.diff(self.yaw, axis=1)), 0.0).sum(axis=1)
        return (slide > distance) | (turn > angle)


def reach(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, up: np.ndarray, drop: float,
          soft_reach: float) -> np.ndarray:
    """(T,) how far (stage units, over the ground) an ankle may move from ``ankle`` in any
    direction and still lie within the leg's soft reach (``soft_reach`` of its length) from
    ``hip`` lowered by ``drop``: the leg's soft length over the ground at that height, less the
    ankle's ground distance from the hip. (T,3) world positions of one leg."""
    length = np.linalg.norm(knee - hip, axis=-1) + np.linalg.norm(ankle - knee, axis=-1)
    apart = hip - ankle
    height = np.maximum(apart @ up - drop, 0.0)
    over = np.linalg.norm(apart - np.outer(apart @ up, up), axis=-1)
    return np.sqrt(np.maximum((soft_reach * length) ** 2 - height ** 2, 0.0)) - over


class _AgentPlan:
    """One agent of :func:`plan_feet_numpy`: its poses' slice of the inputs, per leg."""

    def __init__(self, inputs: PlantInputs, a: int):
        lo, hi = int(inputs.offsets[a]), int(inputs.offsets[a + 1])
        self.inputs = p = inputs
        self.frames, self.seconds, self.turn = p.frames[lo:hi], p.seconds[lo:hi], p.turn[lo:hi]
        self.stationary = np.asarray(p.stationary[lo:hi], dtype=bool)
        self.hip, self.knee, self.ankle, self.ankle_rot = p.hip[lo:hi], p.knee[lo:hi], p.ankle[lo:hi], p.ankle_rot[lo:hi]
        self.source_hip, self.source_ankle = p.source_hip[lo:hi], p.source_ankle[lo:hi]
        self.source_hip_rot, self.source_knee_rot = p.source_hip_rot[lo:hi], p.source_knee_rot[lo:hi]
        self.source_ankle_rot = p.source_ankle_rot[lo:hi]
        self.up_vector = np.asarray(p.up, dtype=np.float64)
        self.up = int(np.argmax(np.abs(self.up_vector)))
        self.up_axis = "YZ"[self.up - 1]
        self.blend = float(p.blend[a])
        self.leash_turn = np.radians(p.leash_degrees * float(p.turn_leash[a]))
        self.max_leash_m = p.max_leash_m * float(p.reach_leash[a])
        self.step_leash_m = p.max_leash_m * min(float(p.step_leash[a]), float(p.reach_leash[a]))
        self.rows = [self._contacts(k, p.contacts[p.contact_offsets[2 * a + k]:p.contact_offsets[2 * a + k + 1]])
                     for k in range(2)]

    def _contacts(self, k: int, ranges) -> _Contacts | None:
        """The contacts of one foot at once, one row each over the frames its ramp reaches, with
        their leashed plants; None without contacts on these poses."""
        p, count, blend = self.inputs, len(self.frames), self.blend
        # The leash: as far as the leg reaches with the pelvis lowered a little, from the
        # least leash to the longest.
        reaches = reach(self.hip[:, k], self.knee[:, k], self.ankle[:, k], self.up_vector,
                        p.max_drop_m / p.meters_per_unit, p.soft_reach)
        radius = np.clip(reaches, p.leash_m / p.meters_per_unit, self.max_leash_m / p.meters_per_unit)
        step_radius = np.clip(reaches, p.leash_m / p.meters_per_unit, self.step_leash_m / p.meters_per_unit)
        ranges = np.array(ranges, dtype=np.float64).reshape(-1, 2)
        inside = (self.frames >= ranges[:, :1] - 1e-9) & (self.frames <= ranges[:, 1:] + 1e-9)   # (C,T)
        used = inside.any(axis=1)
        ranges, inside = ranges[used], inside[used]
        if not len(ranges):
            return None
        reached = _ramp(self.frames, ranges[:, :1], ranges[:, 1:], blend * self.max_leash_m / p.leash_m) > 0  # (C,T)
        lo = reached.argmax(axis=1)
        width = int((reached.sum(axis=1)).max())
        at = lo[:, None] + np.arange(width)                                                      # (C,W)
        valid = at < count
        at = np.minimum(at, count - 1)
        valid &= np.take_along_axis(reached, at, axis=1)
        inside = np.take_along_axis(inside, at, axis=1) & valid
        # Where a contact meets a stationary range, the body moves rigidly there: the plant
        # is that motion, so the range keeps its shape (no correction inside it).
        rigid = inside & self.stationary[at]
        chosen = np.where(rigid.any(axis=1, keepdims=True), rigid, inside)
        n_chosen = chosen.sum(axis=1)[:, None]
        turn_c = self.turn[at]
        yaw0 = np.arctan2((np.sin(turn_c) * chosen).sum(1), (np.cos(turn_c) * chosen).sum(1))[:, None]
        # An edit that turns the body far during a contact turns the plant too.
        apart = np.angle(np.exp(1j * (turn_c - yaw0)))
        yaw = yaw0 + leash_rows(apart[..., None], np.zeros((len(at), 1)), inside, rigid,
                                self.leash_turn)[..., 0]
        # Turned about the planted foot itself, so a plant that turns along does not slide.
        foot = self.source_ankle[:, k][at]                                                        # (C,W,3)
        pivot = (foot * chosen[..., None]).sum(1) / n_chosen
        base = np.einsum("ci,cij->cj", pivot, kinematics.yaw_matrix((yaw * chosen).sum(1) / n_chosen[:, 0],
                                                                    self.up_axis)[:, :3, :3])
        out = _Contacts(ranges=ranges, at=at, valid=valid, inside=inside, rigid=rigid, turn=turn_c, yaw=yaw,
                        foot=foot, pivot=pivot, base=base, radius=radius[at], up_axis=self.up_axis)
        out.offset = self.ankle[:, k][at] - out.carried
        out.offset[..., self.up] = 0.0  # feet stay at their source height: never below their ground
        out.shift = leash_rows(out.offset, (out.offset * chosen[..., None]).sum(1) / n_chosen, inside,
                               rigid, out.radius)
        out.lift = np.zeros(at.shape)
        out.step_radius = step_radius[at]
        out.step_shift = out.shift if self.step_leash_m == self.max_leash_m else leash_rows(
            out.offset, (out.offset * chosen[..., None]).sum(1) / n_chosen, inside, rigid, out.step_radius)
        return out

    def plan(self, stretch) -> tuple:
        """(target, target_rot, weight, stepping, steps) of the legs from the contacts' plants,
        where feet step (their steps ``stretch`` times as long as :func:`replant` would make
        them)."""
        p, count, blend = self.inputs, len(self.frames), self.blend
        up_vector = self.up_vector
        rows = [None if r is None else replace(r, shift=r.shift.copy(), yaw=r.yaw.copy(), lift=r.lift.copy())
                for r in self.rows]
        steps = self._replant(rows, stretch) if all(r is not None for r in rows) else 0
        stepping = np.zeros((count, 2), dtype=bool)
        target = self.ankle.copy()
        target_rot = self.ankle_rot.copy()
        weight = np.zeros((count, 2))
        pos_sum = np.zeros((count, 2, 3))
        rot_sum = np.zeros((count, 2, 4))
        w_sum = np.zeros((count, 2))
        for k, r in enumerate(rows):
            if r is None:
                continue
            stepping[r.at[r.lift > 0], k] = True
            # The lock eases in and out over longer where the plant lies far from the edited foot
            # (within the frames reached above).
            far = np.linalg.norm(r.shift - r.offset, axis=-1) / (p.leash_m / p.meters_per_unit)    # (C,W)
            rows_c = np.arange(len(r.at))
            ends = r.inside.argmax(axis=1), r.at.shape[1] - 1 - r.inside[:, ::-1].argmax(axis=1)
            blend_in, blend_out = (blend * np.clip(far[rows_c, e], 1.0, self.max_leash_m / p.leash_m)[:, None]
                                   for e in ends)
            w = np.where(r.valid, _ramp(self.frames[r.at], r.ranges[:, :1], r.ranges[:, 1:], blend_in, blend_out), 0.0)
            valid = r.valid & (w > 0)
            plant_rot = quat_multiply(yaw_quat(r.yaw.reshape(-1), up_vector).reshape(r.yaw.shape + (4,)),
                                      self.source_ankle_rot[:, k][r.at])
            plant_rot *= np.where(np.sum(plant_rot * self.ankle_rot[:, k][r.at], -1) < 0, -1.0, 1.0)[..., None]
            plant = r.carried + r.shift + (r.lift * (p.step_height_m / p.meters_per_unit))[..., None] * up_vector
            # Where the ramps of two contacts meet, their plants blend by weight: no jump.
            at = r.at[valid]
            np.add.at(pos_sum[:, k], at, (w[..., None] * plant)[valid])
            np.add.at(rot_sum[:, k], at, (w[..., None] * plant_rot)[valid])
            np.add.at(w_sum[:, k], at, w[valid])
            np.maximum.at(weight[:, k], at, w[valid])
        some = w_sum > 0
        target[some] = pos_sum[some] / w_sum[some][:, None]
        target_rot[some] = normalize(rot_sum[some])
        return target, target_rot, weight, stepping, steps

    def _replant(self, rows: list[_Contacts], stretch) -> int:
        """Where the leash lets a foot slide through a contact and the other foot bears the
        weight, the foot steps instead (:func:`replant`), at the speeds the inputs allow (from the
        source's, at least a calm step's); returns the steps taken."""
        p, count = self.inputs, len(self.frames)
        # Which contacts slide, on the leash a foot steps at.
        sliding = [replace(r, shift=r.step_shift).sliding(p.step_slide_m / p.meters_per_unit,
                                                          np.radians(p.step_slide_degrees)) for r in rows]
        if not any(s.any() for s in sliding) or count < 3:
            return 0
        contact = np.full((count, 2), -1)
        movable = np.zeros((count, 2), dtype=bool)
        offset = np.zeros((count, 2, 3))
        shift = np.zeros((count, 2, 3))
        radius = np.zeros((count, 2))
        hold = np.zeros((count, 2))
        turn = np.zeros((count, 2))
        yaw = np.zeros((count, 2))
        for k, (r, s) in enumerate(zip(rows, sliding)):
            c, w = np.nonzero(r.inside)
            t = r.at[c, w]
            contact[t, k] = c
            movable[t, k] = s[c] & ~r.rigid[c, w]
            offset[t, k], shift[t, k], radius[t, k] = r.offset[c, w], r.shift[c, w], r.step_radius[c, w]
            hold[t, k] = r.radius[c, w]
            turn[t, k], yaw[t, k] = r.turn[c, w], r.yaw[c, w]
        seconds = self.seconds
        # How fast a step may move each foot against its hip, turn it, and bend its knee: from the
        # fastest the source does, at least a calm step's pace.
        speed = [max(p.step_foot_speed_ratio * float(np.linalg.norm(
            np.gradient(self.source_ankle[:, k] - self.source_hip[:, k], seconds, axis=0), axis=-1).max()),
            p.step_min_foot_speed_m / p.meters_per_unit) for k in range(2)]
        spin = [max(float(turn_speed(self.source_ankle_rot[:, k], seconds).max()), p.step_min_turn_speed)
                for k in range(2)]
        knee_spin = [max(float(turn_speed(quat_multiply(quat_conjugate(self.source_hip_rot[:, k]), self.source_knee_rot[:, k]),
                                          seconds).max()), p.step_min_knee_speed) for k in range(2)]
        height = p.step_height_m / p.meters_per_unit
        bend = lift_bend(np.linalg.norm(self.knee - self.hip, axis=-1), np.linalg.norm(self.ankle - self.knee, axis=-1),
                         np.linalg.norm(self.ankle - self.hip, axis=-1), height)
        frame = float(np.median(np.diff(seconds)))
        out = replant(contact, movable, offset, radius, turn, shift, yaw, self.leash_turn,
                      seconds=frame, shortest=max(2, int(round(p.step_seconds / frame))),
                      longest=max(2, int(round(p.step_longest_seconds / frame))),
                      height=height, bend=bend, speed=np.array(speed), spin=np.array(spin),
                      knee_spin=np.array(knee_spin), stretch=np.asarray(stretch, dtype=np.float64), hold=hold)
        if not out.steps:
            return 0
        for k, (r, s) in enumerate(zip(rows, sliding)):
            for c in np.flatnonzero(s):
                w = np.flatnonzero(r.inside[c])
                t = r.at[c, w]
                for values, new in ((r.shift, out.shift), (r.yaw, out.yaw), (r.lift, out.lift)):
                    values[c, w] = new[t, k]
                    values[c, :w[0]] = values[c, w[0]]
                    values[c, w[-1] + 1:] = values[c, w[-1]]
                r.lift[c, :w[0]] = r.lift[c, w[-1] + 1:] = 0.0
        return out.steps


def plan_feet_numpy(inputs: PlantInputs) -> PlantOutputs:
    """The plant job in numpy, agent after agent: the peer of :func:`plan_feet` (the same results
    to within rounding)."""
    agents = len(inputs.offsets) - 1
    n = int(inputs.offsets[-1])
    out = PlantOutputs(target=np.zeros((n, 2, 3)), target_rot=np.zeros((n, 2, 4)), weight=np.zeros((n, 2)),
                       stepping=np.zeros((n, 2), dtype=bool), steps=np.zeros(agents, dtype=np.int64))
    for a in range(agents):
        lo, hi = int(inputs.offsets[a]), int(inputs.offsets[a + 1])
        (out.target[lo:hi], out.target_rot[lo:hi], out.weight[lo:hi], out.stepping[lo:hi],
         out.steps[a]) = _AgentPlan(inputs, a).plan(inputs.stretch[a])
    return out
