"""Collision avoidance between agents, and avoid regions (chapter 6, section 4.3.2).

A post-process on what the path and time passes produced: agents are
compared at constant shot-time steps (``MocapSolveSettings.sampleStep``) on their edited
paths, as time-warped, and pushed apart by re-solving their paths
(:mod:`mocapedit.solve.avoidance`) until no two capsules overlap or ``maxIterations`` is reached.
It runs when ``MocapSolveSettings.collisionAvoidance`` is on or ``mocapedit solve
--collisions`` asks for it. Active ``MocapAvoidRegion`` prims always apply: their agents
are kept out of the footprint by capsule radius plus margin, through the same solve.

A pose an agent holds before or after its clip (the shot is longer than the take) that
avoidance moves more than HELD_MOVED_M gets a note: one frame of its path stands for all the
time it holds, so its first or last steps veer to the new place. The note says how to keep
the pose (a hard position constraint at that frame), or why no pin can.

What held before holds after: every hard position constraint keeps its frame where it is,
every hard relative constraint keeps its offset, stationary ranges move rigidly. Agents
with ``mocap:collide = false`` are left alone. Walkers that wait (``maxWait``) get a time
map that plays them slower before the crossing and later from there on; agents that a
time, sync or relative constraint names keep their timing, and an agent that a hard position
constraint names waits only after that constraint's frame (the frame still plays when it did).

With ``MocapSolveSettings.pivotOnFeet`` on, the moved agents then turn between steps and pivot on
their planted feet (the stance pass, :mod:`mocapedit.pipeline.passes.stance`), which moves their
roots by a few centimetres, and the paths are solved once more from there, so that the overlaps
the pivot makes are cleared like any other. That solve moves some paths again, without regard to
the feet: they pivot once more on what it left, and an agent whose second pivot would meet another
agent (or a region) where the cleared paths did not keeps half of that pivot, then half of that,
down to a sixteenth, then none of it, until nothing new meets.

Report: ``stats`` ``collisionStrategy``, ``collisionIterations``, ``collisionsPerIteration``
(collision intervals found before each solve, then after the last), ``remainingOverlaps``,
``regionFramesLeft``, ``minSeparation``, ``delayedAgents`` and ``largestDelay`` (seconds),
``collisionStalled`` (when the iterations stopped making progress before
``maxIterations``); per agent ``minSeparation`` and ``delay`` (seconds it waited); one
``collision`` entry per overlap left (agent pair, shot time, where) and one
``avoid-region`` entry per agent a region had to push; notes naming agents hard
constraints hold together (once per hard relative constraint that holds two agents
closer than their clearance, naming it).

Bad input: two agents that waiting would part (crossing, or one behind the other) where
neither may wait and hard time or sync constraints fix when at least one of them plays,
and that stepping aside leaves overlapping, are an error naming both agents, the
constraints and the frames (the constraints leave no room for the delay). A capsule
radius above :data:`MAX_RADIUS_M` (no character is that wide; a
typing slip in it would push the whole crowd kilometres) is an error naming the agent
and ``mocap:collisionRadius``; so is a hard constraint that holds an agent inside an avoid
region it must keep out of (the error names both prims).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from mocapedit.solve import avoidance, collisions, path_edit, retime
from mocapedit.geometry import ground, trajectory
from mocapedit.usd import writer
from mocapedit.model.errors import prim_error
from mocapedit.pipeline.context import EditedPath, SolveContext
from mocapedit.pipeline.passes import stance
from mocapedit.model.progress import Silent
from mocapedit.model.report import ConstraintEntry, describe_left

#: Clearance (metres) up to which each agent's nearest neighbour is measured for the report.
SEPARATION_REACH_M = 2.0
#: Sides of the outline drawn for a circular region.
OUTLINE_SIDES = 64
REGION_COLOR = (0.9, 0.35, 0.1)
#: Largest capsule radius (metres) collision avoidance accepts.
MAX_RADIUS_M = 10.0
#: A pose held in the shot for at least this long (seconds: the clip ends before the shot does,
#: or starts after it) that avoidance moves further than HELD_MOVED_M (metres) gets a note.
HELD_NOTE_S = 0.5
HELD_MOVED_M = 0.25
#: The last pivot's shift pays itself back over this long (seconds), not the first's 2 s
#: (``stance.EASE_SECONDS``): it holds the planted feet more closely, and what it moves into
#: another agent is given up, not solved again. Measured on the example scenes, the moved
#: agents' skate before locking fell by a further 0.004 to 0.014 times the source's (8 s against
#: 2); the first pivot held as loosely sent a walker of a CMU crowd round, by the detour that
#: the clearing solve made for the larger shift.
LAST_PIVOT_EASE_SECONDS = 8.0
#: The share of its last pivot an agent keeps is halved where that pivot meets another agent, down
#: to this share; below it, none is kept. Measured on the example scenes, a sixteenth rather than
#: a quarter lowered `make demo`'s skate ratio before locking from 1.729 to 1.697 and changed no
#: other scene's.
PIVOT_SHARE_FLOOR = 1.0 / 16.0


def _settings(ctx: SolveContext):
    s = ctx.data.settings
    where = s.path or "MocapSolveSettings"
    if s.collision_strategy not in avoidance.STRATEGIES:
        raise prim_error(where, f"must be one of {', '.join(avoidance.STRATEGIES)}, got "
                         f"'{s.collision_strategy}'", "collisionStrategy")
    return s   # the other values were checked as they were read (limits.setting_problem)


def run(ctx: SolveContext) -> None:
    data = ctx.data
    info = data.info
    settings = _settings(ctx)
    footprints = [collisions.region_footprint(r, info.up_axis) for r in data.avoid_regions]
    enabled = settings.collision_avoidance if ctx.options.collisions is None else bool(ctx.options.collisions)
    if not enabled and not footprints:
        return
    names = [p for p in sorted(data.agents) if data.agents[p].collide]
    if len(names) < (2 if not footprints else 1):
        return
    _check_radii(ctx, names)
    problem = _problem(ctx, names, footprints, enabled)
    _check_pins_outside_regions(ctx, problem)
    solve_settings = avoidance.Settings(
        strategy=settings.collision_strategy, max_iterations=int(settings.max_iterations),
        meters_per_unit=info.meters_per_unit, max_wait_s=float(settings.max_wait),
        time_codes_per_second=float(info.time_codes_per_second))
    outcome = avoidance.resolve(problem, solve_settings, ctx.progress)
    _check_refused_waits(ctx, problem, outcome)
    _apply(ctx, problem, outcome)
    if settings.pivot_on_feet and _cleared(outcome):
        outcome = _pivot_and_clear(ctx, problem, footprints, enabled, solve_settings, outcome)
    ctx.pivoted = True
    _report(ctx, problem, outcome, enabled)
    _held_pose_notes(ctx, problem, outcome)
    _soft_timing_given_way(ctx, problem, outcome)
    if ctx.options.guides and data.avoid_regions:
        _region_guides(ctx, footprints)


def _holds(problem: avoidance.Problem, fps: float) -> list[tuple[int, int, float, float]]:
    """(agent, frame, first, last shot time) of each pose held at least HELD_NOTE_S in the shot:
    the last frame while the shot goes on after the clip ends, the first before it starts."""
    out = []
    if problem.span is None:
        return out
    lo, hi = problem.span
    for i, times in enumerate(problem.frame_times):
        if len(times) < 2:
            continue
        first, last = float(times[0]), float(times[-1])
        if (first - lo) / fps >= HELD_NOTE_S:
            out.append((i, 0, lo, first))
        if (hi - last) / fps >= HELD_NOTE_S:
            out.append((i, len(times) - 1, last, hi))
    return out


def _moved_holds(ctx: SolveContext, problem: avoidance.Problem,
                 outcome: avoidance.Outcome) -> list[tuple[float, int, tuple[int, int, float, float]]]:
    """(distance, agent, hold) of each held pose (:func:`_holds`, on the timing after waiting)
    that avoidance moved more than HELD_MOVED_M, furthest first."""
    info = ctx.data.info
    timed = dataclasses.replace(problem, frame_times=outcome.frame_times or problem.frame_times)
    out = []
    for hold in _holds(timed, info.time_codes_per_second):
        i, frame = hold[0], hold[1]
        if not outcome.moved[i]:
            continue
        moved = float(np.linalg.norm(outcome.paths[i][frame] - problem.paths[i][frame]))
        if moved > info.metres(HELD_MOVED_M):
            out.append((moved, i, hold))
    out.sort(key=lambda item: (-item[0], item[1], item[2][1]))
    return out


def _pin_advice(problem: avoidance.Problem, holds: list, fps: float) -> dict:
    """(agent, frame) -> how to keep each held pose of ``holds`` (:func:`_holds`) where it is: a
    hard MocapPositionConstraint at that frame, unless a pin cannot hold it there (an artist
    constraint holds that frame, it stands within an avoid region's clearance, where a pin is an
    error, or it overlaps a pose an artist pin holds at the same time). A pose that overlaps
    another held pose while both hold: pin one, and the other gives way."""
    names = problem.names
    taken = {(pin.agent, pin.frame): pin.name for pin in problem.pins}
    taken.update({(a, f): link.name for link in problem.links for a, f in ((link.a, link.fa), (link.b, link.fb))})
    blocked: dict[tuple[int, int], str] = {}
    for i, frame, _, _ in holds:
        if (i, frame) in taken:
            blocked[(i, frame)] = f"<{taken[(i, frame)]}> holds that frame"
            continue
        for region in problem.regions:
            at = np.searchsorted(region.agents, i)
            if (at < len(region.agents) and region.agents[at] == i and float(collisions.signed_distance(
                    region.footprint, problem.paths[i][frame][None])[0]) < region.clearance[at]):
                blocked[(i, frame)] = f"it stands within avoid region <{region.name}>'s clearance"
                break
    # What stands still while each holds: the other held poses (these first), and the artist's
    # hard pins (over all the time a pinned pose holds).
    every = _holds(problem, fps)
    spans = {(i, frame): (t0, t1) for i, frame, t0, t1 in every}
    given = {tuple(h[:2]) for h in holds}
    fixed = [(i, problem.paths[i][frame], t0, t1, None)
             for i, frame, t0, t1 in list(holds) + [h for h in every if tuple(h[:2]) not in given]]
    for pin in problem.pins:
        if pin.softness == 0:
            t = float(problem.frame_times[pin.agent][pin.frame])
            fixed.append((pin.agent, pin.position, *spans.get((pin.agent, pin.frame), (t, t)), pin.name))
    paired: dict[tuple[int, int], list[str]] = {}
    if fixed:
        agents = np.array([f[0] for f in fixed], dtype=np.int64)
        found = collisions.detect_at(np.array([f[1] for f in fixed], dtype=np.float64)[None],
                                     problem.radius[agents], problem.height[agents], problem.margin)
        for a, b in zip(found.agent_a, found.agent_b):
            (ia, _, a0, a1, pin_a), (ib, _, b0, b1, pin_b) = fixed[a], fixed[b]
            if ia == ib or a0 > b1 or b0 > a1:
                continue
            for k, other, pin in ((a, ib, pin_b), (b, ia, pin_a)):
                if k >= len(holds):
                    continue
                key = tuple(holds[k][:2])
                if pin is not None:
                    blocked.setdefault(key, f"it overlaps <{names[other]}>, held by <{pin}>, at the same time")
                else:
                    paired.setdefault(key, []).append(f"<{names[other]}>")
    out = {}
    for i, frame, _, _ in holds:
        key = (i, frame)
        if key in blocked:
            out[key] = f"a pin could not keep it where it is ({blocked[key]}): move the agent, or offset its clip in time"
            continue
        out[key] = ("to keep the pose where it is and have the others go round it, pin it: a hard "
                    f"MocapPositionConstraint at frame {frame} at its position there")
        if key in paired:
            out[key] += (f" (not together with {', '.join(sorted(set(paired[key])))}, whose held pose it overlaps "
                         "then: pin one, and the other gives way)")
    return out


def _held_pose_notes(ctx: SolveContext, problem: avoidance.Problem, outcome: avoidance.Outcome) -> None:
    """A note on each agent whose pose held before or after its clip (the shot starts before
    the clip or ends after it) avoidance moved more than HELD_MOVED_M: its first or last steps
    turn into the new place. Pinned (a hard position constraint at that frame), the pose stays
    and the others go round it: the note says how (:func:`_pin_advice`), and one note for the
    run counts them."""
    info = ctx.data.info
    fps = info.time_codes_per_second
    noted = _moved_holds(ctx, problem, outcome)
    if not noted:
        return
    advice = _pin_advice(problem, [hold for _, _, hold in noted], fps)
    for moved, i, (_, frame, _, _) in noted:
        times = outcome.frame_times[i] if outcome.frame_times else problem.frame_times[i]
        when = "after its clip ends" if frame else "before its clip starts"
        span = (f"from {float(times[-1]) / fps:.1f} s to the shot's end" if frame else
                f"from the shot's start to {float(times[0]) / fps:.1f} s")
        ctx.report.agent(problem.names[i]).add_notes(
            f"collision avoidance moved the pose it holds {when} ({span}) by {moved:.3g} stage units "
            f"({moved * info.meters_per_unit:.2f} m), and its {'last' if frame else 'first'} steps turn to "
            f"reach the new place; {advice[(i, frame)]}")
    most = ", ".join(f"<{problem.names[i]}> {moved * info.meters_per_unit:.2f} m" for moved, i, _ in noted[:3])
    ctx.report.note(f"collision avoidance moved the pose {len(noted)} agent{'s' if len(noted) > 1 else ''} "
                    f"hold{'' if len(noted) > 1 else 's'} before or after their clips more than "
                    f"{HELD_MOVED_M:g} m ({most}{', ...' if len(noted) > 3 else ''}): their first or last "
                    "steps veer to reach it; each agent's note says how to keep the pose")


def _check_radii(ctx: SolveContext, names: list[str]) -> None:
    largest = ctx.data.info.metres(MAX_RADIUS_M)
    for name in names:
        radius = ctx.data.agents[name].collision_radius
        if radius > largest:
            raise prim_error(name, f"collision radius {radius:g} is more than {MAX_RADIUS_M:g} m "
                             f"({largest:g} stage units): no character is that wide", "mocap:collisionRadius")


def _check_pins_outside_regions(ctx: SolveContext, problem: avoidance.Problem) -> None:
    """A hard constraint holding an agent inside a region it must avoid contradicts the region."""
    for region in problem.regions:
        for pin in problem.pins:
            at = np.searchsorted(region.agents, pin.agent)
            if pin.softness != 0 or at >= len(region.agents) or region.agents[at] != pin.agent:
                continue
            clearance = region.clearance[at]
            depth = clearance - float(collisions.signed_distance(region.footprint, pin.position[None])[0])
            if depth > 1e-6 * max(clearance, 1.0):
                raise prim_error(pin.name, f"holds agent <{problem.names[pin.agent]}> at frame {pin.frame} "
                                 f"{depth:g} stage units inside avoid region <{region.name}> (its footprint grown "
                                 "by the agent's collision radius and the region's margin); move the constraint "
                                 "or the region, or make one of them soft or inactive")


def _time_holds(ctx: SolveContext) -> dict[str, list[tuple[str, int]]]:
    """Agent -> (prim, frame) of each hard time or sync constraint that fixes when it plays."""
    holds: dict[str, list[tuple[str, int]]] = {}
    for c in ctx.data.time_constraints:
        if c.hard:
            holds.setdefault(c.agent, []).append((c.path, c.frame))
    for c in ctx.data.sync_constraints:
        if c.hard:
            holds.setdefault(c.agent, []).append((c.path, c.frame))
            holds.setdefault(c.target, []).append((c.path, c.target_frame))
    return holds


def _check_refused_waits(ctx: SolveContext, problem: avoidance.Problem, outcome: avoidance.Outcome) -> None:
    """A pair that waiting would part, that hard time constraints keep from waiting and that
    stepping aside did not part either, is an error naming the agents, the constraints and
    the frames: the constraints leave no room for the delay the crossing needs."""
    if not outcome.wait_refused or not len(outcome.remaining):
        return
    holds = _time_holds(ctx)
    names, left, sampling = problem.names, outcome.remaining, outcome.sampling
    blocked = {(min(a, b), max(a, b)) for a, b, _ in outcome.blocked}
    blocked |= {(min(a, b), max(a, b)) for _, a, b, _, _, _ in outcome.link_held}
    for a, b, k, depth in zip(left.agent_a.tolist(), left.agent_b.tolist(), left.deepest.tolist(), left.depth.tolist()):
        pair = (min(a, b), max(a, b))
        prims = [(p, f, names[i]) for i in pair for p, f in holds.get(names[i], [])]
        if pair not in outcome.wait_refused or pair in blocked or not prims:
            continue
        meet = {i: int(round(sampling.frames[k, i])) for i in pair}
        held = ", ".join(f"<{p}> (frame {f} of <{agent}>)" for p, f, agent in prims)
        raise prim_error(prims[0][0], (
            f"agents <{names[pair[0]]}> (frame {meet[pair[0]]}) and <{names[pair[1]]}> (frame {meet[pair[1]]}) "
            f"still overlap by {depth:g} stage units at shot time {float(sampling.times[k]):g}: one of them must "
            f"wait for the other, but neither may: their timing is fixed, by the hard time or sync constraints "
            f"{held}, and stepping aside did not part them; make those constraints soft (a soft one gives way "
            "to a wait, unless hard position or relative constraints on the agent also fix its timing), move "
            "a constraint's time (a sync constraint's offset) so that one of them reaches the meeting later, "
            "remove one, or give avoidance room to steer (fewer hard position constraints or avoid regions "
            "near the meeting)"))


def _problem(ctx: SolveContext, names: list[str], footprints, enabled: bool) -> avoidance.Problem:
    data = ctx.data
    index = {p: i for i, p in enumerate(names)}
    paths, times = [], []
    for p in names:
        edited = ctx.paths.get(p)
        paths.append(np.array(edited.ground if edited is not None else ctx.trajectories[p].ground, dtype=np.float64))
        times.append(np.asarray(ctx.time_maps.get(p, data.agents[p].sample_times), dtype=np.float64))
    agents = [data.agents[p] for p in names]
    # Constraints fix the timing of the agents they name: a time or sync constraint states
    # it, a relative constraint meets another agent at a moment.
    # A soft time or sync constraint gives way to a wait (the report says by how much).
    timed = {c.agent for c in data.time_constraints if c.hard}
    timed |= {a for c in data.sync_constraints if c.hard for a in (c.agent, c.target)}
    timed |= {a for c in data.relative_constraints for a in (c.agent, c.target)}
    # A hard position constraint puts the agent at its frame at that moment: the agent may wait
    # after it (the frame still plays then), not before.
    pinned_until = {}
    for c in data.position_constraints:
        if c.hard:
            pinned_until[c.agent] = max(pinned_until.get(c.agent, -1), int(c.frame))
    problem = avoidance.Problem(
        names=names, paths=paths, frame_times=times,
        radius=np.array([a.collision_radius for a in agents]), height=np.array([a.collision_height for a in agents]),
        margin=float(data.settings.margin), sample_step=float(data.settings.sample_step), collide_agents=enabled,
        fixed_timing=np.array([p in timed for p in names], dtype=bool),
        waits_after=np.array([pinned_until.get(p, -1) for p in names], dtype=np.int64),
        samples_per_second=np.array([trajectory.samples_per_second(a.sample_times, data.info.time_codes_per_second)
                                     for a in agents]),
        # Only what plays in the shot is parted: a long clip's walk after the shot ends (or
        # before it starts) is never seen, and pushes there would bend what is.
        span=data.info.shot_span(min((float(t[0]) for t in times), default=0.0),
                                 max((float(t[-1]) for t in times), default=0.0)))
    for i, a in enumerate(agents):
        problem.rigid.extend((i, first, last) for _, first, last in a.stationary)
    # What the artist fixed stays where it is now.
    pinned = set()
    for c in data.position_constraints:
        if c.hard and c.agent in index and (c.agent, c.frame) not in pinned:
            pinned.add((c.agent, c.frame))
            i = index[c.agent]
            problem.pins.append(avoidance.Pin(i, c.frame, paths[i][c.frame].copy(), name=c.path))
    for c in data.relative_constraints:
        if not c.hard:
            continue
        a, b = index.get(c.agent), index.get(c.target)
        if a is not None and b is not None:
            problem.links.append(avoidance.Link(a, c.frame, b, c.target_frame,
                                                paths[a][c.frame] - paths[b][c.target_frame], name=c.path))
        else:   # the other agent does not move: this one stays put at that frame
            for i, f in ((a, c.frame), (b, c.target_frame)):
                if i is not None and (names[i], f) not in pinned:
                    pinned.add((names[i], f))
                    problem.pins.append(avoidance.Pin(i, f, paths[i][f].copy(), name=c.path))
    for region, footprint in zip(data.avoid_regions, footprints):
        members = [index[p] for p in collisions.region_agents(region, names)]
        members = np.array(sorted(members), dtype=np.int64)
        problem.regions.append(avoidance.Region(region.path, footprint, members,
                                                problem.radius[members] + region.margin))
    return problem


def _cleared(outcome: avoidance.Outcome) -> bool:
    """Whether the solve cleared everything it could: no avoid-region frame left, and no overlap
    but those of pairs that hard constraints hold together."""
    held = {(min(a, b), max(a, b)) for a, b, _ in outcome.blocked}
    held |= {(min(a, b), max(a, b)) for _, a, b, _, _, _ in outcome.link_held}
    left = zip(outcome.remaining.agent_a.tolist(), outcome.remaining.agent_b.tolist())
    return not outcome.region_left and all((min(a, b), max(a, b)) in held for a, b in left)


def _pivot_and_clear(ctx: SolveContext, problem: avoidance.Problem, footprints, enabled: bool,
                     solve_settings: avoidance.Settings, outcome: avoidance.Outcome) -> avoidance.Outcome:
    """The moved agents pivot on their feet (the stance pass), which moves their roots by a few
    centimetres, and the paths are solved again from there, so that what the pivot moves into
    another agent (or a region) is cleared as any overlap is; then they pivot once more where
    that meets nobody (:func:`_pivot_where_clear`). Pairs that hard constraints hold closer than
    their clearance keep their paths (their partings are tight already); a shot that the second
    solve does not clear as well as the first keeps the first's paths."""
    names = problem.names
    held = {names[i] for _, a, b, _, _, _ in outcome.link_held for i in (a, b)}
    held |= {names[i] for a, b, _ in outcome.blocked for i in (a, b)}
    kept = (dict(ctx.paths), dict(ctx.time_maps), dict(ctx.out_times))
    # The walkers keep their way as the first solve was given it, not as it left them.
    first_paths = problem.paths
    feet: dict = {}
    stance.pivot_moved(ctx, keep=held, feet=feet)
    again = _problem(ctx, names, footprints, enabled)
    again.way = first_paths
    # What a pivot moves is a few centimetres: stepped aside from, never waited for (a wait
    # plays a walker in slow motion).
    second = avoidance.resolve(again, dataclasses.replace(solve_settings, max_wait_s=0.0), Silent())
    if len(second.remaining) > len(outcome.remaining) or len(second.region_left) > len(outcome.region_left):
        for now, before in zip((ctx.paths, ctx.time_maps, ctx.out_times), kept):
            now.clear()
            now.update(before)
        return outcome
    _apply(ctx, again, second)
    if _cleared(second):
        _pivot_where_clear(ctx, names, footprints, enabled, solve_settings, held, feet, second)
    return _merged(outcome, second)


