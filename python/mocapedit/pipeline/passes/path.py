"""Path edits: position and relative constraints, stationary tags, path curves
and groups (chapters 4 and 5 of the deliverable).

Agents tied together by relative constraints or groups form a component; each component
with something to do (a position or relative constraint, a path curve) is one two-step
ARAP solve (:mod:`mocapedit.solve.path_edit`), independent of the others, so components run on
a thread pool with the solver releasing the GIL. An agent's result does not depend on
what else is on the stage.

Fills ``ctx.paths`` (ground path and heading per source frame), a report entry per
position constraint, relative constraint, stationary range and path curve of the edited
agents, and per agent ``lengthRatio``, ``shapeChange`` and ``solver``.
"""
from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from mocapedit.geometry import contacts, curves, ground, trajectory
from mocapedit.geometry.components import UnionFind
from mocapedit.inspect import metrics
from mocapedit.solve import path_edit
from mocapedit.solve.path_edit import MIN_BASELINE_M
from mocapedit.model.errors import MocapEditError, prim_error
from mocapedit.model.report import ConstraintEntry
from mocapedit.pipeline.context import EditedPath, SolveContext, consecutive_runs

MET = 1e-6  # stage units: a hard constraint's residual within this is met

#: A path curve holds its agent on the remapped path by soft handles this far apart (s),
#: so other constraints bend the path away from the curve only where they act.
CURVE_ANCHOR_S = 0.5
CURVE_ANCHOR_WEIGHT = 0.05
#: Towards a frame that another constraint moves, the anchors fade out over this many seconds
#: (smoothly, to nothing at that frame): the path leaves the curve gradually, so the change of
#: its length spreads over the walk instead of piling up between the constraint and the
#: nearest anchor (a walk stretched there by half plays its steps half as fast again: the
#: feet slide).
CURVE_ANCHOR_FADE_S = 3.0
#: Lengths that set the solve's tolerances, in metres (and path_edit.MIN_BASELINE_M).
RIGID_MIN_EXTENT_M = 0.02  # smaller stationary ranges turn with the path around them
STILL_M = 1e-5             # as trajectory.headings: tangents shorter than this stand still
#: A group's mesh joins its members this often (seconds); the frames between follow.
GROUP_SAMPLE_S = 0.5


def _validate(ctx: SolveContext) -> None:
    for c in ctx.data.relative_constraints:
        if c.agent == c.target and c.frame == c.target_frame:
            raise prim_error(c.path, f"ties frame {c.frame} of <{c.agent}> to itself; the target (or the target "
                             "frame) must differ from the agent's", "target")
        if not np.all(np.isfinite(c.offset)):
            raise prim_error(c.path, "offset must be finite", "offset")
    for c in ctx.data.position_constraints:
        if not np.all(np.isfinite(c.position)):
            raise prim_error(c.path, "position must be finite", "position")
    for g in ctx.data.groups:
        if len(g.members) < 2:
            raise prim_error(g.path, f"a group needs at least two members, got {len(g.members)}", "members")


def _note_outside_shot(ctx: SolveContext) -> None:
    """One note for the shot on the position and relative constraints whose frame plays outside
    the stage's start and end time codes (its clip referenced with a time offset): they hold
    there, where nobody sees them, and the shot shows only what they carry into it."""
    info, agents = ctx.data.info, ctx.data.agents
    if info.start_time is None or info.end_time is None:
        return
    start, end = float(info.start_time), float(info.end_time)
    outside = []
    for c in list(ctx.data.position_constraints) + list(ctx.data.relative_constraints):
        held = [(c.agent, c.frame)] + ([(c.target, c.target_frame)] if hasattr(c, "target") else [])
        for agent, frame in held:
            time = float(agents[agent].sample_times[frame])
            if not start - 1e-6 <= time <= end + 1e-6:
                outside.append(f"<{c.path}>: frame {frame} of <{agent}> plays at time code {time:g}")
                break
    if outside:
        named = "; ".join(outside[:3]) + (f"; and {len(outside) - 3} more" if len(outside) > 3 else "")
        many = len(outside) != 1
        ctx.report.note(f"{len(outside)} constraint{'s hold at frames' if many else ' holds at a frame'} that "
                        f"play{'' if many else 's'} outside the shot (time codes {start:g} to {end:g}): {named}; "
                        f"the shot shows only what {'they carry' if many else 'it carries'} into it (check the "
                        "frame against the clip's time offset)")


