"""Where every agent is on the ground over shot time, before and after the edits.

The guides, the report figures and the previews all look at the same thing: for each
agent a source track and an edited track, each a ground path with the shot time of every
point. :func:`from_context` takes them from a solve (after every pass);
:func:`from_stages` takes them from two stages read back (the input, and the input with
the edits over it), so a preview needs no solve.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit.inspect import metrics, overlaps
from mocapedit.model.data import StageInfo
from mocapedit.model.report import ConstraintEntry

#: Clearance (metres) within which the nearest neighbour is measured for the report's
#: minSeparation when no pass measured it.
SEPARATION_REACH_M = 2.0


@dataclass
class Track:
    """A ground path over shot time. ``times`` (#F) increasing, ``ground`` #F by 2."""
    times: np.ndarray
    ground: np.ndarray

    def at(self, times: np.ndarray) -> np.ndarray:
        """#T by 2 ground positions at shot times; held at the ends, as UsdSkel holds samples."""
        t = np.asarray(times, dtype=np.float64)
        if len(self.times) == 1:
            return np.broadcast_to(self.ground[0], t.shape + (2,)).copy()
        return np.stack([np.interp(t, self.times, self.ground[:, k]) for k in (0, 1)], axis=-1)

    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.ground, axis=0), axis=1).sum())


@dataclass
class AgentTracks:
    path: str
    source: Track
    edited: Track
    radius: float                 # collision radius, stage units
    collide: bool
    edited_flag: bool             # the edits change this agent


@dataclass
class Crowd:
    info: StageInfo
    agents: list[AgentTracks]     # sorted by path
    sample_step: float = 1.0      # time codes between the samples used for overlaps

    def index(self) -> dict[str, int]:
        return {a.path: i for i, a in enumerate(self.agents)}

    def shot_times(self, step: float | None = None) -> np.ndarray:
        """Time samples ``step`` time codes apart over the shot (:meth:`StageInfo.shot_span`):
        the stage's start and end time codes where it has them, else every edited track (a
        walker that waited finishes its clip after the shot; nothing plays there)."""
        if not self.agents:
            return np.zeros(0)
        step = step or self.sample_step
        t0, t1 = self.info.shot_span(min(float(a.edited.times[0]) for a in self.agents),
                                     max(float(a.edited.times[-1]) for a in self.agents))
        return t0 + step * np.arange(int(np.floor((t1 - t0) / step + 1e-9)) + 1)

    def positions(self, times: np.ndarray, which: str = "edited") -> np.ndarray:
        """#A by #T by 2 ground positions of every agent at shot times."""
        out = np.empty((len(self.agents), len(times), 2))
        for i, a in enumerate(self.agents):
            out[i] = getattr(a, which).at(times)
        return out

    def proximity(self, reach: float = 0.0, progress=None) -> tuple[np.ndarray, overlaps.Proximity]:
        """(shot times, pairs closer than ``reach``) on the edited tracks of colliding agents."""
        times = self.shot_times()
        task = progress.task("overlaps", len(self.agents), "agents") if progress else None
        pos = np.empty((len(self.agents), len(times), 2))
        for i, a in enumerate(self.agents):
            pos[i] = a.edited.at(times)
            if task:
                task.update(i + 1)
        radii = np.array([a.radius for a in self.agents])
        found = overlaps.proximity(pos, radii, reach, np.array([a.collide for a in self.agents], dtype=bool))
        if task:
            pairs = len(overlaps.worst_per_pair(found.overlapping()))
            task.done(f"{pairs} overlapping agent pair{'s' if pairs != 1 else ''}")
        return times, found

    def contact_points(self, found: overlaps.Proximity, times: np.ndarray) -> np.ndarray:
        """#N by 2 ground points half way between the two agents of each row of ``found``."""
        pa = np.array([self.agents[a].edited.at(times[s]) for a, s in zip(found.a, found.sample)]).reshape(-1, 2)
        pb = np.array([self.agents[b].edited.at(times[s]) for b, s in zip(found.b, found.sample)]).reshape(-1, 2)
        return 0.5 * (pa + pb)


def from_context(ctx) -> Crowd:
    """The tracks of a solve after every pass (edited paths and time maps applied)."""
    agents = []
    for path in sorted(ctx.trajectories):
        agent, traj = ctx.data.agents[path], ctx.trajectories[path]
        source = Track(np.asarray(agent.sample_times, dtype=np.float64), traj.ground)
        edited_path = ctx.paths.get(path)
        times = ctx.time_maps.get(path)
        edited = Track(source.times if times is None else np.asarray(times, dtype=np.float64),
                       traj.ground if edited_path is None else np.asarray(edited_path.ground, dtype=np.float64))
        agents.append(AgentTracks(path, source, edited, float(agent.collision_radius), bool(agent.collide),
                                  path in ctx.edits))
    return Crowd(ctx.data.info, agents, float(ctx.data.settings.sample_step))