def _pivot_where_clear(ctx: SolveContext, names: list[str], footprints, enabled: bool,
                       solve_settings: avoidance.Settings, keep: set[str], feet: dict,
                       cleared_by: avoidance.Outcome) -> None:
    """The moved agents but those in ``keep`` pivot on their feet once more, on the paths the
    clearing solve ``cleared_by`` left (``feet``: their source feet, kept from the first pivot,
    :func:`stance.pivot_moved`). Then, round by round, each agent that a new overlap names (a
    pair the cleared paths did not have, or a frame in a region's clearance) keeps half of what
    its pivot moved, then half of that, down to :data:`PIVOT_SHARE_FLOOR`, then none: the cleared
    paths have no new overlap, so the rounds end."""
    cleared = dict(ctx.paths)
    found = cleared_by.remaining
    before = set(zip(found.agent_a.tolist(), found.agent_b.tolist()))
    before_inside = {a for _, a, _, _ in cleared_by.region_left}
    stance.pivot_moved(ctx, keep=keep, feet=feet, ease_seconds=LAST_PIVOT_EASE_SECONDS)
    feet.clear()    # not needed again: freed before the problem is sampled once more
    pivoted = {p: e for p, e in ctx.paths.items() if e is not cleared.get(p)}
    share = {p: 1.0 for p in pivoted}
    uncleared = avoidance.Uncleared(_problem(ctx, names, footprints, enabled), solve_settings)
    while True:
        pairs, inside = uncleared([ctx.paths[p].ground if p in ctx.paths else ctx.trajectories[p].ground
                                   for p in names])
        new = {i for pair in pairs - before for i in pair} | (inside - before_inside)
        back = [names[i] for i in sorted(new) if share.get(names[i], 0.0) > 0.0]
        if not back:
            return
        for p in back:
            share[p] = share[p] / 2 if share[p] > PIVOT_SHARE_FLOOR else 0.0
            a, b = cleared[p], pivoted[p]
            ctx.paths[p] = EditedPath(ground=a.ground + share[p] * (b.ground - a.ground),
                                      heading=a.heading + share[p] * (b.heading - a.heading))


