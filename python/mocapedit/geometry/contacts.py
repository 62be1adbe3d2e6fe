"""Legs and foot contacts of a source clip (numpy, no USD).

A leg is a chain hip (thigh) -> knee -> ankle, each joint the child of the one before,
with an optional toe below the ankle. Legs are found by what the joints' names say
(:func:`mocapedit.model.names.side_and_role`: CMU and Mixamo ``LeftUpLeg/LeftLeg/LeftFoot/LeftToeBase``,
Character Creator ``CC_Base_L_Thigh/L_Calf/L_Foot/L_ToeBase``, Unreal ``thigh_l/calf_l/foot_l/ball_l``
and other rig families, the project's walker) or given by ``mocap:leftLegJoints`` /
``mocap:rightLegJoints``.

A foot is planted when its ankle or its toe is near the lowest height that joint reaches
in the clip and barely moves over the ground. The test has hysteresis (stricter to enter
a contact than to stay in it; the speeds grow with a fast clip's mean foot speed) and a
minimum duration; a contact then extends over the
landing and the lift-off while the joint stays under the release height. Thresholds are
in metres and seconds, converted with ``metersPerUnit`` and the clip's frame times. A cut in
the clip (a step faster than ``trajectory.CUT_SPEED_M``, as from a rest pose left in the
first frame) bounds every contact, and counts in neither the lowest height nor the mean speed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit.geometry import ground, trajectory
from mocapedit.model.data import Agent, Clip, StageInfo
from mocapedit.model.names import joint_leaf, side_and_role
from mocapedit.geometry.stationary import runs

SIDES = ("left", "right")
#: A leg whose foot never comes within this of the lowest point the body reaches in its clip
#: (metres) does not stand on the ground there: see :func:`raised_legs`.
GROUND_REACH_M = 0.3

@dataclass(frozen=True)
class Leg:
    side: str                 # "left" | "right"
    hip: int                  # skeleton joint indices
    knee: int
    ankle: int
    toe: int | None = None

    @property
    def joints(self) -> tuple[int, ...]:
        return (self.hip, self.knee, self.ankle) + ((self.toe,) if self.toe is not None else ())


def _leaf(joint: str) -> str:
    """The joint's own name without a ``namespace:`` prefix."""
    return joint_leaf(joint).rsplit(":", 1)[-1]


def chain_problem(names: list[str], parents: np.ndarray, indices: list[int]) -> str | None:
    """Why ``indices`` (hip, knee, ankle[, toe]) is not a leg chain, or None when it is one."""
    if len(indices) not in (3, 4):
        return f"a leg is hip, knee, ankle and optionally toe: got {len(indices)} joints"
    what = ("knee", "ankle", "toe")
    for k in range(1, len(indices)):
        if int(parents[indices[k]]) != indices[k - 1]:
            return (f"the {what[k - 1]} '{names[indices[k]]}' is not a child of '{names[indices[k - 1]]}': "
                    "a leg is hip, knee, ankle, each the child of the one before")
    return None


def find_legs(joints: list[str], parents: np.ndarray) -> list[Leg]:
    """The legs found by joint name, left first; a side not found is left out. A leg is a hip
    joint whose child is a knee whose child is an ankle, all named for the same side; the toe
    is a child of the ankle named as one (the first in joint order)."""
    said = [side_and_role(_leaf(str(j))) for j in joints]
    children: dict[int, list[int]] = {}
    for i, p in enumerate(parents):
        children.setdefault(int(p), []).append(i)

    def below(joint: int, side: str, roles: tuple[str, ...]) -> list[int]:
        return [c for c in children.get(joint, []) if said[c][0] == side and said[c][1] in roles]

    legs = []
    for side in SIDES:
        for hip in (i for i, (s, r) in enumerate(said) if s == side and r == "hip"):
            chain = next(((knee, ankle) for knee in below(hip, side, ("knee",))
                          for ankle in below(knee, side, ("ankle",))), None)
            if chain is None:
                continue
            knee, ankle = chain
            toes = below(ankle, side, ("toe", "ankle") if _leaf(str(joints[ankle])).lower().endswith("ankle")
                         else ("toe",))
            legs.append(Leg(side, hip, knee, ankle, toes[0] if toes else None))
            break
    return legs


