"""Plausibility of edited motion in the solver: the C++ ``PlausibilityJob`` and its measures
(``_solver.plausibility``, ``joint_facing``, ``turning_rates``, ``direction_deviation``,
``edit_turn``), as keyword wrappers, and the same measures in numpy.

:mod:`mocapedit.inspect.metrics` defines the measures (what they mean, their thresholds) and
calls these; the job measures many agents at once, each owning a run of source samples and a
run of edited samples (offsets), so a crowd's report costs one call. The ``*_numpy``
functions are the measures as numpy computed them one agent at a time: the benchmark times the
job against them and the tests compare them.

Conventions: the facing joint's world matrices are ``(..., 4, 4)`` (row-vector convention);
ground points ``(..., 2)`` in stage units; seconds; radians in, degrees out.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry.ground import to_ground, up_index, up_token
from mocapedit.geometry.shape import as_points, length_ratio


def _up(up_axis) -> int:
    return up_index(up_token(up_axis))


def joint_facing(matrices, up_axis) -> np.ndarray:
    """(..., T) heading of a joint's facing (not unwrapped) from its world matrices (..., T, 4, 4)."""
    return _solver.joint_facing(matrices=matrices, up_axis=_up(up_axis))


def turning_rates(facing, seconds) -> np.ndarray:
    """(..., T-1) unsigned turning rate (degrees per second) of a facing (..., T) at increasing seconds."""
    return _solver.turning_rates(facing=facing, seconds=seconds)


def direction_deviation(source, edited, seconds, min_speed: float, chord: float, turn=None) -> np.ndarray:
    """(..., T) degrees between the edited and the source walking direction (chords of ``chord`` seconds)."""
    return _solver.direction_deviation(source=source, edited=edited, seconds=seconds, min_speed=float(min_speed),
                                       chord=float(chord), turn=turn)


def edit_turn(source, edited, seconds, min_speed: float, span: float) -> np.ndarray:
    """(..., T) radians: the turn an edit gives a walk (chords of ``span`` seconds centred on each sample)."""
    return _solver.edit_turn(source=source, edited=edited, seconds=seconds, min_speed=float(min_speed),
                             span=float(span))


@dataclass
class PlausibilityFigures:
    """The job's figures, one value per agent (see :class:`mocapedit.inspect.metrics.Plausibility`)."""
    max_facing_rate: np.ndarray
    source_max_facing_rate: np.ndarray
    max_extra_facing_rate: np.ndarray
    worst_turn_frame: np.ndarray
    spin_frames: np.ndarray
    max_direction_deviation: np.ndarray
    worst_direction_frame: np.ndarray
    max_turned_deviation: np.ndarray
    max_edit_turn: np.ndarray
    length_ratio: np.ndarray
    time_warp_min: np.ndarray
    time_warp_max: np.ndarray


@dataclass
class Thresholds:
    """What the measures call walking, a walking direction, an edit's turn and a spin."""
    walking_speed: float      # stage units per second
    chord: float              # seconds
    edit_turn_span: float     # seconds
    spin_rate: float          # degrees per second


def plausibility(source_offsets, edited_offsets, source_seconds, source_hip, edited_seconds, edited_hip,
                 up_axis, thresholds: Thresholds, edited_frames=None) -> PlausibilityFigures:
    """Runs the solver's PlausibilityJob: agent ``a`` owns source samples ``source_offsets[a]`` ..
    ``source_offsets[a + 1] - 1`` of ``source_seconds`` (S,) and ``source_hip`` (S, 4, 4), and
    edited samples likewise (``edited_frames`` (E,): the source frame each plays, or None)."""
    out = _solver.plausibility(
        source_offsets=np.asarray(source_offsets, dtype=np.int64), edited_offsets=np.asarray(edited_offsets, np.int64),
        source_seconds=source_seconds, source_hip=source_hip, edited_seconds=edited_seconds, edited_hip=edited_hip,
        edited_frames=edited_frames, up_axis=_up(up_axis), walking_speed=float(thresholds.walking_speed),
        chord=float(thresholds.chord), edit_turn_span=float(thresholds.edit_turn_span),
        spin_rate=float(thresholds.spin_rate))
    return PlausibilityFigures(**{name: getattr(out, name) for name in PlausibilityFigures.__dataclass_fields__})


# ---- the measures in numpy, one agent at a time ------------------------------------------------