def _merged(first: avoidance.Outcome, second: avoidance.Outcome) -> avoidance.Outcome:
    """The outcome of two solves, the second from where the first left the paths: the final
    state, with the iterations, delays and moves of both."""
    def added(a: dict, b: dict) -> dict:
        return {k: a.get(k, 0) + b.get(k, 0) for k in {**a, **b}}
    return dataclasses.replace(
        second, iterations=first.iterations + second.iterations[1:], moved=first.moved | second.moved,
        delays=first.delays + second.delays, solves=first.solves + second.solves,
        seconds=first.seconds + second.seconds, timing=added(first.timing, second.timing),
        work=added(first.work, second.work), kept_direction=sorted(set(first.kept_direction) | set(second.kept_direction)),
        link_held=_held_over_both(first.link_held, second.link_held),
        wait_refused=first.wait_refused | second.wait_refused,
        detour_iterations=first.detour_iterations + second.detour_iterations[1:])


def _held_over_both(first: list, second: list) -> list:
    """Hard links that hold a pair closer than its clearance in either solve, each over the times
    either holds it."""
    out: dict = {}
    for name, a, b, t0, t1, distance in first + second:
        held = out.get((name, a, b))
        out[(name, a, b)] = (name, a, b, t0, t1, distance) if held is None else \
            (name, a, b, min(held[3], t0), max(held[4], t1), min(held[5], distance))
    return list(out.values())