@dataclass
class DetectSettings:
    height: float = 0.04          # metres above the joint's lowest height in the clip, to enter a contact
    release_height: float = 0.06  # metres, to stay in it
    speed: float = 0.25           # metres per second of ground speed, to enter
    release_speed: float = 0.45   # metres per second, to stay
    min_duration: float = 0.06    # seconds a contact must last
    max_gap: float = 0.04         # seconds: shorter breaks between two contacts are bridged
    relative_speed: float = 0.2   # the speed thresholds grow to this fraction of the joint's mean ground speed

    def validate(self) -> None:
        for name in ("height", "speed", "min_duration"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name.replace('_', '-')} must be a positive number, got {value}")
        for entry, release in (("height", "release_height"), ("speed", "release_speed")):
            low, high = getattr(self, entry), getattr(self, release)
            if not np.isfinite(high):
                raise ValueError(f"{release.replace('_', '-')} must be a finite number, got {high}")
            if not high >= low:
                raise ValueError(f"{release.replace('_', '-')} {high:g} is below {entry} {low:g}: a contact "
                                 f"is stayed in up to the release threshold, entered below the other; raise "
                                 f"{release.replace('_', '-')} to {low:g} or more")
        if not (np.isfinite(self.max_gap) and self.max_gap >= 0):
            raise ValueError(f"max-gap must be zero or positive, got {self.max_gap}")
        if not (np.isfinite(self.relative_speed) and self.relative_speed >= 0):
            raise ValueError(f"relative-speed must be zero or positive, got {self.relative_speed}")


def ground_speed(seconds: np.ndarray, points: np.ndarray, up_axis: str) -> np.ndarray:
    """(F,...) ground speed of (F,...,3) world points, stage units per second (central differences)."""
    uv = ground.to_ground(points, up_axis)
    if len(seconds) < 2:
        return np.zeros(uv.shape[:-1])
    return np.linalg.norm(np.gradient(uv, seconds, axis=0), axis=-1)


def _hysteresis(enter: np.ndarray, stay: np.ndarray) -> np.ndarray:
    out = np.zeros(len(enter), dtype=bool)
    on = False
    for i in range(len(enter)):
        on = bool(enter[i]) if not on else bool(stay[i])
        out[i] = on
    return out


def takes(seconds: np.ndarray, points: np.ndarray, up_axis: str, meters_per_unit: float) -> list[tuple[int, int]]:
    """Half-open frame runs ``[a, b)`` of a joint's (F,3) world positions between cuts
    (steps faster than ``trajectory.CUT_SPEED_M``: a rest pose left in a clip's first frame,
    a teleport). Contacts are found within each run, never across a cut."""
    uv = ground.to_ground(points, up_axis)
    cut = trajectory.is_cut(np.linalg.norm(np.diff(uv, axis=0), axis=-1), np.diff(seconds), meters_per_unit)
    bounds = [0, *(np.flatnonzero(cut) + 1).tolist(), len(points)]
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def detect_joint(seconds: np.ndarray, points: np.ndarray, up_axis: str, meters_per_unit: float,
                 settings: DetectSettings, pieces: list[tuple[int, int]] | None = None) -> np.ndarray:
    """(F,) contact mask of one joint from its (F,3) world positions at the clip's frames, found
    within each of ``pieces`` (default :func:`takes`). A lone frame between two cuts is never a
    contact, and counts neither in the lowest height nor in the mean speed."""
    if pieces is None:
        pieces = takes(seconds, points, up_axis, meters_per_unit)
    pieces = [(a, b) for a, b in pieces if b - a >= 2]
    mask = np.zeros(len(points), dtype=bool)
    if not pieces:
        return mask
    h = ground.height(points, up_axis) * meters_per_unit
    v = np.zeros(len(points))
    for a, b in pieces:
        v[a:b] = ground_speed(seconds[a:b], points[a:b], up_axis) * meters_per_unit
    inside = mask_of([(a, b - 1) for a, b in pieces], len(points))
    h = h - h[inside].min()
    # Speeds relative to the clip: a running foot that slips a little while planted is still planted.
    scale = max(1.0, settings.relative_speed * float(v[inside].mean()) / settings.speed)
    low = h <= settings.height
    for a, b in pieces:
        piece = _hysteresis((h[a:b] <= settings.height) & (v[a:b] <= settings.speed * scale),
                            (h[a:b] <= settings.release_height) & (v[a:b] <= settings.release_speed * scale))
        # A contact reaches out over the landing and the lift-off, while the joint is still low:
        # the lock carries the source foot's own motion there, and blends where the foot is in the air.
        for x, y in runs(piece):
            while x > 0 and low[a + x - 1]:
                x -= 1
            while y + 1 < b - a and low[a + y + 1]:
                y += 1
            piece[x:y + 1] = True
        mask[a:b] = piece
    return mask