def _note_rest_frames(ctx: SolveContext) -> None:
    """A note on each position constraint whose frame cuts part from the rest of its clip, alone
    (a rest pose left in a clip's first frame, steps faster than ``trajectory.CUT_SPEED_M`` on
    each side): it holds that frame only, and the take is bent by its own constraints
    (``path_edit.CUT_WEIGHT``). The note says which frame of the take is next to it."""
    info = ctx.data.info
    for c in ctx.data.position_constraints:
        agent = ctx.data.agents[c.agent]
        track = ctx.trajectories.get(c.agent)
        if track is None or len(track.ground) < 2:
            continue
        steps = np.linalg.norm(np.diff(track.ground, axis=0), axis=1)
        cut = trajectory.is_cut(steps, np.diff(np.asarray(agent.sample_times, dtype=np.float64)) / info.time_codes_per_second,
                                info.meters_per_unit)
        last = len(track.ground) - 1

        def alone(g: int) -> bool:   # cut off on both sides (or a clip's end)
            return (g == 0 or bool(cut[g - 1])) and (g == last or bool(cut[g]))

        f = int(c.frame)
        if not alone(f):
            continue
        near = [g for g in (f + 1, f - 1) if 0 <= g <= last and not alone(g)]
        beside = f" (the take's nearest frame is {near[0]})" if near else ""
        ctx.report.note(f"<{c.path}> holds frame {f} of <{c.agent}>, a frame cut off from the rest of its clip "
                        f"(a rest pose, a step faster than {trajectory.CUT_SPEED_M:g} m/s on each side): it holds "
                        f"that frame alone, not the take{beside}; to hold the take, put the constraint on a frame "
                        "of it")


def _components(ctx: SolveContext) -> list[list[str]]:
    """Agents tied by relative constraints and groups, each component sorted, in order."""
    data = ctx.data
    joined = UnionFind(data.agents)
    for c in data.relative_constraints:
        joined.union_smallest(c.agent, c.target)
    for g in data.groups:
        for m in g.members[1:]:
            joined.union_smallest(g.members[0], m)
    active = {c.agent for c in data.position_constraints} | {c.agent for c in data.relative_constraints}
    active |= {a.path for a in data.agents.values() if a.path_curve}
    groups = joined.sets(sorted(data.agents))
    return [members for _, members in sorted(groups.items()) if active & set(members)]


def _by_component(ctx: SolveContext, components: list[list[str]]) -> list[tuple[list, list, list]]:
    """The position and relative constraints and the groups of each component, in stage order."""
    data = ctx.data
    which = {a: n for n, members in enumerate(components) for a in members}
    out = [([], [], []) for _ in components]
    for c in data.position_constraints:
        if c.agent in which:
            out[which[c.agent]][0].append(c)
    for c in data.relative_constraints:
        if c.agent in which:
            out[which[c.agent]][1].append(c)
    for g in data.groups:
        if g.members and g.members[0] in which and all(which.get(m) == which[g.members[0]] for m in g.members):
            out[which[g.members[0]]][2].append(g)
    return out


def _merged_ranges(agent) -> tuple[list[tuple[int, int]], list[list[str]]]:
    """Stationary ranges of an agent, overlapping ones merged, with the tags behind each."""
    out, names = [], []
    for name, first, last in sorted(agent.stationary, key=lambda t: (t[1], t[2])):
        if out and first <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], last))
            names[-1].append(name)
        else:
            out.append((first, last))
            names.append([name])
    return out, names