def _apply(ctx: SolveContext, problem: avoidance.Problem, outcome: avoidance.Outcome) -> None:
    info = ctx.data.info
    for i in np.flatnonzero(outcome.delays > 0):
        name = problem.names[i]
        ctx.time_maps[name] = outcome.frame_times[i]
        if name in ctx.out_times:
            ctx.out_times[name] = retime.shot_times(outcome.frame_times[i])
    # The body turns by the rotation the avoidance applies to its path locally (the path
    # editor's rule), each rigid range by its own angle: never by a tangent that the jitter
    # of a standing root can flip. Agents whose turn windows are the same are turned in one call
    # (each is a block of its own: the same turns as one call each).
    rigid: dict[int, list[int]] = {}
    for k, (a, _, _) in enumerate(problem.rigid):
        rigid.setdefault(a, []).append(k)
    by_window: dict[tuple, list[int]] = {}
    for i, name in enumerate(problem.names):
        if not outcome.moved[i]:
            continue
        # Windows in seconds count this agent's own samples (a 120 fps clip on a 24 fps stage).
        window = path_edit.turn_settings(trajectory.samples_per_second(ctx.data.agents[name].sample_times,
                                                                       info.time_codes_per_second),
                                         info.meters_per_unit)
        key = (window["turn_window"], window["turn_min_travel"], window["turn_max_step"])
        by_window.setdefault(key, []).append(i)
    turned: dict[int, np.ndarray] = {}
    for (turn_window, min_travel, max_step), members in by_window.items():
        offsets = np.cumsum([0] + [len(outcome.paths[i]) for i in members])
        ranges = [(b, problem.rigid[k][1], problem.rigid[k][2]) for b, i in enumerate(members) for k in rigid.get(i, ())]
        angles = [outcome.rigid_angles[k] for i in members for k in rigid.get(i, ())]
        turns = trajectory.deformation_turns(
            np.concatenate([problem.paths[i] for i in members]), np.concatenate([outcome.paths[i] for i in members]),
            offsets, ranges, angles, turn_window, min_travel, max_step)
        turned.update((i, turns[offsets[b]:offsets[b + 1]]) for b, i in enumerate(members))
    for i in sorted(turned):
        name = problem.names[i]
        before = ctx.paths.get(name)
        heading = before.heading if before is not None else ctx.trajectories[name].heading
        ctx.paths[name] = EditedPath(ground=outcome.paths[i], heading=np.asarray(heading) + turned[i])


