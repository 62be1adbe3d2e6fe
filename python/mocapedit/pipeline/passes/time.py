"""Time edits: world time and synchronised time constraints, speed matching.

Reads ``MocapTimeConstraint`` and ``MocapSyncConstraint`` prims and
``MocapSolveSettings.matchSpeed`` / ``minTimeInterval``, and fills ``ctx.time_maps``:
the shot time at which each source frame of an agent plays (sections 5.4.2.3, 5.4.2.4
and 5.4.2.6 of the deliverable). The warp itself is the solver's
(:func:`mocapedit.solve.time_warp.warp`): agents linked by sync constraints solve together, hard
constraints hold exactly, every interval stays at or above ``minTimeInterval`` times the
source interval, and contradicting constraints stop the solve with an error naming them.

With ``matchSpeed`` an agent whose path an earlier pass edited (``ctx.paths``) is first
re-timed so that it travels the edited path at its source speed; its time constraints
then warp that timing.

``processor.compose_edits`` samples each warped clip on the shot's whole frames (and at
the exact times of constrained frames that fall between them, see
:func:`mocapedit.solve.retime.shot_times`), and carries the edited path along at the same
fractional source frames, so space and time edits combine.
"""
from __future__ import annotations

import numpy as np

from mocapedit.geometry import ground
from mocapedit.model import limits
from mocapedit.solve import retime, time_warp
from mocapedit.model.errors import prim_error
from mocapedit.model.report import ConstraintEntry
from mocapedit.pipeline.context import SolveContext

MET = 1e-6  # time codes: a hard constraint's residual within this is met


def _validate(ctx: SolveContext) -> float:
    data = ctx.data
    fraction = float(data.settings.min_time_interval)   # in (0, 1]: limits.setting_problem
    for c in data.time_constraints:
        if not np.isfinite(c.time):
            raise prim_error(c.path, f"time must be a finite time code, got {c.time:g}", "time")
    for c in data.sync_constraints:
        if c.target == c.agent:
            raise prim_error(c.path, f"targets its own agent <{c.agent}>; a sync constraint ties two "
                             "different agents (use two time constraints to time one agent)", "target")
        if not np.isfinite(c.offset):
            raise prim_error(c.path, f"offset must be finite, got {c.offset:g}", "offset")
    return fraction


def _conflict_error(exc: time_warp.TimeWarpConflict, agents: list[str], ctx: SolveContext):
    times = [ctx.data.time_constraints[i] for i in exc.time_constraints]
    syncs = [ctx.data.sync_constraints[i] for i in exc.sync_constraints]
    prims = sorted({c.path for c in times} | {c.path for c in syncs})
    named = ", ".join(f"<{p}>" for p in prims)
    if exc.kind == "cycle":
        if not syncs:
            c = times[0]
            values = " and ".join(f"{t.time:g}" for t in times)
            message = (f"hard time constraints {named} put frame {c.frame} of <{c.agent}> at different "
                       f"times ({values}); keep one, or make the others soft")
        elif not times:
            message = (f"hard sync constraints {named} form a cycle whose offsets do not sum to zero "
                       f"(they miss by {exc.mismatch:g} time codes)")
        else:
            message = (f"hard time and sync constraints {named} fix the same frame's time twice and "
                       f"disagree by {exc.mismatch:g} time codes")
    else:
        if exc.agent >= 0:
            agent = agents[exc.agent]
            a, b = exc.frames
            gap, least = exc.gap, exc.minimum
            how = "backwards" if gap <= 0 else "faster than minTimeInterval allows"
            message = (f"hard constraints {named} would make time run {how} for <{agent}>: frame {b} "
                       f"would play {gap:g} time codes after frame {a}, and the least that allows is "
                       f"{least:g} (minTimeInterval {ctx.data.settings.min_time_interval:g})")
        else:
            message = (f"hard constraints {named} would make time run backwards (or faster than "
                       f"minTimeInterval {ctx.data.settings.min_time_interval:g} allows) for one of "
                       f"the agents they tie together")
    # The prim named first is given its own property: a time constraint's time, a sync
    # constraint's offset.
    prop = "time" if prims[0] in {c.path for c in times} else "offset"
    return prim_error(prims[0], message, prop)


def _root_position(ctx: SolveContext, agent: str, frame: int) -> list[float]:
    traj = ctx.trajectories[agent]
    edited = ctx.paths.get(agent)
    uv = (edited.ground if edited is not None else traj.ground)[frame]
    return ground.from_ground(uv, traj.height[frame], ctx.data.info.up_axis).tolist()


