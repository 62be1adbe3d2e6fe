"""The peer of ``bench_plausibility``: the plausibility figures as the report measured them
before agents were measured together, one agent at a time (numpy on each agent's arrays).

It is what :func:`mocapedit.pipeline.processor.measure_plausibility` and the measures of
:mod:`mocapedit.inspect.metrics` it calls were; it stays here only to be timed and compared
against them.
"""
from __future__ import annotations

import numpy as np

from mocapedit.geometry import animation, trajectory
from mocapedit.geometry import ground
from mocapedit.geometry.ground import ground_axes, to_ground
from mocapedit.geometry.ground import up_token as _up_token
from mocapedit.geometry.shape import as_points as _points
from mocapedit.geometry.shape import length_ratio
from mocapedit.inspect import metrics
from mocapedit.inspect.metrics import (EDIT_TURN_SECONDS, CHORD_SECONDS, WALKING_SPEED_M, FootSkate, Plausibility,
                                       spins)
from mocapedit.model.report import ShotPlausibility
from mocapedit.pipeline import processor


def facing(rotations: np.ndarray, up_axis: str) -> np.ndarray:
    axes = np.asarray(rotations, dtype=np.float64)[:, :3, :3]
    up = ground.up_index(up_axis)
    k = int(np.argmin(np.mean(np.abs(axes[:, :, up]), axis=0)))
    uv = ground.to_ground(axes[:, k, :], up_axis)
    return np.arctan2(uv[:, 1], uv[:, 0])


def foot_skate_of_positions(pos: np.ndarray, t: np.ndarray, up, meters_per_unit: float,
                            time_codes_per_second: float, joints: tuple[str, ...] = (),
                            in_clip: np.ndarray | None = None, contact_height: float | None = None,
                            contact: np.ndarray | None = None) -> FootSkate:
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


def body_facing(matrices, up_axis) -> np.ndarray:
    return np.unwrap(facing(np.asarray(matrices, dtype=np.float64), _up_token(up_axis)))


def facing_change_per_second(facing, seconds) -> np.ndarray:
    f = np.unwrap(np.asarray(facing, dtype=np.float64))
    s = np.asarray(seconds, dtype=np.float64)
    if f.shape != s.shape or f.ndim != 1:
        raise ValueError(f"facing {f.shape} and seconds {s.shape} must both be (T,)")
    dt = np.diff(s)
    if np.any(dt <= 0):
        raise ValueError("sample times must increase")
    return np.degrees(np.abs(np.diff(f))) / dt


def direction_deviation(source_ground, edited_ground, seconds, min_speed: float,
                        chord: float = CHORD_SECONDS, turn=None) -> np.ndarray:
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
              span: float = EDIT_TURN_SECONDS, least_straightness: float = 0.5, measured: list | None = None
              ) -> np.ndarray:
    s = _points(source_ground, "source_ground", dims=(2,))
    e = _points(edited_ground, "edited_ground", dims=(2,))
    t = np.asarray(seconds, dtype=np.float64)
    if s.shape != e.shape or t.shape != (len(s),):
        raise ValueError(f"source {s.shape}, edited {e.shape} and seconds {t.shape} must pair by frame")
    if len(s) < 2:
        if measured is not None:
            measured.append(np.zeros(len(s), dtype=bool))
        return np.zeros(len(s))
    a = np.searchsorted(t, t - 0.5 * span, side="left")
    b = np.minimum(np.searchsorted(t, t + 0.5 * span, side="right") - 1, len(s) - 1)
    ds, de = s[b] - s[a], e[b] - e[a]
    dt = np.maximum(t[b] - t[a], 1e-12)
    along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(s, axis=0), axis=1))]
    chord = np.linalg.norm(ds, axis=1)
    walk = ((b > a) & (chord / dt >= min_speed) & (chord >= least_straightness * (along[b] - along[a]))
            & (np.linalg.norm(de, axis=1) > 0))
    if measured is not None:
        measured.append(walk)
    if not walk.any():
        return np.zeros(len(s))
    angle = np.unwrap(np.arctan2(ds[walk, 0] * de[walk, 1] - ds[walk, 1] * de[walk, 0],
                                 np.einsum("ij,ij->i", ds[walk], de[walk])))
    return np.interp(np.arange(len(s)), np.flatnonzero(walk), angle)