def _soft_timing_given_way(ctx: SolveContext, problem: avoidance.Problem, outcome: avoidance.Outcome) -> None:
    """The residuals of soft time and sync constraints on agents that waited, on their new
    time maps, and a note for each that the wait moved."""
    data = ctx.data
    fps = data.info.time_codes_per_second
    delay = {problem.names[i]: float(outcome.delays[i]) / fps for i in np.flatnonzero(outcome.delays > 0)}
    if not delay:
        return

    def at(agent: str, frame: int) -> float:
        return float(np.asarray(ctx.time_maps.get(agent, data.agents[agent].sample_times))[frame])

    moved = [(c, "time", (c.agent,), abs(at(c.agent, c.frame) - c.time))
             for c in data.time_constraints if not c.hard and c.agent in delay]
    moved += [(c, "sync", (c.agent, c.target), abs(at(c.agent, c.frame) - at(c.target, c.target_frame) - c.offset))
              for c in data.sync_constraints if not c.hard and (c.agent in delay or c.target in delay)]
    for c, kind, agents, residual in moved:
        for entry in ctx.report.constraints:
            if entry.prim == c.path and entry.kind == kind:
                entry.residual, entry.met = float(residual), bool(residual <= 1e-6)
        waits = ", ".join(f"<{a}> waits {delay[a]:g} s" for a in agents if a in delay)
        ctx.report.note(f"<{c.path}> is soft and gives way to collision avoidance ({waits}): its residual is "
                        f"now {residual:g} time codes")