def run(ctx: SolveContext) -> None:
    data = ctx.data
    fraction = _validate(ctx)
    matched = sorted(ctx.paths) if data.settings.match_speed else []
    referenced = {c.agent for c in data.time_constraints}
    referenced |= {a for c in data.sync_constraints for a in (c.agent, c.target)}
    agents = sorted(referenced | set(matched))
    if not agents:
        return
    index = {a: i for i, a in enumerate(agents)}

    rest, minimum = [], []
    still = data.info.metres(1e-3)
    for path in agents:
        agent = data.agents[path]
        times = agent.sample_times.astype(np.float64)
        minimum.append(fraction * np.diff(times))
        if path in matched:
            times = retime.speed_matched_times(times, ctx.trajectories[path].ground, ctx.paths[path].ground,
                                               fraction, still)
        rest.append(times)

    tc, sc = data.time_constraints, data.sync_constraints
    time_frames = np.array([[index[c.agent], c.frame] for c in tc], dtype=np.int32).reshape(-1, 2)
    sync_frames = np.array([[index[c.agent], c.frame, index[c.target], c.target_frame] for c in sc],
                           dtype=np.int32).reshape(-1, 4)
    try:
        result = time_warp.warp(
            rest_times=rest, min_intervals=minimum, min_interval_fraction=fraction,
            time_frames=time_frames, time_hard=np.array([c.hard for c in tc], dtype=bool),
            time_weights=np.array([c.weight for c in tc], dtype=np.float64),
            times=np.array([c.time for c in tc], dtype=np.float64),
            sync_frames=sync_frames, sync_hard=np.array([c.hard for c in sc], dtype=bool),
            sync_weights=np.array([c.weight for c in sc], dtype=np.float64),
            offsets=np.array([c.offset for c in sc], dtype=np.float64))
    except time_warp.TimeWarpConflict as exc:
        raise _conflict_error(exc, agents, ctx) from None

    keys: dict[str, list[int]] = {a: [] for a in agents}
    for c in tc:
        keys[c.agent].append(c.frame)
    for c in sc:
        keys[c.agent].append(c.frame)
        keys[c.target].append(c.target_frame)
    enforced = []
    time_maps, solvers = result.time_maps, result.solver  # lists, converted once
    for i, path in enumerate(agents):
        agent = data.agents[path]
        time_map = time_maps[i]
        if np.array_equal(time_map, agent.sample_times):
            continue
        limits.check_time_map(path, agent.sample_times, time_map,
                              [c for c in tc if c.agent == path] + [c for c in sc if path in (c.agent, c.target)])
        ctx.time_maps[path] = time_map
        times = retime.shot_times(time_map, keys[path])
        if path in ctx.out_times:
            times = np.union1d(times, ctx.out_times[path])
        ctx.out_times[path] = times
        entry = ctx.report.agent(path)
        entry.min_interval = float(result.min_interval[i])
        entry.solver = "matchSpeed" if solvers[i] == "rest" else solvers[i]
        notes = []
        if path in matched:
            notes.append("time map matches the source speed along the edited path (matchSpeed)")
        held = int(result.min_enforced[i])
        if held:
            enforced.append(path)
            notes.append(f"time warp held {held} interval(s) at the minimum "
                         f"(minTimeInterval {fraction:g} of the source interval)")
        if notes:
            entry.add_notes(*notes)
        if solvers[i] == "SPQR fallback":
            ctx.report.note(f"time warp: a singular system for <{path}> was solved by {solvers[i]}")
    if enforced:
        named = ", ".join(f"<{p}>" for p in enforced[:10]) + (", ..." if len(enforced) > 10 else "")
        ctx.report.note(f"time warp: the minimum interval (minTimeInterval {fraction:g}) was enforced for "
                        f"{len(enforced)} agent(s): {named}")

    for c, residual in zip(tc, result.time_residuals):
        residual = float(residual)
        ctx.report.constraints.append(ConstraintEntry(
            prim=c.path, kind="time", agent=c.agent, frame=c.frame, hard=c.hard, residual=residual,
            met=residual <= MET, position=_root_position(ctx, c.agent, c.frame)))
    for c, residual in zip(sc, result.sync_residuals):
        residual = float(residual)
        ctx.report.constraints.append(ConstraintEntry(
            prim=c.path, kind="sync", agent=c.agent, frame=c.frame, target=c.target,
            target_frame=c.target_frame, hard=c.hard, residual=residual, met=residual <= MET,
            position=_root_position(ctx, c.agent, c.frame)))

