"""Guide geometry for the edits layer: what an artist looks at in usdview.

Built from the solve context after every pass, from the report conventions the passes
share (``ctx.report.constraints`` entries, ``ctx.report.stats``) and from the stage data,
so each guide appears as soon as some pass produces what it shows. The writer authors
them under ``/MocapEdit/Guides`` with purpose ``guide``:

==================  ===========  ==================================================
prim                type         what it shows
==================  ===========  ==================================================
SourcePaths         BasisCurves  every agent's source ground path (grey)
EditedPaths         BasisCurves  every edited agent's new ground path (orange)
StationaryRanges    BasisCurves  the stationary ranges on the edited paths (cyan)
StationaryMarks     Points       where each stationary range starts (cyan)
ConstraintHandles   Points       constraint handles: green met, red not met, yellow
                                 when no pass reported on the constraint
RelativeLinks       BasisCurves  agent to target at the constrained frames (blue, red
                                 when not met)
SyncLinks           BasisCurves  the same for sync constraints (purple, red when not met)
GroupLinks          BasisCurves  each group member to the group's centre, at the start
                                 and the end of the time the members share (green)
Collisions          Points       overlaps left between agents (magenta)
==================  ===========  ==================================================

A guide a pass already appended under the same name is kept, and this one is left out.
"""
from __future__ import annotations

import numpy as np

from mocapedit.geometry import ground
from mocapedit.inspect import inspection
from mocapedit.usd import writer
from mocapedit.inspect.inspection import Crowd, Remaining
from mocapedit.model.report import ConstraintEntry
from mocapedit.pipeline.context import SolveContext

SOURCE = (0.55, 0.55, 0.6)
EDITED = (1.0, 0.55, 0.1)
STATIONARY = (0.1, 0.8, 0.9)
MET = (0.2, 0.85, 0.3)
NOT_MET = (0.95, 0.15, 0.1)
NOT_REPORTED = (0.95, 0.8, 0.1)
RELATIVE = (0.25, 0.5, 1.0)
SYNC = (0.7, 0.35, 0.95)
GROUP = (0.35, 0.75, 0.45)
COLLISION = (1.0, 0.1, 0.65)

# Small lifts above the ground so guides drawn over a ground mesh stay visible, in metres.
_LIFT_M = {"source": 0.01, "edited": 0.02, "stationary": 0.03, "links": 0.04, "points": 0.05}


def status_color(entry: ConstraintEntry | None, met_color=MET) -> tuple[float, float, float]:
    """Green (or ``met_color``) when met, red when not, yellow when no pass reported on it."""
    if entry is None:
        return NOT_REPORTED
    return met_color if entry.met else NOT_MET


