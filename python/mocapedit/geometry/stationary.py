"""Automatic detection of stationary ranges in a clip (numpy, no USD).

A frame is stationary when, measured over a short window centred on it, the ground
speed of the agent's root and the turning rate of its facing stay under thresholds.
Runs of such frames that last at least a minimum duration become stationary ranges:
the ranges ``mocapedit detect-stationary`` proposes as ``MocapStationaryAPI`` tags for an
artist to review (section 5.4.1 of the deliverable leaves this tagging to hand work).

Measuring over a window (a displacement over ``window`` seconds, not a per-frame
derivative) ignores the jitter of captured data and the sway of the hips inside a step;
it also trims each range by about half a window at its ends, so a proposed range stays
inside the idle section.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import ground


@dataclass
class DetectSettings:
    max_speed: float = 0.15        # metres per second of ground speed
    max_turn: float = 30.0         # degrees per second of heading change
    min_duration: float = 0.5      # seconds a range must last
    window: float = 0.25           # seconds over which speed and turning are measured
    max_gap: float = 0.1           # seconds: shorter interruptions between two ranges are bridged

    def validate(self) -> None:
        for name in ("max_speed", "max_turn", "min_duration", "window"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name.replace('_', '-')} must be a positive number, got {value}")
        if not (np.isfinite(self.max_gap) and self.max_gap >= 0):
            raise ValueError(f"max-gap must be zero or positive, got {self.max_gap}")


@dataclass
class StationaryRange:
    first: int                     # first frame (0-based, inclusive)
    last: int                      # last frame (inclusive)
    duration: float                # seconds
    max_speed: float               # metres per second, the largest windowed ground speed of its still frames
    max_turn: float                # degrees per second, the largest windowed turning rate of its still frames
    # Frames of gaps shorter than max_gap that join two still runs into this range: they
    # exceed a threshold (that is what makes them a gap), by as much as these maxima.
    bridged: int = 0
    bridged_max_speed: float = 0.0
    bridged_max_turn: float = 0.0


def facing(rotations: np.ndarray, up_axis: str) -> np.ndarray:
    """(F,) heading of a joint's facing, radians counter-clockwise about up.

    ``rotations`` is (F,3,3) or (F,4,4) world matrices (row-vector convention: row k is
    the joint's local axis k in world space). The local axis that stays the most
    horizontal over the clip stands for the facing; any joint convention works, and a
    constant angle between that axis and the true forward does not change turning rates.
    Leading axes (..., F, 4, 4) are clips measured each on its own: (..., F). Measured by
    the solver (``_solver.joint_facing``).
    """
    m = np.asarray(rotations, dtype=np.float64)
    if m.shape[-2:] == (3, 3):
        m = np.concatenate([np.concatenate([m, np.zeros(m.shape[:-1] + (1,))], axis=-1),
                            np.broadcast_to([0.0, 0.0, 0.0, 1.0], m.shape[:-2] + (1, 4))], axis=-2)
    return _solver.joint_facing(matrices=m, up_axis=ground.up_index(ground.up_token(up_axis)))


def _window_ends(seconds: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray]:
    half = 0.5 * window
    a = np.searchsorted(seconds, seconds - half - 1e-9, side="left")
    b = np.searchsorted(seconds, seconds + half + 1e-9, side="right") - 1
    # A window holding a single sample measures against its neighbours.
    n = len(seconds)
    same = b <= a
    a = np.where(same, np.maximum(a - 1, 0), a)
    b = np.where(same, np.minimum(b + 1, n - 1), b)
    return a, b


def ground_speed(seconds: np.ndarray, uv: np.ndarray, window: float) -> np.ndarray:
    """(F,) windowed ground speed, in the units of ``uv`` per second."""
    a, b = _window_ends(seconds, window)
    dt = np.where(b > a, seconds[b] - seconds[a], 1.0)
    return np.where(b > a, np.linalg.norm(uv[b] - uv[a], axis=-1) / dt, 0.0)


def turning_rate(seconds: np.ndarray, heading: np.ndarray, window: float) -> np.ndarray:
    """(F,) windowed turning rate of a heading, radians per second (unsigned)."""
    h = np.unwrap(np.asarray(heading, dtype=np.float64))
    a, b = _window_ends(seconds, window)
    dt = np.where(b > a, seconds[b] - seconds[a], 1.0)
    return np.where(b > a, np.abs(h[b] - h[a]) / dt, 0.0)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (first, last) of each run of True in a (F,) boolean mask."""
    padded = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(s), int(e) - 1) for s, e in zip(edges[::2], edges[1::2])]


def detect(seconds: np.ndarray, ground_m: np.ndarray, heading: np.ndarray,
           settings: DetectSettings | None = None) -> list[StationaryRange]:
    """Stationary ranges of one clip.

    Args:
      seconds: (F,) increasing sample times in seconds.
      ground_m: (F,2) ground position of the root, in metres.
      heading: (F,) facing of the root, radians (see :func:`facing`).
      settings: thresholds; defaults to :class:`DetectSettings`.

    Returns:
      The ranges in frame order; empty when the clip is shorter than the minimum duration.
    """
    settings = settings or DetectSettings()
    settings.validate()
    seconds = np.asarray(seconds, dtype=np.float64)
    n = len(seconds)
    if n < 2:
        return []
    speed = ground_speed(seconds, np.asarray(ground_m, dtype=np.float64), settings.window)
    turn = np.degrees(turning_rate(seconds, heading, settings.window))
    still = (speed <= settings.max_speed) & (turn <= settings.max_turn)
    step = float(np.median(np.diff(seconds)))
    found = runs(still)
    merged: list[list[int]] = []
    for first, last in found:
        if merged and seconds[first] - seconds[merged[-1][1]] - step <= settings.max_gap + 1e-9:
            merged[-1][1] = last
        else:
            merged.append([first, last])
    out = []
    for first, last in merged:
        duration = float(seconds[last] - seconds[first] + step)
        if duration + 1e-9 < settings.min_duration:
            continue
        inside = still[first:last + 1]
        s, t = speed[first:last + 1], turn[first:last + 1]
        out.append(StationaryRange(first=first, last=last, duration=duration,
                                   max_speed=float(s[inside].max()), max_turn=float(t[inside].max()),
                                   bridged=int((~inside).sum()),
                                   bridged_max_speed=float(s[~inside].max(initial=0.0)),
                                   bridged_max_turn=float(t[~inside].max(initial=0.0))))
    return out


__all__ = ["DetectSettings", "StationaryRange", "facing", "ground_speed", "turning_rate", "runs", "detect"]