def on_curve(ctx: SolveContext, path: str) -> curves.Remap:
    """The agent's source path laid along its path curve (``agent.path_curve``): what the path
    pass starts from, and the way the artist draws the agent to walk."""
    data, info = ctx.data, ctx.data.info
    agent, traj = data.agents[path], ctx.trajectories[path]
    ranges, _ = _merged_ranges(agent)
    # Windows in seconds count this agent's own samples (a 120 fps clip on a 24 fps stage).
    rate = trajectory.samples_per_second(agent.sample_times, info.time_codes_per_second)
    poly = curves.ground_polyline(data.curves[agent.path_curve], agent.path_curve, info.up_axis)
    try:
        return curves.remap(traj.ground, poly, ranges, rate, info.metres(STILL_M),
                            info.metres(curves.SLOW_M_S), info.metres(curves.SETTLE_M))
    except ValueError as exc:
        raise prim_error(agent.path_curve, f"cannot remap <{path}> onto this curve: {exc}", "points") from None


def _agent_input(ctx: SolveContext, path: str, fps: float) -> path_edit.AgentInput:
    data, info = ctx.data, ctx.data.info
    agent, traj = data.agents[path], ctx.trajectories[path]
    ranges, names = _merged_ranges(agent)
    rest, turn = traj.ground, None
    # Windows in seconds count this agent's own samples (a 120 fps clip on a 24 fps stage).
    rate = trajectory.samples_per_second(agent.sample_times, fps)
    if agent.path_curve:
        remapped = on_curve(ctx, path)
        rest, turn = remapped.ground, remapped.range_turn
    refs = [f"{agent.animation_path}.stationary:{'/'.join(n)}:frames" for n in names]
    return path_edit.AgentInput(path=path, rest=np.ascontiguousarray(rest, dtype=np.float64), source=traj.ground,
                                source_heading=traj.heading, stationary=ranges, stationary_refs=refs,
                                rest_turn=turn, sample_times=agent.sample_times,
                                turn=path_edit.turn_settings(rate, info.meters_per_unit))


#: A take about one spot travels where its source has no foot planted (``path_edit.AIRBORNE_WEIGHT``),
#: but not against the way its source goes there: where the solved path's walking direction (on
#: ``metrics.CHORD_SECONDS`` chords, where the source walks) turns further than this many degrees
#: from its source's, the frames of those chords weigh AIRBORNE_STIFFEN times as much (up to those
#: on the ground), and the component is solved again, up to AIRBORNE_ROUNDS solves in all. Carried
#: in the air, a generated hop 30 cm forward, its take's end dragged 60 cm back, hopped 26 cm back;
#: it now hops 13 cm forward.
AIRBORNE_MAX_DEVIATION = 60.0
AIRBORNE_STIFFEN = 5.0
AIRBORNE_ROUNDS = 4


def _planted(ctx: SolveContext, path: str) -> np.ndarray | None:
    """(F,) whether a foot of the agent is planted at each frame of its source (its contacts, as
    foot locking finds them), or None for an agent without legs."""
    agent = ctx.data.agents[path]
    if not agent.legs:
        return None
    return np.any([contacts.mask_of(r, agent.frame_count) for r in ctx.source_contacts(path)], axis=0)