def from_stages(source, source_trajectories, edited=None, edited_trajectories=None,
                tolerance: float | None = None) -> Crowd:
    """Tracks from a source stage's data and, optionally, the same crowd with its edits.

    Args:
      source, edited: :class:`~mocapedit.model.data.StageData` of the input and of the input
        with the edits over it (None: no edits, the edited tracks are the source ones)
      source_trajectories, edited_trajectories: agent path -> Trajectory of each
      tolerance: ground distance (stage units) under which an agent counts as unchanged;
        default 0.1 mm
    """
    info = source.info
    tol = info.metres(1e-4) if tolerance is None else tolerance
    agents = []
    for path in sorted(source.agents):
        agent = source.agents[path]
        src = Track(np.asarray(agent.sample_times, dtype=np.float64), source_trajectories[path].ground)
        out, changed = src, False
        if edited is not None and path in edited.agents:
            e_agent = edited.agents[path]
            out = Track(np.asarray(e_agent.sample_times, dtype=np.float64), edited_trajectories[path].ground)
            changed = not (len(out.times) == len(src.times) and np.allclose(out.times, src.times, atol=1e-9)
                           and np.abs(out.ground - src.ground).max(initial=0.0) <= tol)
        agents.append(AgentTracks(path, src, out, float(agent.collision_radius), bool(agent.collide), changed))
    return Crowd(info, agents, float(source.settings.sample_step))


def constraint_status(entries: list[ConstraintEntry]) -> dict[str, ConstraintEntry]:
    """Constraint prim path -> its worst report entry (not met first, then the largest residual)."""
    out: dict[str, ConstraintEntry] = {}
    for entry in entries:
        if entry.prim is None:
            continue
        old = out.get(entry.prim)
        if old is None or _badness(entry) > _badness(old):
            out[entry.prim] = entry
    return out


def _badness(entry: ConstraintEntry) -> tuple[bool, float]:
    return not entry.met, float(entry.residual or 0.0)


def handles(entries: list[ConstraintEntry], position_constraints) -> list[tuple[np.ndarray, ConstraintEntry | None]]:
    """(world position (3,), report entry or None) of every constraint handle.

    The handles are the report entries that give a ``position`` (collisions aside), and
    the position constraints of the stage that no entry placed (None: not reported on).
    """
    out = [(np.asarray(e.position, dtype=np.float64), e) for e in entries
           if e.kind != "collision" and e.position is not None]
    placed = {e.prim for e in entries if e.position is not None}
    status = constraint_status(entries)
    out.extend((np.asarray(c.position, dtype=np.float64), status.get(c.path))
               for c in position_constraints if c.path not in placed)
    return out


def reported_collisions(entries: list[ConstraintEntry]) -> np.ndarray:
    """#N by 3 world positions of the collisions a pass reported as left (not met)."""
    pts = [e.position for e in entries if e.kind == "collision" and e.position is not None and not e.met]
    return np.array(pts, dtype=np.float64).reshape(-1, 3)


def path_figures(source: np.ndarray, edited: np.ndarray) -> tuple[float, float, float]:
    """(length ratio, largest and mean displacement) of an edited path against its source,
    frame by frame.

    Args:
      source, edited: #F by 2 ground paths, one row per source frame
    """
    d = np.linalg.norm(np.asarray(edited) - np.asarray(source), axis=1)
    return metrics.length_ratio(edited, source), float(d.max(initial=0.0)), float(d.mean()) if len(d) else 0.0


def collision_pass_reported(report) -> bool:
    """True when a collision pass measured what is left (so the inspection keeps its word)."""
    return report.stats.remaining_overlaps is not None or any(c.kind == "collision" for c in report.constraints)


@dataclass
class Remaining:
    """The overlaps left on the edited tracks, one row per agent pair (its deepest sample)."""
    a: list[str]
    b: list[str]
    time: np.ndarray              # (N,) shot time of the deepest overlap
    clearance: np.ndarray         # (N,) negative
    ground: np.ndarray            # (N,2) contact point


def remaining_overlaps(crowd: Crowd, progress=None, reach: float = 0.0) -> tuple[Remaining, np.ndarray]:
    """(overlaps per pair, each agent's smallest clearance within ``reach`` or inf)."""
    times, found = crowd.proximity(reach, progress)
    worst = overlaps.worst_per_pair(found.overlapping())
    ground = crowd.contact_points(worst, times) if len(worst) else np.zeros((0, 2))
    names = [a.path for a in crowd.agents]
    return (Remaining([names[i] for i in worst.a], [names[i] for i in worst.b], times[worst.sample],
                      worst.clearance, ground),
            overlaps.min_clearance(found, len(crowd.agents)))


def complete_report(ctx, crowd: Crowd) -> Remaining | None:
    """Adds the figures no pass measured: path length ratio and displacement of each
    edited agent; overlaps left and nearest clearance when no collision pass ran.

    Returns the overlaps found, or None when a collision pass reported them itself.
    """
    for path in sorted(ctx.paths):
        entry = ctx.report.agent(path)
        ratio, largest, mean = path_figures(ctx.trajectories[path].ground, ctx.paths[path].ground)
        if entry.length_ratio is None:   # the path pass measured it on its own terms
            entry.length_ratio = ratio
        if entry.max_displacement is None:
            entry.max_displacement = largest
        if entry.mean_displacement is None:
            entry.mean_displacement = mean
    if collision_pass_reported(ctx.report):
        return None
    remaining, clearance = remaining_overlaps(crowd, progress=ctx.progress,
                                              reach=ctx.data.info.metres(SEPARATION_REACH_M))
    for agent, c in zip(crowd.agents, clearance):
        if agent.collide and np.isfinite(c):
            entry = ctx.report.agent(agent.path)
            if entry.min_separation is None:
                entry.min_separation = float(c)
    if ctx.report.stats.remaining_overlaps is None:
        ctx.report.stats.remaining_overlaps = len(remaining.a)
    return remaining
