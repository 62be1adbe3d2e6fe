"""Collisions between agents and with avoid regions: sampling, detection, footprints (numpy).

Agents are vertical capsules standing on their ground trajectory. They are compared at
common shot times ``t0, t0 + step, ...`` (``MocapSolveSettings.sampleStep``): each
agent's source frame at a shot time comes from its time map when it has one (the clip
plays warped), else from its clip's sample times, and its ground position from its
edited path when it has one. Before its first and after its last frame an agent holds
its end position, as UsdSkel holds the end poses.

Avoid regions are convex footprints on the ground plane (:class:`mocapedit._solver.GroundRegion`)
built from a :class:`~mocapedit.model.data.AvoidRegion`: a circle or a box in the region's
own transform, or the ground footprint of a geometry prim's world bound.

The C++ side (:mod:`mocapedit._solver`) does the detection and the geometry; this module
gathers the arrays and turns its output into per-collision records. :func:`detect_at` is the
one capsule-overlap routine: the solve's avoidance, the inspection's overlaps
(:mod:`mocapedit.inspect.overlaps`) and the separation measure
(:func:`mocapedit.inspect.metrics.min_separation`) all find their pairs with it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import ground
from mocapedit.model.errors import prim_error
from mocapedit.model.data import AvoidRegion

#: Sides of the polygon standing in for a circle whose transform is not a similarity.
ELLIPSE_SIDES = 64


@dataclass
class Sampling:
    """Ground positions of a set of agents at common shot times."""
    agents: list[str]            # (A,) agent paths, the column order
    times: np.ndarray            # (K,) shot times
    frames: np.ndarray           # (K,A) fractional source frame of each agent at each time
    positions: np.ndarray        # (K,A,2) ground positions, stage units

    def at(self, samples: np.ndarray, agents: np.ndarray) -> np.ndarray:
        """(N,2) positions of agent columns at samples, pairwise (``positions[samples, agents]``
        as one gather: numpy's fancy indexing of two index arrays is several times slower)."""
        return np.take(self.positions.reshape(-1, 2), samples * self.positions.shape[1] + agents, axis=0)

    def frames_at(self, samples: np.ndarray, agents: np.ndarray) -> np.ndarray:
        """(N,) fractional source frames of agent columns at samples, pairwise."""
        return np.take(self.frames.reshape(-1), samples * self.frames.shape[1] + agents)


def sample_times(time_ranges: list[tuple[float, float]], step: float) -> np.ndarray:
    """(K,) shot times from the earliest start to the latest end, ``step`` apart.

    The last sample is the latest end itself when the range is not a whole number of steps.
    """
    if not time_ranges:
        return np.zeros(0)
    t0 = min(a for a, _ in time_ranges)
    t1 = max(b for _, b in time_ranges)
    count = int(np.floor((t1 - t0) / step + 1e-9)) + 1
    times = t0 + step * np.arange(count, dtype=np.float64)
    if times[-1] < t1 - 1e-9:
        times = np.append(times, t1)
    return times


def frames_at(frame_times: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Fractional source frames at shot times, for frames played at (F,) increasing times."""
    return np.interp(times, frame_times, np.arange(len(frame_times), dtype=np.float64))


def positions_at(ground_path: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(T,2) positions of a (F,2) per-frame ground path at fractional frames (clamped)."""
    f = np.clip(frames, 0.0, len(ground_path) - 1)
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(ground_path) - 1)
    a = (f - i0)[:, None]
    return ground_path[i0] * (1.0 - a) + ground_path[i1] * a


def sample(agents: list[str], frame_times: dict[str, np.ndarray], paths: dict[str, np.ndarray],
           step: float, span: tuple[float, float] | None = None) -> Sampling:
    """Samples agents at common shot times.

    Args:
      agents: agent paths, the column order of the result.
      frame_times: per agent, (F,) shot time at which each source frame plays.
      paths: per agent, (F,2) ground position at each source frame.
      step: time codes between samples (> 0).
      span: (first, last) shot times to sample; default: from the earliest first frame to
        the latest last frame.
    """
    ranges = [(float(frame_times[a][0]), float(frame_times[a][-1])) for a in agents]
    times = sample_times(ranges if span is None else [span], step)
    frames = np.empty((len(times), len(agents)))
    for i, a in enumerate(agents):
        frames[:, i] = frames_at(frame_times[a], times)
    out = Sampling(agents=list(agents), times=times, frames=frames, positions=np.empty((len(times), len(agents), 2)))
    if len(agents):
        flat = [np.asarray(paths[a], dtype=np.float64).reshape(-1, 2) for a in agents]
        Resampler(out, np.concatenate([[0], np.cumsum([len(g) for g in flat])]))(np.concatenate(flat))
    return out


class Resampler:
    """Re-reads a sampling's positions from new per-frame paths, concatenated; the frames
    and weights are worked out once, so a re-read is two gathers.

    Args:
      sampling: the sampling to update in place (its frames stay)
      starts: #A+1 first row of each agent (in sampling order) in the paths, then #V
      columns: only these agents (sampling columns) are re-read; ``starts`` and the paths
        then hold those agents alone, in this order
    """

    def __init__(self, sampling: Sampling, starts: np.ndarray, columns: np.ndarray | None = None):
        starts = np.asarray(starts, dtype=np.int64)
        self.columns = None if columns is None else np.asarray(columns, dtype=np.int64)
        last = (starts[1:] - starts[:-1] - 1)[None, :]
        f = np.clip(sampling.frames if columns is None else sampling.frames[:, self.columns], 0.0, last)
        i0 = np.floor(f).astype(np.int64)
        base = starts[:-1][None, :]
        w1 = (f - i0).ravel()
        self.sampling = sampling
        self.i0 = (base + i0).ravel()
        # Only samples between two frames blend (none when samples fall on frames).
        self.blend = np.flatnonzero(w1 > 0.0)
        self.i1 = (base + np.minimum(i0 + 1, last)).ravel()[self.blend]
        self.w1 = w1[self.blend, None]

    def __call__(self, paths: np.ndarray) -> None:
        """paths: #V by 2 ground positions, agent i's frames at rows starts[i] .. starts[i+1]-1."""
        if self.columns is not None:
            out = np.empty((len(self.i0), 2))
        else:
            out = self.sampling.positions.reshape(-1, 2)
        np.take(paths, self.i0, axis=0, out=out)
        if len(self.blend):
            p0 = out[self.blend]
            out[self.blend] = p0 + (paths[self.i1] - p0) * self.w1
        if self.columns is not None:
            self.sampling.positions[:, self.columns] = out.reshape(len(self.sampling.times), len(self.columns), 2)


def resample(sampling: Sampling, paths: np.ndarray, starts: np.ndarray) -> None:
    """Re-reads every agent's positions from new per-frame paths, concatenated.

    Args:
      paths: #V by 2 ground positions, agent i's frames at rows starts[i] .. starts[i+1]-1
      starts: #A+1 first row of each agent (in sampling order), then #V
    """
    Resampler(sampling, starts)(paths)


@dataclass
class Collisions:
    """Collision intervals found at a sampling, one entry per interval (numpy columns)."""
    agent_a: np.ndarray          # (M,) column of the first agent (agent_a < agent_b)
    agent_b: np.ndarray          # (M,)
    first: np.ndarray            # (M,) first colliding sample (inclusive)
    last: np.ndarray             # (M,) last colliding sample (inclusive)
    deepest: np.ndarray          # (M,) sample of the maximal overlap
    depth: np.ndarray            # (M,) wanted clearance minus clearance there, > 0
    min_clearance: np.ndarray    # (A,) each agent's smallest clearance, +inf if none within reach
    min_clearance_sample: np.ndarray  # (A,) sample of it, -1 if +inf
    colliding_samples: int       # (pair, sample) records below the wanted clearance
    pair_tests: int = 0          # narrow-phase capsule tests the detection made
    near: "Collisions | None" = None  # intervals below the watch distance, when one was asked for

    def __len__(self) -> int:
        return int(self.agent_a.shape[0])


def detect(sampling: Sampling, radius: np.ndarray, height: np.ndarray, margin: float,
           report_distance: float = 0.0, active: np.ndarray | None = None,
           brute_force: bool = False, watch: float | None = None) -> Collisions:
    """Collision intervals of every pair at a sampling (a grid per sample, in C++).

    ``watch``: a clearance above ``margin``; the intervals below it are gathered in the same
    pass as ``near`` (their depth measured from ``watch``).
    """
    return detect_at(sampling.positions, radius, height, margin, report_distance, active,
                     brute_force, watch)


def detect_at(positions: np.ndarray, radius: np.ndarray, height: np.ndarray, margin: float,
              report_distance: float = 0.0, active: np.ndarray | None = None,
              brute_force: bool = False, watch: float | None = None,
              base: np.ndarray | None = None) -> Collisions:
    """:func:`detect` on ground positions given as an array: the one capsule-overlap routine
    behind the solve's detection, the inspection's overlaps and the separation measure.

    Args:
      positions: #K by #A by 2 ground positions of each agent at each sample, stage units
        (finite for the active agents)
      radius, height: #A capsule radii and heights (> 0 for the active agents), stage units
      margin: clearance (>= 0) below which a pair collides
      report_distance: ``min_clearance`` is exact up to this clearance, +inf beyond
      active: #A flags, agents taking part (default: all)
      brute_force: test every pair at every sample (the reference) instead of the grid
      watch: see :func:`detect`
      base: #A base elevations along up (default: all on the ground plane)
    """
    k = positions.shape[0]
    out = _solver.detect_collisions(
        positions=np.ascontiguousarray(np.asarray(positions, dtype=np.float64).reshape(-1, 2)), samples=k,
        radius=np.asarray(radius, dtype=np.float64), height=np.asarray(height, dtype=np.float64),
        base=None if base is None else np.asarray(base, dtype=np.float64),
        active=None if active is None else [bool(x) for x in active], margin=float(margin),
        report_distance=float(report_distance), threads=0, brute_force=brute_force,
        watch_distance=float(watch) if watch is not None and watch > margin else 0.0)
    found = _intervals(out.collisions, out, colliding_samples=int(out.colliding_samples))
    found.pair_tests = int(out.pair_tests)
    if out.near is not None:
        near = out.near
        found.near = _intervals(near, out, colliding_samples=int(np.sum(near.last - near.first + 1)))
    return found


def _intervals(intervals: _solver.CollisionIntervals, out: _solver.CollisionResult,
               colliding_samples: int) -> Collisions:
    return Collisions(agent_a=intervals.agent_a, agent_b=intervals.agent_b, first=intervals.first,
                      last=intervals.last, deepest=intervals.deepest, depth=intervals.depth,
                      min_clearance=out.min_clearance, min_clearance_sample=out.min_clearance_sample,
                      colliding_samples=colliding_samples)


def clearances(sampling: Sampling, radius: np.ndarray, a: np.ndarray, b: np.ndarray,
               k: np.ndarray) -> np.ndarray:
    """(M,) capsule clearances of agent columns a and b at samples k (agents on one ground)."""
    return ground_clearances(sampling.positions, radius, a, b, k)


def ground_clearances(positions: np.ndarray, radius: np.ndarray, a: np.ndarray, b: np.ndarray,
                      k: np.ndarray) -> np.ndarray:
    """(M,) clearances of the capsules of agents a and b at samples k, all standing on the
    ground (heights play no part), from #K by #A by 2 positions; the detection's arithmetic."""
    d = positions[k, a] - positions[k, b]
    return np.linalg.norm(d, axis=-1) - radius[a] - radius[b]


def sample_runs(present: np.ndarray, base: np.ndarray | None = None) -> list[tuple[int, int, np.ndarray]]:
    """(first, end, agents) of each run of samples ``first .. end-1`` in which the same two or
    more agents are present (at the same base elevations): :func:`detect_at` measures a run in
    one call, where agents come and go or change elevation.

    Args:
      present: #A by #T bools
      base: #A by #T base elevations (NaN where absent); default: all on the ground
    """
    runs, first = [], 0
    n_times = present.shape[1]
    for t in range(1, n_times + 1):
        if t < n_times and np.array_equal(present[:, t], present[:, first]) \
                and (base is None or np.array_equal(base[:, t], base[:, first], equal_nan=True)):
            continue
        idx = np.flatnonzero(present[:, first])
        if len(idx) >= 2:
            runs.append((first, t, idx))
        first = t
    return runs


_CAPSULE_CLEARANCE = np.vectorize(_solver.capsule_clearance, otypes=[np.float64])


def capsule_clearance(ground_a, base_a, radius_a, height_a, ground_b, base_b, radius_b, height_b):
    """Clearance between vertical capsules (broadcasting; stage units, negative = overlap).

    A capsule stands on ``base`` (its height along up), has total height ``height`` (a capsule
    shorter than ``2 * radius`` is a sphere half way up) and radius ``radius``; ``ground`` is
    its ``(..., 2)`` ground position.
    """
    d = np.asarray(ground_b, dtype=np.float64) - np.asarray(ground_a, dtype=np.float64)
    return _CAPSULE_CLEARANCE(d[..., 0], d[..., 1], radius_a, height_a, base_a, radius_b, height_b, base_b)


# ---- avoid regions -----------------------------------------------------------------------

def _to_world_ground(points: np.ndarray, local_to_world: np.ndarray, up_axis: str) -> np.ndarray:
    homo = np.concatenate([points, np.ones((len(points), 1))], axis=1)
    return ground.to_ground((homo @ local_to_world)[:, :3], up_axis)


def region_footprint(region: AvoidRegion, up_axis: str):
    """The region's ground footprint as a :class:`mocapedit._solver.GroundRegion`.

    Raises MocapEditError naming the region for a non-positive radius or size, a negative
    margin, or a transform or geometry that leaves the footprint without area.
    """
    if not np.isfinite(region.margin) or region.margin < 0:
        raise prim_error(region.path, f"margin must not be negative, got {region.margin:g}", "margin")
    if region.geometry is not None:
        lo, hi = region.geometry_bounds
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        pts = ground.to_ground(corners, up_axis)
        try:
            return _solver.GroundRegion.hull(np.ascontiguousarray(pts))
        except _solver.InvalidInput:
            raise prim_error(region.path, f"the ground footprint of geometry <{region.geometry}> has no "
                             "area", "geometry") from None
    m = np.asarray(region.local_to_world, dtype=np.float64)
    if region.shape == "circle":
        if not (np.isfinite(region.radius) and region.radius > 0):
            raise prim_error(region.path, f"radius must be positive, got {region.radius:g}", "radius")
        i, j = ground.plane_indices(up_axis)   # the region's own ground axes
        local = np.zeros((3, 3))
        local[1, i] = 1.0
        local[2, j] = 1.0
        g = _to_world_ground(local, m, up_axis)
        centre, axes = g[0], g[1:] - g[0]     # images of the local ground axes
        gram = axes @ axes.T
        scale2 = 0.5 * np.trace(gram)
        if not scale2 > 0 or abs(np.linalg.det(axes)) <= 1e-12 * scale2:
            raise prim_error(region.path, "its transform flattens the circle to no area on the ground",
                             "radius")
        if np.allclose(gram, scale2 * np.eye(2), rtol=1e-9, atol=1e-12 * scale2):
            return _solver.GroundRegion.circle(centre, region.radius * np.sqrt(scale2))
        # An ellipse on the ground: a polygon circumscribed about it (it contains the ellipse).
        theta = 2 * np.pi * np.arange(ELLIPSE_SIDES) / ELLIPSE_SIDES
        r = region.radius / np.cos(np.pi / ELLIPSE_SIDES)
        ring = np.stack([np.cos(theta), np.sin(theta)], axis=1) * r
        return _solver.GroundRegion.hull(np.ascontiguousarray(centre + ring @ axes))
    size = np.asarray(region.size, dtype=np.float64)
    if not (np.all(np.isfinite(size)) and np.all(size > 0)):
        raise prim_error(region.path, f"size must be positive along every axis, got "
                         f"({', '.join(f'{s:g}' for s in size)})", "size")
    half = 0.5 * size
    corners = np.array([[x, y, z] for x in (-half[0], half[0]) for y in (-half[1], half[1])
                        for z in (-half[2], half[2])])
    try:
        return _solver.GroundRegion.hull(np.ascontiguousarray(_to_world_ground(corners, m, up_axis)))
    except _solver.InvalidInput:
        raise prim_error(region.path, "its transform flattens the box to no area on the ground", "size") from None


def region_agents(region: AvoidRegion, agents: list[str]) -> list[str]:
    """The agents a region applies to, among ``agents`` (all of them when it lists none)."""
    if not region.agents:
        return list(agents)
    listed = set(region.agents)
    return [a for a in agents if a in listed]


def push_out(footprint, points: np.ndarray, clearance) -> _solver.RegionPush:
    """Points of (N,2) closer to a footprint than their clearance ((N,) or scalar); see
    :func:`mocapedit._solver.push_out_of_region`."""
    c = np.atleast_1d(np.asarray(clearance, dtype=np.float64))
    return _solver.push_out_of_region(footprint, np.ascontiguousarray(points, dtype=np.float64), c)


def signed_distance(footprint, points: np.ndarray) -> np.ndarray:
    """(N,) signed distances of (N,2) ground points to a footprint's boundary (negative inside)."""
    return _solver.region_signed_distance(footprint, np.ascontiguousarray(points, dtype=np.float64))


def outline(footprint, grow: float = 0.0, sides: int = 64) -> np.ndarray:
    """(K,2) counter-clockwise outline of a footprint grown by ``grow`` (rounded corners)."""
    if footprint.is_circle:
        a = 2 * np.pi * np.arange(sides) / sides
        return np.asarray(footprint.center) + (footprint.radius + grow) * np.stack([np.cos(a), np.sin(a)], 1)
    poly = np.asarray(footprint.polygon)
    if grow <= 0:
        return poly.copy()
    edges = np.roll(poly, -1, axis=0) - poly
    normals = np.stack([edges[:, 1], -edges[:, 0]], 1) / np.linalg.norm(edges, axis=1)[:, None]
    points = []
    steps = max(2, sides // len(poly))
    for i in range(len(poly)):
        a0 = np.arctan2(*normals[i - 1][::-1])
        a1 = np.arctan2(*normals[i][::-1])
        a1 = a0 + (a1 - a0) % (2 * np.pi)
        for t in np.linspace(a0, a1, steps):
            points.append(poly[i] + grow * np.array([np.cos(t), np.sin(t)]))
    return np.array(points)
