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

from dataclasses import dataclass

import numpy as np

__all__ = ["follow", "leash", "leash_rows", "Replant", "replant", "step_profile", "step_frames", "lift_bend"]


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


def step_frames(distance: float, turn: float, height: float, bend: float, speed: float, spin: float,
                knee_spin: float, seconds: float, shortest: int) -> int:
    """Frames a step takes (at least ``shortest``) so that the foot moves no faster than ``speed``
    (stage units per second) and turns no faster than ``spin``, and the knee bends no faster than
    ``knee_spin`` (radians per second): the peaks of :func:`step_profile` over ``distance`` on the
    ground, ``height`` up, ``turn`` about up and ``bend`` of the knee (the bend that lifts the
    foot by ``height``)."""
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
            trigger: float = 0.6, lead: float = 0.5) -> Replant:
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
    faster than ``spin`` (2,) and the knee bends no faster than ``knee_spin`` (2,) per second,
    the fastest the source moves each foot and knee (:func:`step_frames`), times ``stretch`` (2,). Where it may not step, the
    plant follows at the leash's length, as :func:`leash` does.
    """
    count = contact.shape[0]
    stretch = np.ones(2) if stretch is None else stretch
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

    def landing(k: int, t: int, t1: int) -> tuple[np.ndarray, float]:
        drift = offset[t1, k] - offset[t, k]
        norm = float(np.linalg.norm(drift))
        to = offset[t1, k] + (drift * (lead * radius[t1, k] / norm) if norm > 1e-3 * radius[t, k] else 0.0)
        spun = _angle(turn[t1, k] - turn[t, k])
        y1 = float(turn[t1, k]) + (np.sign(spun) * lead * turn_radius if abs(spun) > 1e-3 * turn_radius else 0.0)
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
                plan, n = None, shortest
                for _ in range(3):   # the landing depends on the step's length, and the length on the landing
                    if n > longest or not may_step(k, c, t, t + n):
                        break
                    to, y1 = landing(k, t, t + n)
                    need = step_frames(float(np.linalg.norm(to - s["plant"])), _angle(y1 - s["yaw"]), height,
                                       float(bend[t, k]), float(speed[k]), float(spin[k]), float(knee_spin[k]),
                                       seconds, shortest)
                    need = max(shortest, int(np.ceil(need * stretch[k])))
                    if need <= n:
                        plan = (n, to, y1)
                        break
                    n = need
                if plan is not None:
                    n, to, y1 = plan
                    s["step"] = (t, s["plant"].copy(), to, s["yaw"], y1)
                    s["profile"] = profiles.setdefault(n, step_profile(n))
                    stepping[t:t + n + 1, k] = True
                    steps += 1
                    shift[t, k], yaw[t, k] = s["plant"], s["yaw"]
                    continue
            # No step here: the plant follows at the leash's length.
            d = float(np.linalg.norm(o - s["plant"]))
            if d > r:
                s["plant"] = o - (o - s["plant"]) * (r / d)
            a = _angle(turn[t, k] - s["yaw"])
            if abs(a) > turn_radius:
                s["yaw"] += a - np.sign(a) * turn_radius
            shift[t, k], yaw[t, k] = s["plant"], s["yaw"]
    return Replant(shift, yaw, lift, steps)