def _world(ctx: SolveContext, uv: np.ndarray) -> np.ndarray:
    return ground.from_ground(np.asarray(uv, dtype=np.float64), 0.0, ctx.data.info.up_axis)


def _report(ctx: SolveContext, problem: avoidance.Problem, outcome: avoidance.Outcome, enabled: bool) -> None:
    data, report = ctx.data, ctx.report
    names = problem.names
    settings_prim = data.settings.path
    stats = report.stats
    stats.collision_strategy = data.settings.collision_strategy
    stats.collision_iterations = len(outcome.iterations) - 1
    stats.collisions_per_iteration = [it.collisions for it in outcome.iterations]
    stats.remaining_overlaps = len(outcome.remaining)
    stats.region_frames_left = len(outcome.region_left)
    if outcome.kept_direction:
        kept = [names[a] for a in outcome.kept_direction]
        report.note(f"collision avoidance would have sent {len(kept)} agent{'s' if len(kept) > 1 else ''} back "
                    "against the way they walk (" + ", ".join(f"<{n}>" for n in kept[:5])
                    + (", ..." if len(kept) > 5 else "") + "): they keep their paths, and the overlaps they "
                    "leave are listed in the collision entries; move them or their neighbours, or make them wait with "
                    "time constraints")
    # Nearest neighbour of each agent on the final paths, within reach.
    reach = data.info.metres(SEPARATION_REACH_M)
    final = collisions.detect(outcome.sampling, problem.radius, problem.height, problem.margin,
                              report_distance=problem.margin + reach,
                              active=np.full(len(names), enabled))
    clearance = final.min_clearance
    if enabled:
        for name, c in zip(names, clearance):
            if np.isfinite(c):
                report.agent(name).min_separation = float(c)
        if np.isfinite(clearance).any():
            stats.min_separation = float(np.min(clearance))
    fps = data.info.time_codes_per_second
    delayed = np.flatnonzero(outcome.delays > 0)
    if enabled and data.settings.max_wait > 0:
        stats.delayed_agents = int(len(delayed))
        stats.largest_delay = float(outcome.delays.max(initial=0.0) / fps)
    for i in delayed:
        report.agent(names[i]).delay = float(outcome.delays[i] / fps)
    times = outcome.sampling.times
    blocked = {(a, b) for a, b, _ in outcome.blocked}
    left = outcome.remaining
    for a, b, k, depth in zip(left.agent_a, left.agent_b, left.deepest, left.depth):
        pa, pb = outcome.sampling.positions[k, a], outcome.sampling.positions[k, b]
        report.constraints.append(ConstraintEntry(
            prim=settings_prim, kind="collision", agent=names[a], target=names[b],
            frame=int(round(outcome.sampling.frames[k, a])), target_frame=int(round(outcome.sampling.frames[k, b])),
            time=float(times[k]), hard=False, residual=float(depth), met=False,
            held_by_constraints=(int(a), int(b)) in blocked,
            position=_world(ctx, 0.5 * (pa + pb)).tolist()))
    by_link = {(a, b): (t0, t1) for _, a, b, t0, t1, _ in outcome.link_held}
    for name, a, b, t0, t1, distance in outcome.link_held:
        report.note(f"<{name}> holds agents <{names[a]}> and <{names[b]}> {distance:g} apart, closer than "
                    f"their clearance ({problem.radius[a] + problem.radius[b] + problem.margin:g}): they are "
                    f"not pushed apart from time {t0:g} to {t1:g}; the rest of their shot is")
    for a, b, t in outcome.blocked:
        t0, t1 = by_link.get((min(a, b), max(a, b)), (np.inf, -np.inf))
        if t0 <= t <= t1:
            continue
        report.note(f"agents <{names[a]}> and <{names[b]}> cannot be separated at time {t:g}: hard "
                    "constraints hold both of them there")
    _region_entries(ctx, problem, outcome)
    its = stats.collisions_per_iteration
    if enabled:
        left_text = describe_left(len(left), len(outcome.region_left))
        how = (f"{its[0]} collision interval{'s' if its[0] != 1 else ''} at first, {left_text} after "
               f"{stats.collision_iterations} iteration{'s' if stats.collision_iterations != 1 else ''} "
               f"({problem.names and stats.collision_strategy})")
        report.note(f"collision avoidance: {how}")
        ran_out = outcome.stalled or stats.collision_iterations >= data.settings.max_iterations
        # (Overlaps left by the guard against walking back have their own note.)
        if len(left) and not blocked and ran_out:
            why = (f"after {stats.collision_iterations} iterations without progress "
                   "(constraints that cannot all hold)" if outcome.stalled
                   else f"at maxIterations ({data.settings.max_iterations})")
            last = its[-3:]
            if not outcome.stalled and len(last) == 3 and 0 < last[-1] < last[0]:
                # Still parting them when the iterations ran out: more would likely finish the job.
                report.note(f"collision avoidance stopped {why} with {left_text}, still parting them "
                            f"({', '.join(map(str, last))} collision intervals over the last iterations): raise "
                            f"maxIterations on <{settings_prim}>, or move the agents the collision entries name")
            else:
                report.note(f"collision avoidance stopped {why} with {left_text}; see the collision entries")
        _note_starting_overlaps(ctx, problem)
    if outcome.stalled:
        stats.collision_stalled = True
        if outcome.region_left:
            report.note(f"avoid regions: {len(outcome.region_left)} frames left inside after "
                        f"{stats.collision_iterations} iterations without progress (constraints that cannot "
                        "all hold); see the avoid-region entries")