def _resample(values: np.ndarray, at: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    x = np.arange(len(values), dtype=np.float64)
    flat = values.reshape(len(values), -1)
    out = np.stack([np.interp(at, x, flat[:, c]) for c in range(flat.shape[1])], axis=1)
    return out.reshape((len(at),) + values.shape[1:])


def _pair(source: np.ndarray, count: int) -> np.ndarray:
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
        # The largest turn counts every span where the source walks; the turn directions are
        # compared with only where it also goes somewhere, and where that is a guess a chord
        # walks back only if it also does against the unturned source.
        max_turn = float(np.degrees(np.abs(edit_turn(gs_at[keep], ge[keep], ss_at[keep], walking,
                                                     least_straightness=0.0)).max(initial=0.0)))
        measured: list = []
        turn = edit_turn(gs_at[keep], ge[keep], ss_at[keep], walking, measured=measured)
        dev[keep] = direction_deviation(gs_at[keep], ge[keep], ss_at[keep], walking)
        turned[keep] = direction_deviation(gs_at[keep], ge[keep], ss_at[keep], walking, turn=turn)
        guess = np.ones(len(ge), dtype=bool)
        guess[np.flatnonzero(keep)[measured[0]]] = False
        turned = np.where(guess & np.isfinite(dev), np.minimum(turned, dev), turned)
        dev_frame = int(np.nanargmax(dev)) if np.isfinite(dev).any() else -1
        max_dev = float(dev[dev_frame]) if dev_frame >= 0 else float("nan")
        max_turned = float(np.nanmax(turned)) if np.isfinite(turned).any() else float("nan")
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


def measure_plausibility(ctx: SolveContext) -> None:
    info = ctx.data.info
    up, chains, figures = info.up_axis, {}, []
    for path in sorted(ctx.edits):
        if path not in ctx.paths and path not in ctx.time_maps:
            continue
        agent, traj = ctx.data.agents[path], ctx.trajectories[path]
        clip = ctx.data.clip_of(agent)
        hip = metrics.default_facing_joint(agent.joints)
        feet = metrics.default_foot_joints(agent.joints)
        joints = [hip] + feet
        key = (agent.clip_key, tuple(agent.joints))
        if key not in chains:
            chains[key] = np.stack([trajectory.joint_skel_space(agent, clip, j) for j in joints], axis=1)
        source = chains[key] @ agent.skel_to_world[:, None]               # (F, 1 + feet, 4, 4)
        times, frames = ctx.output_frames(path)
        edited = animation.interp_frames(source, frames)
        moved = ctx.paths.get(path)
        if moved is not None:
            edited = edited @ trajectory.ground_motion(
                animation.interp_frames(traj.ground, frames), animation.interp_frames(traj.heading, frames),
                animation.interp_frames(moved.ground, frames), animation.interp_frames(moved.heading, frames),
                up)[:, None]
        seconds = 1.0 / info.time_codes_per_second
        skate = [float("nan"), float("nan")]
        keep = metrics.in_shot(times, info.start_time, info.end_time)   # the samples the shot plays
        if feet:
            units = (up, info.meters_per_unit, info.time_codes_per_second)
            # A retimed agent against its source as its timing plays it (see the feet pass).
            same = len(times) == len(agent.sample_times) and np.allclose(times, agent.sample_times)
            played = source if same else animation.interp_frames(source, frames)
            planted = foot_skate_of_positions(played[:, 1:, 3, :3], times, *units).contact & keep[:, None]
            before = foot_skate_of_positions(played[:, 1:, 3, :3], times, *units, contact=planted)
            skate = [before.mean, foot_skate_of_positions(edited[:, 1:, 3, :3], times, *units,
                                                                  contact=planted).mean]
        entry = ctx.report.agent(path)
        if entry.foot_skate_unlocked is not None:  # foot locking measured the legs as the layer plays them
            skate = [entry.foot_skate_source, entry.foot_skate_edited]
        first, stop = metrics.shot_window(keep, frames, len(agent.sample_times))
        p = plausibility_of(path, agent.sample_times[first:stop] * seconds, source[first:stop, 0],
                            times[keep] * seconds, edited[keep, 0], up, info.meters_per_unit, *skate,
                            edited_frames=frames[keep] - first)
        figures.append(p)
        processor.record_plausibility(entry, p, skate, frames[keep])
    if figures:
        ctx.report.stats.plausibility = ShotPlausibility.from_dict(metrics.worst_plausibility(figures))