def clean_ranges(mask: np.ndarray, seconds: np.ndarray, settings: DetectSettings) -> list[tuple[int, int]]:
    """Inclusive frame ranges of a mask, short breaks bridged and short ranges dropped."""
    ranges = runs(mask)
    merged: list[list[int]] = []
    for a, b in ranges:
        if merged and seconds[a] - seconds[merged[-1][1]] <= settings.max_gap + 1e-9:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged if seconds[b] - seconds[a] >= settings.min_duration - 1e-9]


def detect_leg(seconds: np.ndarray, ankle: np.ndarray, toe: np.ndarray | None, up_axis: str,
               meters_per_unit: float, settings: DetectSettings | None = None) -> list[tuple[int, int]]:
    """Contact ranges of one foot: frames where its ankle or its toe is planted. No range
    spans a cut in the clip (:func:`takes`, of the ankle)."""
    settings = settings or DetectSettings()
    pieces = takes(seconds, ankle, up_axis, meters_per_unit)
    mask = detect_joint(seconds, ankle, up_axis, meters_per_unit, settings, pieces)
    if toe is not None:
        mask |= detect_joint(seconds, toe, up_axis, meters_per_unit, settings, pieces)
    return [(a + x, a + y) for a, b in pieces for x, y in clean_ranges(mask[a:b], seconds[a:b], settings)]


def raised_legs(agent: Agent, clip: Clip, info: StageInfo) -> dict[int, float]:
    """The legs (index into ``agent.legs``) whose foot never comes within :data:`GROUND_REACH_M`
    of the lowest point the body reaches in the clip, and how far above it their foot's lowest
    is (metres): an arm given as a leg, the feet of a handstand. No contact is found on them."""
    h = ground.height(trajectory.skel_world(agent, clip)[..., 3, :3], info.up_axis) * info.meters_per_unit
    lowest = float(h.min()) if h.size else 0.0
    out = {}
    for k, leg in enumerate(agent.legs):
        foot = min(float(h[:, j].min()) for j in (leg.ankle, leg.toe) if j is not None)
        if foot - lowest > GROUND_REACH_M:
            out[k] = foot - lowest
    return out


def raised_note(agent: Agent, raised: dict[int, float]) -> str | None:
    """What :func:`raised_legs` found, for the agent's notes; None when every leg is on the ground."""
    if not raised:
        return None
    parts = []
    for k, metres in raised.items():
        leg = agent.legs[k]
        parts.append(f"the {leg.side} leg's foot '{agent.joints[leg.ankle]}' is never within "
                     f"{GROUND_REACH_M * 100:.0f} cm of the lowest point of the body (it stays {metres:.2f} m above it): "
                     f"no contacts on it; check mocap:{leg.side}LegJoints")
    return "; ".join(parts)


def detect_agent(agent: Agent, clip: Clip, info: StageInfo, settings: DetectSettings | None = None,
                 raised: dict[int, float] | None = None) -> list[list[tuple[int, int]]]:
    """Detected contact ranges of each leg of an agent (``agent.legs``), on its source clip;
    none on the legs ``raised`` (default :func:`raised_legs`)."""
    seconds = agent.sample_times / info.time_codes_per_second
    if raised is None:
        raised = raised_legs(agent, clip, info)
    out = []
    for k, leg in enumerate(agent.legs):
        if k in raised:
            out.append([])
            continue
        ankle = trajectory.joint_world_position(agent, clip, leg.ankle)
        toe = trajectory.joint_world_position(agent, clip, leg.toe) if leg.toe is not None else None
        out.append(detect_leg(seconds, ankle, toe, info.up_axis, info.meters_per_unit, settings))
    return out


def leg_ranges(authored, legs, frame_count: int) -> list[list[tuple[int, int]]]:
    """Per leg, the inclusive frame ranges of an artist's contacts ``authored`` ((name, ankle,
    first, last), as the reader gives them): a leg's contacts that overlap or touch are one, as
    detection joins its ankle's and toe's (a heel strike on the ankle and a toe-off on the toe
    that overlap it are one plant of the foot)."""
    return [runs(mask_of([(a, b) for _, ankle, a, b in authored if ankle == leg.ankle], frame_count))
            for leg in legs]


def mask_of(ranges, frame_count: int) -> np.ndarray:
    """(F,) bool mask of inclusive frame ranges."""
    out = np.zeros(frame_count, dtype=bool)
    for a, b in ranges:
        out[a:b + 1] = True
    return out


__all__ = ["Leg", "SIDES", "find_legs", "chain_problem", "DetectSettings", "detect_leg", "detect_joint", "detect_agent", "raised_legs", "raised_note", "GROUND_REACH_M",
           "clean_ranges", "leg_ranges", "mask_of", "ground_speed", "takes"]