class _Component:
    """The inputs of one component, and (after run) its result."""

    def __init__(self, ctx: SolveContext, members: list[str], fps: float, positions: list, relatives: list,
                 groups: list):
        """``positions``, ``relatives``, ``groups``: the stage's constraints and groups on these
        members (see ``_by_component``)."""
        data, info = ctx.data, ctx.data.info
        up = info.up_axis
        self.members = members
        self.inputs = [_agent_input(ctx, p, fps) for p in members]
        self.positions, self.relatives, self.groups = positions, relatives, groups
        self.handles = [path_edit.Handle(c.agent, c.frame, ground.to_ground(c.position, up), _weight(c), c.path)
                        for c in self.positions]
        self.links = [path_edit.Link(c.agent, c.frame, c.target, c.target_frame, ground.to_ground(c.offset, up),
                                     c.space, _weight(c), c.path) for c in self.relatives]
        # Hard pins on a stationary range beyond two that its rigid motion meets anyway.
        implied = set(path_edit.implied_handles(self.inputs, self.handles, MET))
        self.handles = [h for k, h in enumerate(self.handles) if k not in implied]
        self.curve_only = not self.handles and not self.links
        # Frames where this component's constraints act on each agent.
        held: dict[str, list[int]] = {}
        for h in self.handles:
            held.setdefault(h.agent, []).append(h.frame)
        for k in self.links:
            held.setdefault(k.agent, []).append(k.frame)
            held.setdefault(k.target, []).append(k.target_frame)
        for a in self.inputs:
            curve = data.agents[a.path].path_curve
            if curve:
                rate = trajectory.samples_per_second(a.sample_times, fps)
                step = max(1, int(round(CURVE_ANCHOR_S * rate)))
                frames = np.array(sorted(set(range(0, a.frames, step)) | {a.frames - 1}))
                weights = CURVE_ANCHOR_WEIGHT * _anchor_fade(frames, held.get(a.path, []), CURVE_ANCHOR_FADE_S * rate)
                self.handles.extend(path_edit.Handle(a.path, int(f), a.rest[f], float(w), curve)
                                    for f, w in zip(frames, weights) if w > 0)
        self.settings = path_edit.Settings(
            min_baseline=info.metres(MIN_BASELINE_M), rigid_min_extent=info.metres(RIGID_MIN_EXTENT_M),
            still=info.metres(STILL_M), group_step=max(1.0, round(GROUP_SAMPLE_S * fps)),
            **path_edit.turn_settings(fps, info.meters_per_unit))
        self.fps, self.walking = fps, metrics.WALKING_SPEED_M / info.meters_per_unit
        for a in self.inputs:
            if path_edit.may_hold_spot(a, held.get(a.path, []), self.settings):
                planted = _planted(ctx, a.path)
                if planted is not None:
                    a.stance = path_edit.stance_weights(planted)
        self.result: path_edit.ComponentResult | None = None
        self.problem: path_edit.ComponentProblem | None = None

    def run(self) -> None:
        if self.curve_only:   # path curves alone: the remapped paths
            self.result = path_edit.ComponentResult(
                agents={a.path: path_edit.AgentResult(ground=a.rest, heading=path_edit.rest_heading(a, self.settings),
                                                      range_turn=a.rest_turn if a.rest_turn is not None
                                                      else np.zeros(len(a.stationary)))
                        for a in self.inputs},
                solver="none", notes=[], link_offsets=np.zeros((0, 2)))
            return
        try:
            for _ in range(AIRBORNE_ROUNDS):
                self.problem = path_edit.ComponentProblem(self.inputs, self.handles, self.links,
                                                          [path_edit.Group(g.members, g.stiffness, g.path)
                                                           for g in self.groups], self.settings)
                self.result = self.problem.solve()
                if not self._ground_reversed_flights():
                    break
        except path_edit.ContradictionError as exc:
            raise self._contradiction(exc) from None

    def _ground_reversed_flights(self) -> bool:
        """Frames of the takes about one spot that weigh less than on the ground
        (``AgentInput.stance``), on chords where the solved path walks further than
        AIRBORNE_MAX_DEVIATION from the source's way, weigh AIRBORNE_STIFFEN times more; returns
        whether any did."""
        changed = False
        for a in self.inputs:
            if a.stance is None:
                continue
            g = self.result.agents[a.path].ground
            seconds = np.asarray(a.sample_times, dtype=np.float64) / self.fps
            dev = metrics.direction_deviation(a.source, g, seconds, self.walking)
            bad = np.flatnonzero(np.nan_to_num(dev) > AIRBORNE_MAX_DEVIATION)
            if not len(bad):
                continue
            ends = np.searchsorted(seconds, seconds[bad] + metrics.CHORD_SECONDS)
            chords = np.zeros(len(seconds), dtype=bool)
            for i, j in zip(bad, ends):
                chords[i:j + 1] = True
            stance = a.stance.copy()
            stance[chords] = np.minimum(1.0, stance[chords] * AIRBORNE_STIFFEN)
            if (stance != a.stance).any():
                a.stance = stance
                changed = True
        return changed

    def _contradiction(self, exc) -> MocapEditError:
        p = self.problem or getattr(exc, "problem", None)
        prims, stationary, held = [], [], []
        for kind, index in exc.constraints:
            if kind == "handle" and p is not None and index < len(p.handle_refs) and p.handle_refs[index]:
                prims.append(p.handle_refs[index])
            elif kind == "link" and p is not None and index < len(p.link_refs) and p.link_refs[index]:
                prims.append(p.link_refs[index])
            elif kind == "rigid" and p is not None and p.rigid_refs[index][0] == "stationary":
                _, agent, r = p.rigid_refs[index]
                stationary.append(next(a for a in self.inputs if a.path == agent).stationary_refs[r])
            elif kind == "rigid" and p is not None:
                held.extend(p.rigid_refs[index][1])
        if p is None or (not prims and not stationary):
            return MocapEditError(f"hard constraints contradict each other: {exc}")
        named = ", ".join(f"<{x}>" for x in sorted(set(prims)))
        positions = {c.path: c for c in self.positions}
        same_frame = len(prims) == 2 and all(x in positions for x in prims) and \
            len({(positions[x].agent, positions[x].frame) for x in prims}) == 1 and not stationary
        if same_frame:
            c = positions[prims[0]]
            message = (f"hard position constraints {named} pin frame {c.frame} of <{c.agent}> to places "
                       f"{exc.mismatch:g} apart; keep one, or make the others soft")
            prop = "position"
        else:
            extra = (" and the stationary range " + ", ".join(stationary) + " (which moves rigidly)") if stationary else ""
            if held:
                extra += (", which hold " + ", ".join(f"<{h}>" for h in held) + " at a single place (so it only "
                          "moves by one translation)")
            message = (f"hard constraints {named}{extra} contradict each other: they cannot all hold (they miss by "
                       f"{exc.mismatch:g} stage units); make some of them soft")
            prop = "offset" if any(x not in positions for x in prims) else "position"
        return prim_error(sorted(set(prims))[0] if prims else stationary[0], message, prop)