def build(ctx: SolveContext, crowd: Crowd, remaining: Remaining | None) -> None:
    """Appends the inspection guides to ``ctx.guides`` (nothing when guides are off)."""
    if not ctx.options.guides:
        return
    info = ctx.data.info
    up = info.up_axis
    taken = {g.name for g in ctx.guides}
    lift = {k: info.metres(v) for k, v in _LIFT_M.items()}

    def add(guide):
        if guide.name not in taken:
            taken.add(guide.name)
            ctx.guides.append(guide)

    def world(uv, height):
        return ground.from_ground(np.asarray(uv, dtype=np.float64), height, up)

    def edited_ground(path):
        edited = ctx.paths.get(path)
        return ctx.trajectories[path].ground if edited is None else np.asarray(edited.ground)

    def at_frame(path, frame):
        g = edited_ground(path)
        return g[int(np.clip(frame, 0, len(g) - 1))]

    paths = sorted(ctx.trajectories)
    add(writer.GuideCurves(
        name="SourcePaths", curves=[world(ctx.trajectories[p].ground, lift["source"]) for p in paths],
        color=SOURCE, width=info.metres(0.03), doc="Ground paths of the agents' source clips, one curve per agent."))
    edited = sorted(ctx.paths)
    add(writer.GuideCurves(
        name="EditedPaths", curves=[world(edited_ground(p), lift["edited"]) for p in edited],
        color=EDITED, width=info.metres(0.04), doc="Edited ground paths, one curve per edited agent."))

    ranges, starts = [], []
    for p in paths:
        g = edited_ground(p)
        for _, first, last in ctx.data.agents[p].stationary:
            first, last = max(int(first), 0), min(int(last), len(g) - 1)
            if last < first:
                continue
            seg = g[first:last + 1]
            ranges.append(world(seg if len(seg) > 1 else np.repeat(seg, 2, axis=0), lift["stationary"]))
            starts.append(world(seg[0], lift["points"]))
    add(writer.GuideCurves(
        name="StationaryRanges", curves=ranges, color=STATIONARY, width=info.metres(0.08),
        doc="Stationary ranges (MocapStationaryAPI) on the edited paths: these frames move rigidly."))
    add(writer.GuidePoints(
        name="StationaryMarks", points=np.array(starts).reshape(-1, 3),
        colors=np.tile(STATIONARY, (len(starts), 1)), width=info.metres(0.15),
        doc="Where each stationary range starts."))

    status = inspection.constraint_status(ctx.report.constraints)
    handles = inspection.handles(ctx.report.constraints, ctx.data.position_constraints)
    add(writer.GuidePoints(
        name="ConstraintHandles", points=np.array([h for h, _ in handles]).reshape(-1, 3),
        colors=np.array([status_color(e) for _, e in handles]).reshape(-1, 3),
        width=info.metres(0.25),
        doc="Constraint handles: green when met, red when not, yellow when no solve reported on it."))

    for name, constraints, met_color, what in (
            ("RelativeLinks", ctx.data.relative_constraints, RELATIVE, "relative position"),
            ("SyncLinks", ctx.data.sync_constraints, SYNC, "sync")):
        curves, link_colors = [], []
        for c in constraints:
            curves.append(world([at_frame(c.agent, c.frame), at_frame(c.target, c.target_frame)], lift["links"]))
            link_colors.append(status_color(status.get(c.path), met_color))
        add(writer.GuideCurves(
            name=name, curves=curves, color=met_color, colors=np.array(link_colors).reshape(-1, 3),
            width=info.metres(0.02),
            doc=f"One segment per {what} constraint, from the agent at its frame to the target at "
                "the target frame; red when the constraint is not met."))

    add(writer.GuideCurves(
        name="GroupLinks", curves=_group_links(ctx.data.groups, crowd, lambda uv: world(uv, lift["links"])),
        color=GROUP, width=info.metres(0.02),
        doc="Each group member linked to the group's centre, at the start and the end of the time the "
            "members share."))

    if remaining is None:   # a collision pass reported what is left
        points = inspection.reported_collisions(ctx.report.constraints)
    else:
        points = world(remaining.ground, lift["points"]).reshape(-1, 3)
    add(writer.GuidePoints(
        name="Collisions", points=points, colors=np.tile(COLLISION, (len(points), 1)), width=info.metres(0.3),
        doc="Overlaps left between agents' collision capsules: one point per pair, where they overlap most."))


def _group_links(groups, crowd: Crowd, world) -> list[np.ndarray]:
    index = crowd.index()
    curves = []
    for group in groups:
        members = [crowd.agents[index[m]] for m in group.members if m in index]
        if len(members) < 2:
            continue
        t0 = max(float(m.edited.times[0]) for m in members)
        t1 = min(float(m.edited.times[-1]) for m in members)
        times = [t0] if t1 <= t0 else [t0, t1]
        for t in times:
            pts = np.array([m.edited.at(np.array([t]))[0] for m in members])
            centre = pts.mean(axis=0)
            curves.extend(world(np.array([centre, p])) for p in pts)
    return curves