def _note_starting_overlaps(ctx: SolveContext, problem: avoidance.Problem) -> None:
    """A note naming the pairs whose capsules already overlap where the shot starts, on the paths
    avoidance was given: agents placed inside each other are pushed apart from their first frame,
    which bends their paths the most (and a crowd full of them may not clear)."""
    if not problem.names or not problem.collide_agents:
        return
    start = problem.span[0] if problem.span is not None else min(float(t[0]) for t in problem.frame_times)
    at = np.array([start])
    positions = np.stack([collisions.positions_at(np.asarray(path, dtype=np.float64),
                                                  collisions.frames_at(np.asarray(times, dtype=np.float64), at))
                          for path, times in zip(problem.paths, problem.frame_times)], axis=1)
    found = collisions.detect_at(positions, problem.radius, problem.height, 0.0)
    if len(found) == 0:
        return
    names = problem.names
    order = np.argsort(-found.depth, kind="stable")
    pairs = [f"<{names[found.agent_a[k]]}> and <{names[found.agent_b[k]]}> by {found.depth[k]:.3g}"
             for k in order[:3]]
    count = len(found)
    more = f" and {count - 3} more" if count > 3 else ""
    ctx.report.note(
        f"{count} agent pair{'s' if count != 1 else ''} already overlap{'' if count != 1 else 's'} where the shot "
        f"starts (time {start:g}; stage units): {', '.join(pairs)}{more}. Agents placed inside each other are "
        "pushed apart from their first frame, which bends their paths the most; place them apart (their "
        "translate) or offset their clips in time")