def _anchor_fade(frames: np.ndarray, held: list[int], width: float) -> np.ndarray:
    """(K,) factor of the curve anchors at ``frames``: 0 at the ``held`` frames, easing
    (smoothstep) to 1 at ``width`` frames from the nearest of them; 1 without any."""
    if not held or width <= 0:
        return np.ones(len(frames))
    gap = np.abs(np.asarray(frames, dtype=np.float64)[:, None] - np.asarray(held, dtype=np.float64)[None]).min(axis=1)
    x = np.clip(gap / width, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _weight(c) -> float:
    return path_edit.HARD if c.hard else float(c.weight)


def _world(ctx: SolveContext, path: str, uv, frame: int) -> list[float]:
    h = ctx.trajectories[path].height[frame]
    return ground.from_ground(np.asarray(uv, dtype=np.float64), h, ctx.data.info.up_axis).tolist()


def _report(ctx: SolveContext, comp: _Component) -> None:
    res = comp.result
    edited = {p: r.ground for p, r in res.agents.items()}
    for c in comp.positions:
        target = ground.to_ground(c.position, ctx.data.info.up_axis)
        residual = float(np.linalg.norm(edited[c.agent][c.frame] - target))
        ctx.report.constraints.append(ConstraintEntry(
            prim=c.path, kind="position", agent=c.agent, frame=c.frame, hard=c.hard, residual=residual,
            met=residual <= MET, position=[float(v) for v in c.position]))
    for c, offset in zip(comp.relatives, res.link_offsets):
        d = edited[c.agent][c.frame] - edited[c.target][c.target_frame]
        residual = float(np.linalg.norm(d - offset))
        ctx.report.constraints.append(ConstraintEntry(
            prim=c.path, kind="relative", agent=c.agent, frame=c.frame, target=c.target,
            target_frame=c.target_frame, hard=c.hard, residual=residual, met=residual <= MET,
            position=_world(ctx, c.agent, edited[c.agent][c.frame], c.frame)))
    for a in comp.inputs:
        g = edited[a.path]
        for (first, last), ref in zip(a.stationary, a.stationary_refs):
            residual = float(metrics.rigidity_error(a.source, g, [(first, last)])[0])
            ctx.report.constraints.append(ConstraintEntry(
                prim=ref.split(".stationary:")[0], kind="stationary", agent=a.path, frame=first,
                hard=True, residual=residual, met=residual <= MET, position=_world(ctx, a.path, g[first], first)))
        agent = ctx.data.agents[a.path]
        if agent.path_curve:
            residual = float(np.linalg.norm(g - a.rest, axis=1).max(initial=0.0))
            ctx.report.constraints.append(ConstraintEntry(
                prim=agent.path_curve, kind="path-curve", agent=a.path, frame=0, hard=False, residual=residual,
                met=residual <= MET))
        entry = ctx.report.agent(a.path)
        entry.update(path_edit.shape_figures(a, g, ctx.data.info.metres(MIN_BASELINE_M)))
        r = res.agents[a.path]
        entry.solver = "translation only" if r.translate_only and res.solver not in ("none",) else res.solver
        if res.notes:
            notes = entry.add_notes()
            notes.extend(n for n in res.notes if n not in notes)


def _note_sparse_qr(ctx: SolveContext, comps: list[_Component]) -> None:
    """One note for the shot on the components sparse QR solved (too ill-conditioned for LDLT:
    paths of thousands of frames). Their results are as exact; each agent's entry names its solver."""
    qr = [c for c in comps if "SPQR" in c.result.solver]
    if not qr:
        return
    named = ", ".join(f"<{c.members[0]}>" for c in qr[:3]) + (f" and {len(qr) - 3} more" if len(qr) > 3 else "")
    how = sorted({c.result.solver for c in qr})
    ctx.report.note(f"path solve: {len(qr)} of {len(comps)} path components were solved by sparse QR, slower "
                    f"than LDLT and as exact ({named}; {', '.join(how)})")


def solve_components(comps: list[_Component]) -> list:
    """Solves components where this runs (a Dask task of a split shot, see
    :class:`~mocapedit.pipeline.context.ComponentPool`) and returns, per component, its result or
    the :class:`MocapEditError` it raised, so the shot's process raises the first in order. The
    solver's records of each step (bound objects, which do not pickle) stay here: the pass reads
    only the solver's name."""
    out = []
    for comp in comps:
        try:
            comp.run()
            out.append(dataclasses.replace(comp.result, step1=None, step2=None))
        except MocapEditError as exc:
            out.append(exc)
    return out


def _run_on_pool(ctx: SolveContext, comps: list[_Component], task) -> None:
    pool = ctx.options.components
    chunks = [comps[run] for run in consecutive_runs([sum(a.frames for a in c.inputs) for c in comps], pool.chunks)]
    done = 0
    for chunk, results in zip(chunks, pool.map(solve_components, chunks)):
        for comp, result in zip(chunk, results):
            if isinstance(result, MocapEditError):
                raise result
            comp.result = result
        done += len(chunk)
        task.update(done)


def run(ctx: SolveContext) -> None:
    _validate(ctx)
    _note_outside_shot(ctx)
    _note_rest_frames(ctx)
    members = _components(ctx)
    if not members:
        return
    fps = ctx.data.info.time_codes_per_second
    comps = [_Component(ctx, m, fps, *mine) for m, mine in zip(members, _by_component(ctx, members))]
    task = ctx.progress.task("path edits", len(comps))
    workers = min(len(comps), os.cpu_count() or 1, 2)
    if ctx.options.components is not None:
        _run_on_pool(ctx, comps, task)
    elif workers > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(c.run) for c in comps]
            for i, f in enumerate(futures):
                f.result()   # re-raises the first failure, in component order
                task.update(i + 1)
    else:
        for i, c in enumerate(comps):
            c.run()
            task.update(i + 1)
    task.done()
    for comp in comps:
        for path, r in comp.result.agents.items():
            ctx.paths[path] = EditedPath(ground=r.ground, heading=r.heading)
        _report(ctx, comp)
    _note_sparse_qr(ctx, comps)
    ctx.report.stats.path_components = len(comps)
