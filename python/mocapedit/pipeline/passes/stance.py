"""The stance pass: each moved agent's edited path and turn, the turn taken between steps and the
body pivoting on its planted feet (:mod:`mocapedit.solve.stance`), after every pass that moves
paths and before foot locking, which then has less to correct.

Frames the artist fixed keep their path and turn: pinned frames, relative constraints' frames
(and a few either side) and stationary ranges. Agents on a path curve keep the path drawn for them;
takes about one spot (whose source root stays within ``path_edit.DRIFT_SPREAD_M``) are carried as a
whole, and foot locking steps them. Collision avoidance runs the pass before its last solve (see
:mod:`mocapedit.pipeline.passes.collisions`), so that the overlaps a pivot makes are cleared.
``MocapSolveSettings.pivotOnFeet`` turns it off.
"""
from __future__ import annotations

import numpy as np

from mocapedit.geometry import contacts, ground, trajectory
from mocapedit.pipeline.context import EditedPath, SolveContext
from mocapedit.solve import path_edit, stance


#: Frames either side of a constrained frame that keep the edited path too: the direction of the
#: path there (what a target-space offset turns with) comes from them.
AROUND_FRAMES = 3


def _fixed(ctx: SolveContext, paths: list[str]) -> dict[str, np.ndarray]:
    """Per agent, (F,) the frames the artist fixed: constrained frames and those around them,
    stationary ranges."""
    data = ctx.data
    out = {p: np.zeros(data.agents[p].frame_count, dtype=bool) for p in paths}

    def fix(agent: str, frame: int) -> None:
        if agent in out:
            out[agent][max(frame - AROUND_FRAMES, 0):frame + AROUND_FRAMES + 1] = True

    for c in data.position_constraints:
        fix(c.agent, c.frame)
    for c in data.relative_constraints:
        fix(c.agent, c.frame)
        fix(c.target, c.target_frame)
    for p in paths:
        for _, first, last in data.agents[p].stationary:
            out[p][first:last + 1] = True
    return out


def _feet(ctx: SolveContext, path: str, cache: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """((F,L,2) each leg's planted point on the ground in the source (half way between its ankle
    and toe), (F,L) its contacts), or None for an agent without two legs or contacts."""
    data = ctx.data
    agent = data.agents[path]
    if len(agent.legs) != 2:
        return None
    ranges = ctx.source_contacts(path)
    if not any(ranges):
        return None
    clip = data.clip_of(agent)
    points = []
    for leg in agent.legs:
        joints = [leg.ankle] + ([leg.toe] if leg.toe is not None else [])
        world = np.mean([trajectory.joint_world_position(agent, clip, j, cache) for j in joints], axis=0)
        points.append(ground.to_ground(world, data.info.up_axis))
    planted = np.stack([contacts.mask_of(r, agent.frame_count) for r in ranges], axis=1)
    return np.stack(points, axis=1), planted


def pivot_moved(ctx: SolveContext, keep: set[str] = frozenset(), feet: dict | None = None,
                ease_seconds: float = stance.EASE_SECONDS) -> None:
    """Every moved agent with two legs and foot contacts but those in ``keep``: its edited path and
    turn pivoted on its planted feet (:func:`stance.pivot`, the shift paying itself back over
    about ``ease_seconds``), frames the artist fixed kept. ``feet``: a dict that keeps each
    agent's source feet (:func:`_feet`) for a later call."""
    ctx.pivoted = True
    if not ctx.data.settings.pivot_on_feet:
        return
    # Agents on a path curve walk the path the artist drew; a take about one spot (a boxer's, an
    # idle) is carried as a whole and foot locking steps it.
    spot = path_edit.DRIFT_SPREAD_M / ctx.data.info.meters_per_unit

    def walks(p: str) -> bool:
        return float(np.linalg.norm(np.ptp(ctx.trajectories[p].ground, axis=0))) >= spot

    moved = [p for p in sorted(ctx.paths) if ctx.moved(p) and p not in keep
             and ctx.data.agents[p].path_curve is None and walks(p)]
    if not moved:
        return
    info = ctx.data.info
    cache: dict = {}
    fixed = _fixed(ctx, moved)
    known = {} if feet is None else feet
    agents, found = [], []
    for p in moved:
        if p not in known:
            known[p] = _feet(ctx, p, cache)
        if known[p] is not None:
            agents.append(p)
            found.append(known[p])
    source = [ctx.trajectories[p] for p in agents]
    pivoted = stance.pivot(
        [t.ground for t in source], [ctx.paths[p].ground for p in agents],
        [ctx.paths[p].heading - t.heading for p, t in zip(agents, source)],
        [f[0] for f in found], [f[1] for f in found], [fixed[p] for p in agents],
        [1.0 / trajectory.samples_per_second(ctx.data.agents[p].sample_times, info.time_codes_per_second)
         for p in agents], ease_seconds)
    for p, t, (uv, turn) in zip(agents, source, pivoted):
        ctx.paths[p] = EditedPath(ground=uv, heading=t.heading + turn)
        # Measured again on the final path (the inspection fills it in).
        ctx.report.agent(p).length_ratio = None


def run(ctx: SolveContext) -> None:
    """The stance pass, unless collision avoidance ran it already."""
    if not ctx.pivoted:
        pivot_moved(ctx)