def _region_entries(ctx: SolveContext, problem: avoidance.Problem, outcome: avoidance.Outcome) -> None:
    """One avoid-region entry per (region, agent) that the region had to push or still holds."""
    names = problem.names
    worst: dict[tuple[int, int], tuple[float, int]] = {}
    for r, a, f, depth in outcome.region_left:
        if depth > worst.get((r, a), (0.0, 0))[0]:
            worst[(r, a)] = (depth, f)
    for r, region in enumerate(problem.regions):
        if len(region.agents) == 0:
            continue
        flat = np.concatenate([problem.paths[a] for a in region.agents])
        owner = np.concatenate([np.full(len(problem.paths[a]), a) for a in region.agents])
        push = collisions.push_out(region.footprint, flat, region.clearance[np.searchsorted(region.agents, owner)])
        touched = sorted(set(owner[push.index].tolist()) | {a for (rr, a) in worst if rr == r})
        for a in touched:
            depth, frame = worst.get((r, a), (0.0, None))
            if frame is None:
                frame = int(np.argmin(collisions.signed_distance(region.footprint, outcome.paths[a])))
            ctx.report.constraints.append(ConstraintEntry(
                prim=region.name, kind="avoid-region", agent=names[a], frame=int(frame), hard=True,
                residual=float(depth), met=depth <= 1e-6, position=_world(ctx, outcome.paths[a][frame]).tolist()))


def _region_guides(ctx: SolveContext, footprints) -> None:
    info = ctx.data.info
    curves = []
    for region, footprint in zip(ctx.data.avoid_regions, footprints):
        for grow in (0.0, region.margin):
            if grow == 0.0 and curves and region.margin == 0.0:
                continue
            outline = collisions.outline(footprint, grow, OUTLINE_SIDES)
            curves.append(ground.from_ground(np.vstack([outline, outline[:1]]), info.metres(0.05), info.up_axis))
    ctx.guides.append(writer.GuideCurves(
        name="AvoidRegions", curves=curves, color=REGION_COLOR, width=info.metres(0.03),
        doc="Each avoid region's ground footprint and, when it has a margin, the footprint grown by it."))