def joint_facing_numpy(rotations: np.ndarray, up_axis: str) -> np.ndarray:
    """:func:`joint_facing` of (F,3,3) or (F,4,4) world matrices."""
    axes = np.asarray(rotations, dtype=np.float64)[:, :3, :3]
    up = up_index(up_token(up_axis))
    k = int(np.argmin(np.mean(np.abs(axes[:, :, up]), axis=0)))
    uv = to_ground(axes[:, k, :], up_axis)
    return np.arctan2(uv[:, 1], uv[:, 0])


def turning_rates_numpy(facing, seconds) -> np.ndarray:
    """:func:`turning_rates` of one facing (T,)."""
    f = np.unwrap(np.asarray(facing, dtype=np.float64))
    s = np.asarray(seconds, dtype=np.float64)
    if f.shape != s.shape or f.ndim != 1:
        raise ValueError(f"facing {f.shape} and seconds {s.shape} must both be (T,)")
    dt = np.diff(s)
    if np.any(dt <= 0):
        raise ValueError("sample times must increase")
    return np.degrees(np.abs(np.diff(f))) / dt


def direction_deviation_numpy(source_ground, edited_ground, seconds, min_speed: float, chord: float,
                              turn=None) -> np.ndarray:
    """:func:`direction_deviation` of one pair of paths (T, 2)."""
    s = as_points(source_ground, "source_ground", dims=(2,))
    e = as_points(edited_ground, "edited_ground", dims=(2,))
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


def edit_turn_numpy(source_ground, edited_ground, seconds, min_speed: float, span: float) -> np.ndarray:
    """:func:`edit_turn` of one pair of paths (T, 2)."""
    s = as_points(source_ground, "source_ground", dims=(2,))
    e = as_points(edited_ground, "edited_ground", dims=(2,))
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


def plausibility_numpy(source_seconds, source_hip, edited_seconds, edited_hip, up_axis, thresholds: Thresholds,
                       edited_frames=None) -> dict:
    """The figures of :func:`plausibility` for one agent ({field of PlausibilityFigures: value})."""
    ss, se = np.asarray(source_seconds, np.float64), np.asarray(edited_seconds, np.float64)
    ms, me = np.asarray(source_hip, np.float64), np.asarray(edited_hip, np.float64)
    fs, fe = np.unwrap(joint_facing_numpy(ms, up_axis)), np.unwrap(joint_facing_numpy(me, up_axis))
    gs, ge = to_ground(ms[:, 3, :3], up_axis), to_ground(me[:, 3, :3], up_axis)
    walking, chord, span = thresholds.walking_speed, thresholds.chord, thresholds.edit_turn_span
    if len(se) >= 2 and len(ss) >= 2:
        rate_e = turning_rates_numpy(fe, se)
        if edited_frames is None:
            rate_s = _pair(turning_rates_numpy(fs, ss), len(rate_e))
            warp = np.diff(se) / _pair(np.diff(ss), len(se) - 1)
            gs_at, ss_at = _pair(gs, len(ge)), _pair(ss, len(se))
        else:
            f = np.asarray(edited_frames, dtype=np.float64)
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
        limit = thresholds.spin_rate
        spin = int(np.count_nonzero((rate_e > limit) & (rate_s <= limit)))
        # Held ends of a warped clip: measure on the frames that advance.
        keep = np.r_[True, np.diff(ss_at) > 0]
        dev, turned = np.full(len(ge), np.nan), np.full(len(ge), np.nan)
        turn = edit_turn_numpy(gs_at[keep], ge[keep], ss_at[keep], walking, span)
        dev[keep] = direction_deviation_numpy(gs_at[keep], ge[keep], ss_at[keep], walking, chord)
        turned[keep] = direction_deviation_numpy(gs_at[keep], ge[keep], ss_at[keep], walking, chord, turn=turn)
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
    return dict(max_facing_rate=rates[0], source_max_facing_rate=rates[1], max_extra_facing_rate=extra,
                worst_turn_frame=turn_frame, spin_frames=spin, max_direction_deviation=max_dev,
                worst_direction_frame=dev_frame, max_turned_deviation=max_turned, max_edit_turn=max_turn,
                length_ratio=length_ratio(ge, gs), time_warp_min=warp_range[0], time_warp_max=warp_range[1])


__all__ = ["joint_facing", "turning_rates", "direction_deviation", "edit_turn", "plausibility", "Thresholds",
           "PlausibilityFigures", "joint_facing_numpy", "turning_rates_numpy", "direction_deviation_numpy",
           "edit_turn_numpy", "plausibility_numpy"]
