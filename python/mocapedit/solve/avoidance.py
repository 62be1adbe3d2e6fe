"""Collision avoidance by waiting and path editing (chapter 6 of the deliverable), and avoid regions.

The agents' ground paths are re-solved with the two-step Laplacian energy of the path
editor (:class:`mocapedit._solver.SeparationSolver`: each agent factored once, rows that
push points apart added per solve) until no two capsules overlap and no agent stands in
an avoid region, or ``max_iterations`` is reached. Two strategies:

``accumulate`` (the deliverable, sections 6.2 and 6.3)
  At each iteration, every maximal collision (the deepest sample of each contiguous
  collision interval of a pair) adds a mesh-based constraint joining the two colliding
  points at capsule clearance plus margin, along the line between them; the paths are
  re-solved with the previous iteration's result as the new source. The deliverable notes
  that this accumulates deformation, since every iteration's source is already deformed.

``relinearize`` (the default)
  The source stays the input paths, factored once. Every sample where two agents have
  overlapped or come within ``buffer_m`` of it stays a one-sided row ("at least the
  clearance apart along this direction"), re-linearised around the latest result at each
  iteration; each solve finds the row forces of that complementarity problem (a row
  pushes or stays idle, it never pulls), so near misses switch on by themselves when a
  push drives them into contact. Where two agents overlap they are pushed sideways to
  their relative motion, on one side per pair (one side in the world, so a walker who
  walks up to another and back passes it on the same side both ways), so a walker steps
  round the other instead of being held back before the crossing and thrown forward after
  it. Each solve starts from the original source, so deformation does not accumulate.

  What makes it fast: the detection that counts the collisions also gathers the near
  misses (one pass); a row keeps the direction it was solved with while the fresh one
  turns less than ``keep_degrees`` (any direction is a conservative separation), so rows
  are re-sent unchanged and the solver reuses their agents' Schur blocks; each solve
  step starts from the last solve's forces of the same step; a pair that still overlaps
  where it was already held apart is held at every sample of its intervals, a little
  further apart each time it resists, so the iterations do not stall on it.

Before either, walkers wait (``Settings.max_wait_s``, ``MocapSolveSettings.maxWait``):
of two walkers whose paths cross, the one that reaches the crossing later slows down
before it, through its time map, until the other has passed (of two walking the same
way, the one behind waits). A wait changes no path: no detour, no turn, no length added,
and feet planted in the source stay planted (the pose plays slower, it does not slide).
What waiting cannot part (head-on, overtaking without room, standing agents, agents whose
timing constraints fix) the paths then resolve. Measured on the example scenes by FK
(README), waiting first and then steering with a weak anchor (detours spread over about
0.75 s each side at 24 fps) beat steering alone on foot skate, path length and walking
direction.

Before waiting, the paths go round the avoid regions alone, with a much weaker anchor
(``Settings.region_anchor_weight``): a region stands still, so a walker heading into it veers
from afar and every step bends a little; waiting and steering then start from those paths
(:func:`_detours` says why, with the figures). Regions keep their rows in the later solves.

Artist constraints hold throughout: hard pins and links are hard rows of every solve,
stationary ranges move rigidly. Pairs that hard constraints hold together are reported,
not looped on. The iterations stop when ``patience`` of them in a row make no progress.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import trajectory
from mocapedit.solve import collisions
from mocapedit.solve.path_edit import MIN_BASELINE_M
from mocapedit.model import report

STRATEGIES = ("relinearize", "accumulate")

#: Softness of separation and region rows (1 / weight, relative to the shape terms): nearly
#: hard, but two constraints that cannot both hold give way instead of failing.
SEPARATION_SOFTNESS = 1e-5
#: Fraction of the distance a hard link holds two agents at by which they may come closer
#: around the link's moment and still count as held there (the sway of a standing pair).
LINK_HOLD_SLACK = 0.1


@dataclass
class Pin:
    """The agent's ground position at a frame: hard (softness 0) or soft (1 / weight)."""
    agent: int
    frame: int
    position: np.ndarray          # (2,) ground, stage units
    softness: float = 0.0
    name: str = ""


@dataclass
class Link:
    """Agent a at frame fa minus agent b at frame fb equals offset (hard)."""
    a: int
    fa: int
    b: int
    fb: int
    offset: np.ndarray            # (2,) ground, stage units
    name: str = ""


@dataclass
class Region:
    """An avoid region: the listed agents stay outside its footprint by their clearance."""
    name: str
    footprint: object             # mocapedit._solver.GroundRegion
    agents: np.ndarray            # (N,) agent indices
    clearance: np.ndarray         # (N,) capsule radius plus margin, stage units


@dataclass
class Problem:
    names: list[str]                    # (A,) agent paths
    paths: list[np.ndarray]             # (F_a,2) ground path per source frame before avoidance
    frame_times: list[np.ndarray]       # (F_a,) shot time of each source frame
    radius: np.ndarray                  # (A,) capsule radius, stage units
    height: np.ndarray                  # (A,) capsule height, stage units
    margin: float = 0.0                 # extra clearance between capsules, stage units
    sample_step: float = 1.0            # time codes between collision samples
    rigid: list[tuple[int, int, int]] = field(default_factory=list)   # (agent, first, last) frames
    pins: list[Pin] = field(default_factory=list)
    links: list[Link] = field(default_factory=list)
    regions: list[Region] = field(default_factory=list)
    collide_agents: bool = True         # False: regions only
    fixed_timing: np.ndarray | None = None  # (A,) bool: time constraints fix the agent's timing
    #: (A,) int: the last source frame whose shot time is fixed (a hard position constraint put
    #: the agent there at that moment), -1 for none: the agent may wait, but only after it
    waits_after: np.ndarray | None = None
    span: tuple[float, float] | None = None  # shot times compared (default: all the frames play)
    #: (F_a,2) per agent: the paths whose way the walkers keep (the rows against walking back),
    #: when it is not ``paths``' (a solve resumed from an earlier one's result keeps the source's way)
    way: list[np.ndarray] | None = None
    #: (A,) samples per second of each agent's path (its clip's rate), which set its anchor
    #: (``ANCHOR_RATE``); None: from ``frame_times`` as :func:`resolve` is given them
    samples_per_second: np.ndarray | None = None


#: Samples per second at which the separation solve's weights (``Settings.anchor_weight``,
#: ``region_anchor_weight``, the shape terms) hold. They are per frame, so a path sampled k
#: times as often, weighted alike, detoured over about 1/k of the seconds and gave way k^3 times
#: as easily: the same crossing stepped aside at 0.23 m/s at 24 fps, 0.54 at 60 and 0.87 at 120,
#: and CMU takes (60 and 120 fps) in a crowd swerved 30 cm in a quarter of a second. Each agent
#: is solved at its own rate against this one (``SeparationSolver(rates=)``): the same motion
#: costs the same at any rate.
ANCHOR_RATE = 24.0


@dataclass
class Settings:
    strategy: str = "relinearize"
    max_iterations: int = 10
    anchor_weight: float = 1e-5         # pull of every frame to its source (relative to shape terms)
    overshoot: float = 0.03             # separations aim this fraction past the clearance
    buffer_m: float = 0.3               # near misses watched by relinearize, metres
    spread: int = 3                     # relinearize constrains every n-th sample of an interval
    keep_degrees: float = 5.0           # relinearize keeps a row's direction while it turns less
    sweeps: int = 20                    # Gauss-Seidel sweeps per solve step at least (warm-started)
    sweep_budget: float = 3e5           # rows x sweeps per step allowed beyond that (up to 10x sweeps)
    relaxation: float = 1.0             # over-relaxation of the Gauss-Seidel sweeps, in (0, 2)
    split_from_frames: int | None = 1_000_000  # frames from which a crowd's rows are swept in two
                                        # halves on two threads (None: all in time order)
    tolerance: float = 1e-3             # of the clearance: Gauss-Seidel stops when no row moves more
    patience: int = 6                   # stop after this many iterations without progress
    stiffen_after: int = 3              # relinearize: from this iteration on, the anchor is
    stiffen: float = 3.0                # this many times stiffer (10 slid a dense crowd's feet 1.35
                                        # times the source's before locking; 3: 1.23, README)
    forward_keep: float | None = 0.5    # relinearize: least projection of an edited 0.25 s chord on
                                        # the source's direction, in source chord lengths (None: none)
    forward_cone_degrees: float = 45.0  # relinearize: largest angle of such a chord off that direction
    forward_watch: float = 0.25         # relinearize: such a chord's rows are held once within this
                                        # many source chord lengths of breaking
    #: pull of every frame to its source while the paths go round the avoid regions, before
    #: any walker waits or steps aside (None: regions are solved with the collisions, at
    #: ``anchor_weight``): weak, so a detour round a static region spreads over the approach
    region_anchor_weight: float | None = 1.5e-7
    max_wait_s: float = 3.0             # most delay waiting may add to one agent, seconds (0: none)
    wait_step_s: float = 0.25           # delays are tried in steps of this, seconds
    wait_rounds: int = 8                # rounds of waiting at most
    time_codes_per_second: float = 24.0
    meters_per_unit: float = 1.0


@dataclass
class Iteration:
    collisions: int                     # collision intervals (pair, contiguous samples)
    colliding_samples: int
    region_samples: int                 # frames inside an avoid region's clearance
    deepest: float                      # largest overlap, stage units
    rows: int = 0                       # separation and region rows of the solve that follows
    solves: int = 0


@dataclass
class Outcome:
    paths: list[np.ndarray]             # (F_a,2) edited ground paths
    rigid_angles: np.ndarray            # per Problem.rigid: rotation of the range (radians, CCW)
    iterations: list[Iteration]         # the state before each solve, then the final state
    sampling: collisions.Sampling       # at the edited paths
    remaining: collisions.Collisions    # collision intervals left
    region_left: list[tuple[int, int, int, float]]  # (region, agent, frame, depth) inside still
    blocked: list[tuple[int, int, float]]  # (agent a, agent b, shot time) held together by hard constraints
    moved: np.ndarray                   # (A,) bool: the agent's path changed
    solves: int = 0
    seconds: float = 0.0
    #: the iterations stopped before max_iterations because ``patience`` of them in a row
    #: neither lowered the count of collisions and region frames nor the deepest overlap
    stalled: bool = False
    #: wall seconds by phase: "factor" (the agents' energies), "detect" (sampling and
    #: detection), "gather", "blocks", "sweeps" and "responses" (inside the solves), "rows"
    #: (the rest: forming the rows)
    timing: dict = field(default_factory=dict)
    #: work done, summed over the solves: "rows" sent, Gauss-Seidel "updates" passed on,
    #: "inverseColumns" (back-substitutions for the agents' Schur blocks)
    work: dict = field(default_factory=dict)

    #: (A,) the shot time of each source frame after waiting (the problem's when none waits)
    frame_times: list[np.ndarray] = field(default_factory=list)
    #: agents that stepping aside sent back against their direction, kept on the paths they came
    #: in with (their overlaps are left)
    kept_direction: list[int] = field(default_factory=list)
    #: (A,) delay each agent took up by waiting, time codes
    delays: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (constraint, agent a, agent b, first and last shot time, distance): hard links that hold
    #: two agents closer than their clearance; the pair is left as it is over that time
    link_held: list[tuple[str, int, int, float, float, float]] = field(default_factory=list)
    #: (agent a, agent b) with a < b: pairs that waiting would part (crossing, or one behind
    #: the other) but neither of which may wait, their timing being fixed
    wait_refused: set[tuple[int, int]] = field(default_factory=set)
    #: the state before each solve of the detours round the avoid regions (solved first, with
    #: ``Settings.region_anchor_weight``), then the final state; empty when there was none
    detour_iterations: list[Iteration] = field(default_factory=list)

    @property
    def converged(self) -> bool:
        return len(self.remaining) == 0 and not self.region_left


class _Rows:
    """Rows of a SeparationSolver solve, gathered as numpy arrays."""

    def __init__(self):
        self.direction, self.rhs, self.softness, self.kind, self.force, self.force1 = [], [], [], [], [], []
        self.term_row, self.term_vertex, self.term_weight = [], [], []
        self.count = 0

    def add(self, direction, rhs, softness, vertices, weights, at_least=False, force=0.0, force1=None):
        """Rows in bulk: direction (R,2), rhs (R,), softness (R,), vertices/weights (R,T).

        ``at_least``: one-sided rows (value >= rhs); ``force``, ``force1``: (R,) starting forces
        of step 2 and step 1 (``force1`` defaults to ``force``).
        """
        direction = np.asarray(direction, dtype=np.float64).reshape(-1, 2)
        r = len(direction)
        if r == 0:
            return np.zeros(0, np.int64)
        idx = self.count + np.arange(r)
        self.direction.append(direction)
        self.rhs.append(np.broadcast_to(np.asarray(rhs, dtype=np.float64), (r,)))
        self.softness.append(np.broadcast_to(np.asarray(softness, dtype=np.float64), (r,)))
        self.kind.append(np.full(r, 1 if at_least else 0, dtype=np.int32))
        self.force.append(np.broadcast_to(np.asarray(force, dtype=np.float64), (r,)))
        self.force1.append(np.broadcast_to(np.asarray(force if force1 is None else force1, dtype=np.float64), (r,)))
        vertices = np.asarray(vertices).reshape(r, -1)
        weights = np.asarray(weights, dtype=np.float64).reshape(r, -1)
        self.term_row.append(np.repeat(idx, vertices.shape[1]))
        self.term_vertex.append(vertices.ravel())
        self.term_weight.append(weights.ravel())
        self.count += r
        return idx

    def solve(self, solver, tolerance: float = 1e-6, max_sweeps: int = 500, relaxation: float = 1.0,
              split_from: int | None = 1_000_000):
        cat = lambda parts, shape, dtype: (np.concatenate(parts) if parts else np.zeros(shape)).astype(dtype)  # noqa: E731
        return solver.solve(direction=cat(self.direction, (0, 2), np.float64).reshape(-1, 2),
                            rhs=cat(self.rhs, 0, np.float64), softness=cat(self.softness, 0, np.float64),
                            term_row=cat(self.term_row, 0, np.int32),
                            term_vertex=cat(self.term_vertex, 0, np.int32),
                            term_weight=cat(self.term_weight, 0, np.float64), kind=cat(self.kind, 0, np.int32),
                            initial_forces=cat(self.force, 0, np.float64), tolerance=tolerance,
                            max_sweeps=max_sweeps, initial_shape_forces=cat(self.force1, 0, np.float64),
                            relaxation=relaxation, split_from=-1 if split_from is None else split_from)


def _samples_per_second(problem: Problem, settings: Settings) -> np.ndarray:
    """(A,) ``Problem.samples_per_second``, or each agent's from its frame times."""
    if problem.samples_per_second is not None:
        return np.asarray(problem.samples_per_second, dtype=np.float64)
    return np.array([trajectory.samples_per_second(t, settings.time_codes_per_second) for t in problem.frame_times],
                    dtype=np.float64)


def _held_frames(problem: Problem, settings: Settings, rates: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(V,) how many frames' time each frame's anchor stands for (empty: one each): an agent's
    first and last frames, where it holds its pose before its clip starts and after it ends
    within ``Problem.span``, stand for as many frames as it holds them at its own rate. Held
    for seconds and anchored as one frame, a pose that walkers kept bumping into slid 1.5 m
    and turned the steps before it 40 degrees; anchored for the time it stands, it is as stiff
    as a stand that long."""
    if problem.span is None or not len(problem.frame_times):
        return np.zeros(0)
    lo, hi = problem.span
    out = np.ones(int(starts[-1]))
    for a, t in enumerate(problem.frame_times):
        if len(t) < 2:
            continue
        per_code = rates[a] / settings.time_codes_per_second
        out[starts[a]] += max(float(t[0]) - lo, 0.0) * per_code
        out[starts[a + 1] - 1] += max(hi - float(t[-1]), 0.0) * per_code
    return out if np.any(out != 1.0) else np.zeros(0)


class _State:
    """The problem laid out for the solver: concatenated paths, samples, fixed rows."""

    def __init__(self, problem: Problem, settings: Settings, sampling: collisions.Sampling | None = None):
        """``sampling``: the problem's agents sampled already, at its time maps and over its span
        (the waits' last sampling), taken over instead of sampled again."""
        self.p = problem
        self.s = settings
        self.rest, self.starts, self.rigid = _layout(problem)
        self.way = self.rest if problem.way is None or not len(problem.paths) else \
            np.concatenate(problem.way).astype(np.float64)
        counts = np.diff(self.starts).astype(np.int64)
        rates = _samples_per_second(problem, settings)
        self.rates = rates / ANCHOR_RATE
        self.anchor_frames = _held_frames(problem, settings, rates, self.starts)
        # A cut in a path (a rest pose left in a clip's first frame) is no motion to keep: no
        # shape term spans it (as the path editor's weigh next to nothing, ``CUT_WEIGHT``).
        step = np.zeros(len(self.rest))
        step[1:] = np.linalg.norm(np.diff(self.rest, axis=0), axis=1)
        cut = trajectory.is_cut(step, np.repeat(1.0 / rates, counts), settings.meters_per_unit)
        cut[self.starts[:-1]] = False
        self.cut_into = cut.astype(np.int32) if cut.any() else np.zeros(0, np.int32)
        self.times = {i: t for i, t in enumerate(problem.frame_times)}
        idx = list(range(len(problem.names)))
        self.sampling = sampling if sampling is not None else collisions.sample(
            idx, self.times, {i: g for i, g in enumerate(problem.paths)}, problem.sample_step, problem.span)
        self.resample = collisions.Resampler(self.sampling, self.starts)
        pinned = np.zeros(len(self.rest), dtype=bool)
        for pin in problem.pins:
            if pin.softness == 0:
                pinned[self.starts[pin.agent] + pin.frame] = True
        self.pinned = pinned
        self.link_holds = self._link_holds()
        self.in_span = self._in_span()

    def _in_span(self) -> np.ndarray:
        """(V,) the frames that play within ``Problem.span`` (and the frame on each side, whose
        positions the samples at its ends interpolate); all frames without a span."""
        out = np.ones(len(self.rest), dtype=bool)
        if self.p.span is None:
            return out
        lo, hi = self.p.span
        for a, t in self.times.items():
            t = np.asarray(t, dtype=np.float64)
            first = max(int(np.searchsorted(t, lo, side="right")) - 1, 0)
            last = min(int(np.searchsorted(t, hi, side="left")), len(t) - 1)
            inside = np.zeros(len(t), dtype=bool)
            inside[first:last + 1] = True
            out[self.starts[a]:self.starts[a + 1]] = inside
        return out

    def _link_holds(self) -> list[tuple[int, int, int, int, int]]:
        """(link, a, b, first, last): samples around each hard link that holds its two agents
        closer than their clearance, over which their input paths stay that close, but no
        closer than the link holds them (within ``LINK_HOLD_SLACK``). The pair is not pushed
        apart there (the artist put them there); elsewhere it is, so two agents who walk into
        each other after a handshake are still parted."""
        p, pos = self.p, self.sampling.positions
        out = []
        for i, link in enumerate(p.links):
            need = p.radius[link.a] + p.radius[link.b] + p.margin
            holds = float(np.linalg.norm(link.offset))
            if holds >= need or not len(self.sampling.times):
                continue
            at = int(np.argmin(np.abs(self.sampling.times - self.times[link.a][link.fa])))
            gap = np.linalg.norm(pos[:, link.a] - pos[:, link.b], axis=1)
            close = (gap < need * (1.0 + self.s.overshoot)) & (gap >= (1.0 - LINK_HOLD_SLACK) * holds)
            close[at] = True
            first, last = at, at
            while first > 0 and close[first - 1]:
                first -= 1
            while last + 1 < len(close) and close[last + 1]:
                last += 1
            out.append((i, min(link.a, link.b), max(link.a, link.b), first, last))
        return out

    def split(self, flat: np.ndarray) -> list[np.ndarray]:
        return [flat[self.starts[a]:self.starts[a + 1]].copy() for a in range(len(self.starts) - 1)]

    def sample_terms(self, agents: np.ndarray, samples: np.ndarray):
        """Vertices (N,2) and weights (N,2) of agents' positions at samples (interpolated)."""
        f = self.sampling.frames_at(samples, agents)
        counts = self.starts[agents + 1] - self.starts[agents]
        f = np.clip(f, 0.0, counts - 1)
        i0 = np.floor(f).astype(np.int64)
        i1 = np.minimum(i0 + 1, counts - 1)
        w1 = f - i0
        base = self.starts[agents]
        return np.stack([base + i0, base + i1], axis=1), np.stack([1.0 - w1, w1], axis=1)

    def held(self, a: np.ndarray, b: np.ndarray, k: np.ndarray) -> np.ndarray:
        """(N,) True where hard constraints hold the pairs (a, b) at samples k: pins hold both
        agents' points (no push can move them), or a link holds the two closer than their
        clearance around that moment."""
        va, wa = self.sample_terms(a, k)
        vb, wb = self.sample_terms(b, k)
        out = np.all(self.pinned[va] | (wa == 0), axis=1) & np.all(self.pinned[vb] | (wb == 0), axis=1)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        for _, la, lb, first, last in self.link_holds:
            out |= (lo == la) & (hi == lb) & (k >= first) & (k <= last)
        return out

    def fixed_rows(self, rows: _Rows, forces: np.ndarray | None = None, forces1: np.ndarray | None = None) -> None:
        """Artist pins and links, two rows each: every solve carries them (``forces``,
        ``forces1``: the last solve's step-2 and step-1 forces, to start from)."""
        count = len(self.p.pins) + len(self.p.links)

        def start(f):
            return np.zeros((count, 2)) if f is None or len(f) != 2 * count else f.reshape(-1, 2)

        f2, f1 = start(forces), start(forces1)
        for i, pin in enumerate(self.p.pins):
            v = self.starts[pin.agent] + pin.frame
            rows.add(np.eye(2), pin.position, pin.softness, [[v], [v]], [[1.0], [1.0]], force=f2[i], force1=f1[i])
        for i, link in enumerate(self.p.links, len(self.p.pins)):
            va, vb = self.starts[link.a] + link.fa, self.starts[link.b] + link.fb
            rows.add(np.eye(2), link.offset, 0.0, [[va, vb], [va, vb]], [[1.0, -1.0], [1.0, -1.0]],
                     force=f2[i], force1=f1[i])

    def detect(self, flat: np.ndarray, extra: float = 0.0, watch: float | None = None) -> collisions.Collisions:
        """Collisions at the paths ``flat`` closer than margin + ``extra``; with ``watch``, also
        the near misses closer than margin + ``watch`` (as ``near``), in the same pass."""
        self.resample(flat)
        active = np.ones(len(self.p.names), dtype=bool) if self.p.collide_agents else np.zeros(len(self.p.names), bool)
        return collisions.detect(self.sampling, self.p.radius, self.p.height, self.p.margin + extra,
                                 report_distance=self.p.margin + extra, active=active,
                                 watch=None if watch is None else self.p.margin + watch)

    def region_hits(self, flat: np.ndarray, extra: float = 0.0):
        """Per region: (vertices, agent of each, push) of the frames that play in the shot
        (``in_span``) within clearance + extra."""
        out = []
        for k, region in enumerate(self.p.regions):
            verts = [np.arange(self.starts[a], self.starts[a + 1]) for a in region.agents]
            verts = [v[self.in_span[v]] for v in verts]
            if not verts:
                out.append(None)
                continue
            owner = np.concatenate([np.full(len(v), i) for i, v in enumerate(verts)])
            verts = np.concatenate(verts)
            clearance = region.clearance[owner] + extra
            push = _solver.push_out_of_region(region.footprint, np.ascontiguousarray(flat[verts]), clearance)
            out.append((verts[push.index], region.agents[owner[push.index]], push))
        return out


def _unit(d: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(d, axis=1)
    ok = n > 1e-12
    out = np.where(ok[:, None], d / np.where(ok, n, 1.0)[:, None], fallback)
    return out


def _fallback_normals(state: _State, a: np.ndarray, b: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Where two points coincide: sideways to their relative motion (or along x)."""
    at = state.sampling.at
    k1 = np.minimum(k + 1, len(state.sampling.times) - 1)
    k0 = np.maximum(k - 1, 0)
    rel = (at(k1, a) - at(k0, a)) - (at(k1, b) - at(k0, b))
    side = np.stack([-rel[:, 1], rel[:, 0]], axis=1)
    n = np.linalg.norm(side, axis=1)
    return np.where((n > 1e-12)[:, None], side / np.where(n > 1e-12, n, 1.0)[:, None], [[1.0, 0.0]])


def _separation_normals(state: _State, a: np.ndarray, b: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Directions pushing agent a away from agent b at samples k, one pass side per pair.

    Two agents passing each other must keep to one side over the whole encounter: the
    line between their points swings from side to side with the sway of a walk, and
    following it would push them alternately left and right. The side of b that a keeps to is
    voted once per pair, in the world (the sum of a's offsets from b across their relative
    motion, over the samples where they are closest), and where they overlap they are pushed
    sideways to their relative motion, towards that side (a conservative linearisation of
    the distance). The vote is taken again at each iteration (among the samples that still
    overlap), so a pair that other pushes moved to the other side is not pulled back through.
    """
    at = state.sampling.at
    rel = at(k, a) - at(k, b)
    k1 = np.minimum(k + 1, len(state.sampling.times) - 1)
    k0 = np.maximum(k - 1, 0)
    motion = (at(k1, a) - at(k0, a)) - (at(k1, b) - at(k0, b))
    speed = np.linalg.norm(motion, axis=1)
    clearance = _clearance(state, a, b)
    # Passing, not walking together: over two samples they move by a fair part of a clearance.
    moving = speed > 0.05 * clearance
    t = np.where(moving[:, None], motion / np.where(moving, speed, 1.0)[:, None], [[1.0, 0.0]])
    perp = np.stack([-t[:, 1], t[:, 0]], axis=1)
    along, across = np.sum(rel * t, axis=1), np.sum(rel * perp, axis=1)
    pair = a * np.int64(len(state.p.names)) + b
    near = np.linalg.norm(rel, axis=1) < clearance
    close = moving & near
    uniq, inverse = np.unique(pair, return_inverse=True)
    # The side is voted in the world: the offsets of a from b across their motion, summed.
    # A vote along the motion (pass on its left) flips with it, and an agent who walks up
    # to another and back, or who walks beside another a little faster then a little slower,
    # was pushed to one side going and to the other coming back: round the other in a loop.
    lateral = np.where(close[:, None], across[:, None] * perp, 0.0)
    vote = np.stack([np.bincount(inverse, weights=lateral[:, i], minlength=len(uniq)) for i in (0, 1)], axis=1)
    # A pair met exactly head-on votes for the left of its motion.
    fallback = np.stack([np.bincount(inverse, weights=np.where(close, perp[:, i], 0.0), minlength=len(uniq))
                         for i in (0, 1)], axis=1)
    scale = np.bincount(inverse, weights=np.where(close, np.abs(across), 0.0), minlength=len(uniq))
    tied = np.linalg.norm(vote, axis=1) <= 1e-9 * scale
    vote[tied] = fallback[tied]
    side = np.where(np.sum(vote[inverse] * perp, axis=1) >= 0, 1.0, -1.0)
    # Where they overlap they pass side by side on the voted side; the line between the
    # points would turn along their motion before and after the crossing and hold one
    # back on each side of it. Apart, each sample keeps its own direction.
    d = np.where(close[:, None], side[:, None] * perp, along[:, None] * t + across[:, None] * perp)
    # Where they overlap but barely move against each other (one stands where the other
    # turns back, pauses or sways), the pair's voted side holds: the line between their
    # points is a few centimetres long there and points anywhere, and following it pushed
    # such samples out in every direction, round the other in a loop.
    still = ~moving & near & (np.linalg.norm(vote, axis=1) > 0)[inverse]
    d[still] = vote[inverse[still]]
    return _unit(d, np.where(moving[:, None], side[:, None] * perp, [[1.0, 0.0]]))


def _clearance(state: _State, a, b) -> np.ndarray:
    return state.p.radius[a] + state.p.radius[b] + state.p.margin


def _iteration(state: _State, found: collisions.Collisions, hits) -> Iteration:
    return Iteration(collisions=len(found), colliding_samples=int(found.colliding_samples),
                     region_samples=int(sum(len(h[0]) for h in hits if h is not None)),
                     deepest=float(max([found.depth.max(initial=0.0)] +
                                       [h[2].depth.max(initial=0.0) for h in hits if h is not None])))


def _expand(found: collisions.Collisions, spread, colliding_depth: float = 0.0):
    """(a, b, sample) to constrain for each interval: its deepest sample, and, for intervals
    deeper than ``colliding_depth``, every spread-th sample and the last one too
    (``spread``: one for all intervals, or (M,) one per interval)."""
    if len(found) == 0:
        z = np.zeros(0, np.int64)
        return z, z, z
    deep = found.depth > colliding_depth
    spread = np.broadcast_to(np.asarray(spread, dtype=np.int64), (len(found),))
    length = np.where(deep, (found.last - found.first) // spread + 2, 0)
    rep = np.repeat(np.arange(len(found)), length)
    offset = np.arange(int(length.sum())) - np.repeat(np.cumsum(length) - length, length)
    k = np.minimum(found.first[rep] + offset * spread[rep], found.last[rep])
    a = np.concatenate([found.agent_a, found.agent_a[rep]])
    b = np.concatenate([found.agent_b, found.agent_b[rep]])
    k = np.concatenate([found.deepest, k])
    return a.astype(np.int64), b.astype(np.int64), k.astype(np.int64)


def resolve(problem: Problem, settings: Settings | None = None, progress=None) -> Outcome:
    """Pushes the agents' paths apart and out of the regions; see the module doc."""
    settings = settings or Settings()
    if settings.strategy not in STRATEGIES:
        raise ValueError(f"unknown collision strategy '{settings.strategy}' (use {' or '.join(STRATEGIES)})")
    t0 = time.perf_counter()
    fixed = np.zeros(len(problem.names), bool) if problem.fixed_timing is None else np.asarray(problem.fixed_timing)
    # Anchors by the clips' own rates, before waiting stretches their timing.
    problem = dataclasses.replace(problem, samples_per_second=_samples_per_second(problem, settings))
    source = problem
    strategy = _relinearize if settings.strategy == "relinearize" else _accumulate
    detour = _detours(problem, settings, strategy, progress)
    if detour is not None:
        problem = dataclasses.replace(problem, paths=detour[0])
    waits = _waits(problem, settings, fixed)
    if waits.delay.any():
        problem = dataclasses.replace(problem, frame_times=waits.frame_times, span=waits.span)
    state = _State(problem, settings, sampling=waits.sampling)
    watch = settings.buffer_m / settings.meters_per_unit if settings.strategy == "relinearize" else None
    run = _Run(state, progress, watch)
    flat, angles = strategy(state, run)
    backward = _walks_backward(state, flat)
    while any(backward[k.a] != backward[k.b] for k in problem.links):   # linked agents go back together
        for k in problem.links:
            backward[k.a] = backward[k.b] = backward[k.a] or backward[k.b]
    if backward.any():
        # An agent sent back against its source direction (a loop, a hook) is worse than an
        # overlap it leaves: it keeps the path it came in with, and what it leaves is reported.
        for a in np.flatnonzero(backward):
            flat[state.starts[a]:state.starts[a + 1]] = state.rest[state.starts[a]:state.starts[a + 1]]
        angles = np.where([backward[a] for a, _, _ in problem.rigid], 0.0, angles) if len(problem.rigid) else angles
        run.found, run.hits = state.detect(flat, watch=run.watch), state.region_hits(flat)
    if detour is not None:
        angles = angles + detour[1]
        run.merge(detour[2])
    found, hits = run.found, run.hits
    region_left = []
    for r, h in enumerate(hits):
        if h is None:
            continue
        verts, agents, push = h
        for v, a, d in zip(verts, agents, push.depth):
            region_left.append((r, int(a), int(v - state.starts[a]), float(d)))
    moved = np.array([not np.array_equal(flat[state.starts[a]:state.starts[a + 1]], source.paths[a])
                      for a in range(len(problem.names))], dtype=bool)
    return Outcome(kept_direction=np.flatnonzero(backward).tolist(), paths=state.split(flat), rigid_angles=angles, iterations=run.iterations,
                   sampling=state.sampling, remaining=found, region_left=region_left,
                   blocked=_blocked(state, found), link_held=_link_held(state), moved=moved, solves=run.solves, stalled=run.stalled,
                   frame_times=waits.frame_times, delays=waits.delay, wait_refused=waits.refused,
                   seconds=time.perf_counter() - t0, timing=run.timing(time.perf_counter() - t0), work=dict(run.work),
                   detour_iterations=detour[2].iterations if detour is not None else [])


class Uncleared:
    """What paths leave uncleared at a problem's samples (its time maps and span), measured as
    often as the paths change: the problem is laid out and sampled once. Nothing is solved."""

    def __init__(self, problem: Problem, settings: Settings | None = None):
        self._state = _State(problem, settings or Settings())

    def __call__(self, paths: list[np.ndarray]) -> tuple[set[tuple[int, int]], set[int]]:
        """(pairs, inside) at ``paths`` (one (F,2) ground path per agent, as the problem's): the
        pairs of agents ``(a, b)``, ``a < b``, closer than their clearance at some sample, and
        the agents with a frame in the shot within an avoid region's clearance."""
        state = self._state
        flat = np.concatenate(paths).astype(np.float64) if len(paths) else state.rest
        found = state.detect(flat)
        pairs = set(zip(found.agent_a.tolist(), found.agent_b.tolist()))
        inside = {int(a) for hit in state.region_hits(flat) if hit is not None for a in hit[1]}
        return pairs, inside


#: Seconds between the two ends of the chords whose directions :func:`_walks_backward` compares,
#: and metres a source chord spans at least to count (the plausibility figures' walking direction).
CHORD_SECONDS = 0.25
CHORD_MIN_M = 0.05


def _walks_backward(state: "_State", flat: np.ndarray) -> np.ndarray:
    """(agents,) whether the paths ``flat`` send an agent more than 90 degrees away from the
    direction it walks in on the path it came in with, on any chord of ``CHORD_SECONDS``
    where that path travels ``CHORD_MIN_M`` or more."""
    s = state.s
    agents = len(state.p.names)
    least = CHORD_MIN_M / s.meters_per_unit
    # Each agent's chords (first, last frame) as rows of the concatenated paths; agents that
    # play their frames at the same times share the search.
    chords: dict[bytes, int] = {}
    starts, ends = [], []           # per distinct time map: its chords' first and last frames
    group = np.zeros(agents, dtype=np.int64)
    for a, times in enumerate(state.p.frame_times):
        times = np.asarray(times, dtype=np.float64)
        key = times.tobytes()
        if key not in chords:
            seconds = times / s.time_codes_per_second
            end = np.searchsorted(seconds, seconds + CHORD_SECONDS)
            ok = end < len(seconds)
            chords[key] = len(starts)
            starts.append(np.flatnonzero(ok))
            ends.append(end[ok])
        group[a] = chords[key]
    if not agents:
        return np.zeros(agents, dtype=bool)
    # All agents' chords at once, agent after agent: agent a's are its time map's, shifted to
    # its rows.
    count = np.array([len(c) for c in starts], dtype=np.int64)
    at = np.concatenate([[0], np.cumsum(count)])
    per_agent = count[group]
    owner = np.repeat(np.arange(agents), per_agent)
    pick = np.arange(int(per_agent.sum())) + np.repeat(at[group] - (np.cumsum(per_agent) - per_agent), per_agent)
    shift = state.starts[:-1].astype(np.int64)[owner]
    first, last = np.concatenate(starts)[pick] + shift, np.concatenate(ends)[pick] + shift
    was, now = state.way[last] - state.way[first], flat[last] - flat[first]
    back = (np.linalg.norm(was, axis=1) >= least) & (np.einsum("ij,ij->i", was, now) < 0.0)
    return np.bincount(owner[back], minlength=agents) > 0


def _detours(problem: Problem, settings: Settings, strategy, progress):
    """The paths gone round the avoid regions alone, before anyone waits or steps aside:
    (paths, rigid angles, the run), or None without regions or ``region_anchor_weight``.

    Regions stand still: a walker heading into one can go round it from afar. Solved with the
    walkers' usual anchor, a detour round a fountain bends the path within about 0.75 s each
    side; with the same timing, the bent stretch walks up to 85 % faster than its source and
    turns up to 60 degrees more within one step (``avoid_regions.usda``), so planted feet are
    dragged 40 to 70 cm, further than legs reach. With the anchor ``region_anchor_weight``
    (weak), the detour spreads over about 2 s each side: every step bends a little, the path
    keeps its length within a few per cent, and the walker's place shifts instead (most where
    the region stands early or late in its walk).
    Waiting and stepping aside then start from these paths, with the usual anchor, so the
    regions' detours are planned once and the walkers part from each other around them."""
    if settings.region_anchor_weight is None or not any(len(r.agents) for r in problem.regions):
        return None
    alone = dataclasses.replace(settings, anchor_weight=settings.region_anchor_weight)
    state = _State(dataclasses.replace(problem, collide_agents=False), alone)
    run = _Run(state, progress, None, "avoid regions")
    flat, angles = strategy(state, run)
    return state.split(flat), angles, run


def _layout(problem: Problem) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """(rest, starts, rigid): the agents' paths concatenated, each agent's first row (then the
    total), and the rigid ranges as global rows, as the solver takes them."""
    counts = np.array([len(g) for g in problem.paths], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    rest = np.concatenate(problem.paths).astype(np.float64) if len(counts) else np.zeros((0, 2))
    rigid = [(int(starts[a] + f), int(starts[a] + l)) for a, f, l in problem.rigid]
    return rest, starts, rigid


class _Run:
    """What both strategies share: the detection before each solve, its record, progress."""

    def __init__(self, state: _State, progress, watch: float | None = None, task: str = "collision avoidance"):
        self.state = state
        self.watch = watch              # near misses gathered by each detection (stage units)
        self.iterations: list[Iteration] = []
        self.solves = 0
        self.seconds = {"factor": 0.0, "detect": 0.0, "gather": 0.0, "blocks": 0.0, "sweeps": 0.0, "responses": 0.0}
        self.work = {"rows": 0, "updates": 0, "inverseColumns": 0}
        self.found = None
        self.hits = None
        self.best = (np.inf, np.inf)    # fewest collisions and region frames, smallest deepest overlap
        self.since_best = 0             # iterations since either improved
        self.stalled = False
        self.pending = False            # rows were added that the next solve must meet
        self.task = progress.task(task, state.s.max_iterations, "iterations") if progress else None

    def merge(self, other: "_Run") -> None:
        """Adds the time and work of an earlier run (the regions' detours) to this one's."""
        for k, v in other.seconds.items():
            self.seconds[k] += v
        for k, v in other.work.items():
            self.work[k] += v
        self.solves += other.solves

    def observe(self, flat: np.ndarray, it: int) -> bool:
        """Detects at the current paths; True when there is nothing (more) to solve."""
        state = self.state
        t = time.perf_counter()
        self.found = state.detect(flat, watch=self.watch)
        self.hits = state.region_hits(flat)
        self.seconds["detect"] += time.perf_counter() - t
        record = _iteration(state, self.found, self.hits)
        self.iterations.append(record)
        left = record.collisions + record.region_samples
        # Constraints that cannot all hold (a wall closer than a capsule, a crowd packed
        # tighter than its clearances) trade overlap for overlap forever: stop when the
        # iterations no longer make progress, whatever max_iterations says.
        if left < self.best[0] or record.deepest < self.best[1] * (1.0 - 1e-3):
            self.since_best = 0
        else:
            self.since_best += 1
        self.best = (min(self.best[0], left), min(self.best[1], record.deepest))
        self.stalled = left > 0 and self.since_best >= state.s.patience and it < state.s.max_iterations
        last = (left == 0 and not self.pending) or it == state.s.max_iterations or self.stalled
        if self.task is not None:
            left = report.describe_left(record.collisions, record.region_samples)
            if last:
                self.task.done(left, count=it)
            else:
                self.task.update(it, left)
        return last

    def timing(self, total: float) -> dict:
        out = {k: round(v, 4) for k, v in self.seconds.items()}
        out["rows"] = round(total - sum(self.seconds.values()), 4)
        return out

    def factor(self, rest, starts, rigid, anchor_weight: float, still_extent: float):
        """A SeparationSolver for the paths (rest, starts) and their rigid ranges, timed. Its
        shape terms are framed as the path editor's (``MIN_BASELINE_M``)."""
        t = time.perf_counter()
        solver = _solver.SeparationSolver(rest=rest, starts=starts, rigid=rigid, anchor_weight=anchor_weight,
                                          rates=self.state.rates, anchor_frames=self.state.anchor_frames,
                                          cut_into=self.state.cut_into,
                                          still_extent=still_extent,
                                          min_baseline=MIN_BASELINE_M / self.state.s.meters_per_unit, threads=0)
        self.seconds["factor"] += time.perf_counter() - t
        return solver

    def solved(self, rows: "_Rows", out: _solver.SeparationResult) -> None:
        for name, sec in zip(("blocks", "sweeps", "responses", "gather"), out.seconds):
            self.seconds[name] += float(sec)
        self.work["updates"] += int(out.updates)
        self.work["inverseColumns"] += int(out.inverse_columns)
        self.work["rows"] += rows.count
        self.solves += 1
        self.iterations[-1].rows = rows.count
        self.iterations[-1].solves = 1


def _accumulate(state: _State, run: _Run):
    """The deliverable's scheme: each iteration re-solves from the previous result."""
    p, s = state.p, state.s
    flat = state.rest.copy()
    angles = np.zeros(len(p.rigid))
    for it in range(s.max_iterations + 1):
        if run.observe(flat, it):
            break
        found = run.found
        solver = run.factor(flat, state.starts, state.rigid, s.anchor_weight, _still(s))
        rows = _Rows()
        state.fixed_rows(rows)
        # A mesh-based constraint per maximal collision: the two colliding points joined by
        # an edge of the clearance's length, along the line between them.
        a, b, k = (found.agent_a.astype(np.int64), found.agent_b.astype(np.int64),
                   found.deepest.astype(np.int64))
        pa, pb = state.sampling.at(k, a), state.sampling.at(k, b)
        offset = _unit(pa - pb, _fallback_normals(state, a, b, k)) * \
            (_clearance(state, a, b) * (1.0 + s.overshoot))[:, None]
        va, wa = state.sample_terms(a, k)
        vb, wb = state.sample_terms(b, k)
        verts, weights = np.concatenate([va, vb], axis=1), np.concatenate([wa, -wb], axis=1)
        for axis in (0, 1):
            rows.add(np.eye(2)[[axis] * len(a)], offset[:, axis], SEPARATION_SOFTNESS, verts, weights)
        # Regions: each frame inside is pinned where it is pushed to.
        for h in run.hits:
            if h is None or len(h[0]) == 0:
                continue
            verts_r, agents_r, push = h
            target = push.target + push.normal * (s.overshoot * p.radius[agents_r])[:, None]
            for axis in (0, 1):
                rows.add(np.eye(2)[[axis] * len(verts_r)], target[:, axis], SEPARATION_SOFTNESS,
                         verts_r[:, None], np.ones((len(verts_r), 1)))
        out = rows.solve(solver)
        run.solved(rows, out)
        flat = out.positions
        angles = angles + out.rigid_angles
    return flat, angles


def _still(settings: Settings) -> float:
    return 1e-5 / settings.meters_per_unit


class _Candidates:
    """Separation constraints of relinearize, one per (agent a, agent b, sample), kept
    sorted by key (sample-major, so Gauss-Seidel sweeps them in time order)."""

    def __init__(self, agents: int):
        self.n = np.int64(max(agents, 1))
        self.keys = np.zeros(0, np.int64)
        self.force = np.zeros(0)          # last solve's step-2 force (warm start)
        self.force1 = np.zeros(0)         # and its step-1 force
        self.blocked = np.zeros(0, bool)  # hard constraints hold this pair together
        self.normal = np.zeros((0, 2))    # direction of the last solve's row (NaN: not solved yet)
        self.pair_keys = np.zeros(0, np.int64)   # pairs that resisted (a * n + b), sorted
        self.pair_count = np.zeros(0, np.int64)  # how many times each did

    def split(self):
        n = self.n
        return (self.keys // n) % n, self.keys % n, self.keys // (n * n)

    def prune(self, state: _State, reach: float) -> None:
        """Forgets watched samples that do not push and whose agents are now far apart."""
        a, b, k = self.split()
        gap = np.linalg.norm(state.sampling.at(k, a) - state.sampling.at(k, b), axis=1) \
            - _clearance(state, a, b)
        keep = (self.force > 0.0) | (self.force1 > 0.0) | self.blocked | (gap < reach)
        self.keys, self.force, self.force1, self.blocked, self.normal = (
            self.keys[keep], self.force[keep], self.force1[keep], self.blocked[keep], self.normal[keep])

    def resist(self, found: collisions.Collisions) -> None:
        """Counts, per pair, the detections that still found it overlapping although it had
        rows already (``found``: the collisions at the latest result)."""
        if len(found) == 0:
            return
        pairs = np.unique(found.agent_a.astype(np.int64) * self.n + found.agent_b)
        ca, cb, _ = self.split()
        held = pairs[np.isin(pairs, ca * self.n + cb)]
        self.pair_keys, self.pair_count = _count_into(self.pair_keys, self.pair_count, held)

    def resistance(self, a, b) -> np.ndarray:
        """(N,) how many times the pairs (a, b) resisted."""
        keys = np.asarray(a, np.int64) * self.n + np.asarray(b, np.int64)
        if len(self.pair_keys) == 0:
            return np.zeros(len(keys), np.int64)
        at = np.minimum(np.searchsorted(self.pair_keys, keys), len(self.pair_keys) - 1)
        return np.where(self.pair_keys[at] == keys, self.pair_count[at], 0)

    def resisting(self, found: collisions.Collisions) -> np.ndarray:
        """(M,) True for the intervals of pairs that resisted."""
        return self.resistance(found.agent_a, found.agent_b) > 0

    def add(self, a, b, k) -> None:
        keys = np.unique((k * self.n + a) * self.n + b)
        at = np.searchsorted(self.keys, keys)
        known = at < len(self.keys)
        known[known] = self.keys[at[known]] == keys[known]
        new, at = keys[~known], at[~known]
        if len(new) == 0:
            return
        # Both sorted: each new key goes in before the first kept key above it.
        self.keys = np.insert(self.keys, at, new)
        self.force = np.insert(self.force, at, 0.0)
        self.force1 = np.insert(self.force1, at, 0.0)
        self.blocked = np.insert(self.blocked, at, False)
        self.normal = np.insert(self.normal, at, np.nan, axis=0)

    def linearise(self, fresh: np.ndarray, keep_cos: float) -> np.ndarray:
        """The rows' directions for the next solve, given the directions at the latest result.

        Any unit direction makes a conservative separation row (the distance is at least
        its projection), so a row keeps the direction it was solved with while that is
        within the angle whose cosine is ``keep_cos`` of the fresh one: rows sent again
        unchanged cost the solver nothing to set up, and their forces are warm starts as
        they are. A row whose direction turns past a right angle starts again from zero force.
        """
        cos = np.sum(self.normal * fresh, axis=1)
        turn = ~(cos >= keep_cos)
        flip = turn & ~(cos > 0.0)
        self.force[flip] = 0.0
        self.force1[flip] = 0.0
        self.normal[turn] = fresh[turn]
        return self.normal


def _count_into(keys: np.ndarray, counts: np.ndarray, new: np.ndarray):
    """Sorted keys and counts, with one more for each of the unique keys ``new``."""
    merged = np.concatenate([keys, new])
    uniq, inverse = np.unique(merged, return_inverse=True)
    total = np.bincount(inverse, weights=np.concatenate([counts, np.ones(len(new))]), minlength=len(uniq))
    return uniq, total.astype(np.int64)


class _RegionCandidates:
    """Frames watched near each avoid region: one-sided rows, re-linearised each iteration."""

    def __init__(self):
        self.region = np.zeros(0, np.int64)
        self.vertex = np.zeros(0, np.int64)
        self.clearance = np.zeros(0)
        self.force = np.zeros(0)
        self.force1 = np.zeros(0)

    def add(self, region: int, vertices: np.ndarray, clearance: np.ndarray) -> None:
        known = self.vertex[self.region == region]
        new = ~np.isin(vertices, known)
        self.region = np.concatenate([self.region, np.full(int(new.sum()), region)])
        self.vertex = np.concatenate([self.vertex, vertices[new]])
        self.clearance = np.concatenate([self.clearance, clearance[new]])
        self.force = np.concatenate([self.force, np.zeros(int(new.sum()))])
        self.force1 = np.concatenate([self.force1, np.zeros(int(new.sum()))])

    def linearise(self, state: _State, flat: np.ndarray):
        """(normal (N,2), rhs (N,)) of one-sided rows n . x >= rhs keeping frames out.

        A frame outside the region grown by its clearance keeps to the tangent line at its
        nearest point. A frame inside whose source frame (the solve's rest) lies inside too
        goes round the region: sideways to the agent's motion, on the side of the region's
        centre its path already passes, to where that sideways line leaves the grown region
        (the tangent line there). Pushing each frame to its nearest boundary point would
        instead hold a walker back before the middle of the region and throw it forward
        after it. A frame that others pushed in (its source frame lies outside: a walker
        squeezed against a wall) goes back out the nearest way; sideways to a walk along a
        wall lies the wall's far side.
        """
        normal = np.zeros((len(self.vertex), 2))
        rhs = np.zeros(len(self.vertex))
        owner = np.searchsorted(state.starts, self.vertex, side="right") - 1
        for r, region in enumerate(state.p.regions):
            sel = np.flatnonzero(self.region == r)
            if len(sel) == 0:
                continue
            v, c = self.vertex[sel], self.clearance[sel]
            pts = flat[v]
            near = _solver.nearest_on_region(region.footprint, np.ascontiguousarray(pts))
            nrm = near.normal.copy()
            target = near.boundary + nrm * c[:, None]
            inside = near.distance < c
            if inside.any():
                own = _solver.nearest_on_region(region.footprint, np.ascontiguousarray(state.rest[v[inside]]))
                inside[np.flatnonzero(inside)[own.distance >= c[inside]]] = False
            if inside.any():
                t = _path_tangents(state, flat, v[inside])
                speed = np.linalg.norm(t, axis=1)
                moving = speed > 1e-12
                # Unit: _exit walks its rays by distance.
                t = t / np.where(moving, speed, 1.0)[:, None]
                left = np.stack([-t[:, 1], t[:, 0]], axis=1)
                centre = _centre(region.footprint)
                cross = np.sum(left * (centre - pts[inside]), axis=1)   # > 0: centre on the left
                agents = owner[sel][inside]
                uniq, inv = np.unique(agents, return_inverse=True)
                side = np.where(np.bincount(inv, weights=cross, minlength=len(uniq)) > 0, -1.0, 1.0)[inv]
                way = side[:, None] * left
                exit_pt = _exit(region.footprint, pts[inside], way, c[inside])
                exit_near = _solver.nearest_on_region(region.footprint, np.ascontiguousarray(exit_pt))
                go = moving & (np.sum(exit_near.normal * way, axis=1) > 0)
                idx = np.flatnonzero(inside)[go]
                nrm[idx] = exit_near.normal[go]
                target[idx] = exit_near.boundary[go] + nrm[idx] * c[inside][go, None]
            normal[sel] = nrm
            rhs[sel] = np.sum(nrm * target, axis=1)
        return normal, rhs


def _path_tangents(state: _State, flat: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """(N,2) central-difference tangents of the paths at global vertices (one-sided at ends)."""
    owner = np.searchsorted(state.starts, vertices, side="right") - 1
    lo, hi = state.starts[owner], state.starts[owner + 1] - 1
    return flat[np.minimum(vertices + 1, hi)] - flat[np.maximum(vertices - 1, lo)]


def _centre(footprint) -> np.ndarray:
    return np.asarray(footprint.center) if footprint.is_circle else np.asarray(footprint.polygon).mean(axis=0)


def _exit(footprint, points: np.ndarray, way: np.ndarray, clearance: np.ndarray) -> np.ndarray:
    """Where rays from points along unit directions leave a convex footprint grown by clearance."""
    if footprint.is_circle:
        d = points - np.asarray(footprint.center)
        reach = footprint.radius + clearance
        b = np.sum(d * way, axis=1)
        s = -b + np.sqrt(np.maximum(b * b - np.sum(d * d, axis=1) + reach * reach, 0.0))
        return points + s[:, None] * way
    poly = np.asarray(footprint.polygon)
    hi = np.full(len(points), 2.0 * np.ptp(poly, axis=0).max() + 2.0 * clearance.max(initial=0.0)
                 + np.linalg.norm(points - poly.mean(axis=0), axis=1).max(initial=0.0))
    lo = np.zeros(len(points))
    for _ in range(48):   # the distance grows monotonically along a ray leaving a convex region
        mid = 0.5 * (lo + hi)
        d = _solver.region_signed_distance(footprint, np.ascontiguousarray(points + mid[:, None] * way))
        out = d >= clearance
        hi = np.where(out, mid, hi)
        lo = np.where(out, lo, mid)
    return points + hi[:, None] * way


class _Forward:
    """One-sided rows that keep walkers going their way: for a chord of ``chord_s`` seconds
    of an agent's path where the source moves faster than ``moving_m_s``, the edited chord's
    projection on the source chord's direction stays at least ``keep`` times the source
    chord's length, and the edited chord stays within ``cone_degrees`` of that direction (a
    push never sends a walker back the way it came, nor across its way: a projection alone
    lets a push far enough sideways pass for progress). Only the rows an iterate broke, or
    came within ``watch`` source chord lengths of breaking, are solved, kept from then on:
    held before they break, they cost no iteration of their own (on the bench's dense crowds
    of 1,000, 5 to 7 iterations instead of 8 to 10; the mean displacement grows by up to 1%).

    A crowd of 10,000 has millions of chords: each keeps its ends, direction and length and
    which of its rows are held; the rows' directions and bounds are worked out from those when
    needed, the forces are kept for the held rows only, and :meth:`watch` goes through the
    chords a block at a time (held as arrays of three rows per chord, they took 600 MB)."""

    #: Chords :meth:`watch` measures at once.
    BLOCK = 1 << 16

    def __init__(self, state: _State, keep: float = 0.5, chord_s: float = 0.25, moving_m_s: float = 0.2,
                 cone_degrees: float = 45.0, watch: float = 0.0):
        s, p = state.s, state.p
        starts = state.starts.astype(np.int64)
        counts = np.diff(starts)
        # Seconds per frame of each agent (the median interval; agents of one length at once).
        dt = np.zeros(len(counts))
        for count in np.unique(counts[counts >= 2]):
            group = np.flatnonzero(counts == count)
            times = np.stack([p.frame_times[a] for a in group])
            dt[group] = np.median(np.diff(times, axis=1), axis=1) / s.time_codes_per_second
        h = np.maximum(1, np.round(chord_s / np.maximum(dt, 1e-9))).astype(np.int64)
        # The chords of every agent longer than its chord: frames lo .. hi - h - 1.
        chords = np.where((counts >= 2) & (counts > h), counts - h, 0)
        owner = np.repeat(np.arange(len(counts)), chords)
        v = np.arange(int(chords.sum()), dtype=np.int64) - np.repeat(np.cumsum(chords) - chords, chords) + starts[:-1][owner]
        hv = h[owner]
        c = np.take(state.way, v + hv, axis=0) - np.take(state.way, v, axis=0)
        n = np.linalg.norm(c, axis=1)
        moving = np.flatnonzero(n > moving_m_s / s.meters_per_unit * hv * dt[owner])
        del owner
        index = np.int32 if len(state.rest) < np.iinfo(np.int32).max else np.int64
        self.v, self.u = np.take(v, moving).astype(index), np.take(v + hv, moving).astype(index)
        del v, hv
        self.length = np.take(n, moving)
        self.dx, self.dy = (np.take(c[:, k], moving) / self.length for k in range(2))
        del c, n, moving
        self.keep, self.watch_by = keep, watch
        self.sin, self.cos = np.sin(np.radians(cone_degrees)), np.cos(np.radians(cone_degrees))
        self.on = np.zeros((len(self.v), 3), bool)
        # The held rows (flat indices chord * 3 + row, ascending) and their forces.
        self._held_rows = np.zeros(0, dtype=np.int64)
        self._force, self._force1 = np.zeros(0), np.zeros(0)

    def _rows(self, chord: np.ndarray, row: np.ndarray | None = None) -> tuple:
        """(nx, ny, rhs) of the chords' rows: all three of each, (len, 3) each, or of row ``row``
        of each, (len,) each. Three rows per chord: d.c >= keep |c_source|, and the cone's two
        edges n.c >= 0 (n = sin d -+ cos across, across = (-d_y, d_x))."""
        dx, dy = self.dx[chord], self.dy[chord]
        sin, cos = self.sin, self.cos
        nx = np.stack([dx, sin * dx - cos * -dy, sin * dx + cos * -dy], axis=1)
        ny = np.stack([dy, sin * dy - cos * dx, sin * dy + cos * dx], axis=1)
        rhs = np.zeros((len(dx), 3))
        rhs[:, 0] = self.keep * self.length[chord]
        if row is None:
            return nx, ny, rhs
        at = np.arange(len(dx))
        return nx[at, row], ny[at, row], rhs[at, row]

    @property
    def normal(self) -> np.ndarray:
        """(C, 3, 2) the rows' directions."""
        nx, ny, _ = self._rows(np.arange(len(self.v)))
        return np.stack([nx, ny], axis=2)

    def watch(self, flat: np.ndarray) -> int:
        """Turns on the rows of the chords ``flat`` breaks or nearly breaks; returns how many
        broken ones were new."""
        fresh_count = 0
        sin, cos = self.sin, self.cos
        for lo in range(0, len(self.v), self.BLOCK):
            hi = min(lo + self.BLOCK, len(self.v))
            chord = np.take(flat, self.u[lo:hi], axis=0) - np.take(flat, self.v[lo:hi], axis=0)
            cx, cy = chord[:, 0], chord[:, 1]
            dx, dy = self.dx[lo:hi], self.dy[lo:hi]
            # A row is held from when its value drops below its bound and a slack.
            slack = self.watch_by * self.length[lo:hi]
            bound = self.keep * self.length[lo:hi]
            for k, (nx, ny) in enumerate(((dx, dy), (sin * dx - cos * -dy, sin * dy - cos * dx),
                                          (sin * dx + cos * -dy, sin * dy + cos * dx))):
                value = nx * cx + ny * cy
                on = self.on[lo:hi, k]
                rhs = bound if k == 0 else 0.0
                fresh = (value < rhs) & ~on
                fresh_count += int(np.count_nonzero(fresh))
                on |= fresh | (value < (bound + slack if k == 0 else slack))
        return fresh_count

    def add(self, rows: "_Rows") -> np.ndarray:
        held = np.flatnonzero(self.on.ravel())
        # Rows are only ever turned on: the ones held before keep their forces.
        force, force1 = np.zeros(len(held)), np.zeros(len(held))
        before = np.searchsorted(held, self._held_rows)
        force[before], force1[before] = self._force, self._force1
        self._held_rows, self._force, self._force1 = held, force, force1
        c, k = np.divmod(held, 3)
        nx, ny, rhs = self._rows(c, k)
        return rows.add(np.stack([nx, ny], axis=1), rhs, SEPARATION_SOFTNESS,
                        np.stack([self.u[c], self.v[c]], axis=1).astype(np.int64), np.tile([1.0, -1.0], (len(c), 1)),
                        at_least=True, force=force, force1=force1)

    def solved(self, force: np.ndarray, force1: np.ndarray) -> None:
        """The forces of the rows the last add() sent (no watch() in between)."""
        self._force, self._force1 = np.array(force, dtype=np.float64), np.array(force1, dtype=np.float64)


def _relinearize(state: _State, run: _Run):
    p, s = state.p, state.s
    solver = run.factor(state.rest, state.starts, state.rigid, s.anchor_weight, _still(s))
    flat = state.rest.copy()
    angles = np.zeros(len(p.rigid))
    cands = _Candidates(len(p.names))
    watched = _RegionCandidates()
    buffer = s.buffer_m / s.meters_per_unit
    fixed_force, fixed_force1 = np.zeros(0), np.zeros(0)
    forward = _Forward(state, s.forward_keep or 0.0, cone_degrees=s.forward_cone_degrees,
                       moving_m_s=0.2 if s.forward_keep is not None else np.inf, watch=s.forward_watch)
    for it in range(s.max_iterations + 1):
        # A result that sends someone back the way it came is solved again, with the chords
        # it broke held, even when nothing collides any more.
        run.pending = forward.watch(flat) > 0
        if run.observe(flat, it):
            break
        if it > 0 and _only_blocked(cands, run.found) and run.iterations[-1].region_samples == 0 \
                and not run.pending:
            break
        if it == s.stiffen_after:
            # Overlaps that outlast the first iterations are knots of many pushes; gentle
            # detours that reach far make them spread. Stiffer anchors keep the last pushes
            # local, so they converge.
            solver = run.factor(state.rest, state.starts, state.rigid, s.anchor_weight * s.stiffen, _still(s))
        # Watch every near miss: each becomes a one-sided row that pushes only when needed.
        if p.collide_agents:
            # A pair still overlapping where it was already held apart resists: it is held at
            # every sample of its intervals from now on, and a little further apart each time.
            near = run.found.near
            cands.resist(run.found)
            cands.add(*_expand(near, np.where(cands.resisting(near), 1, max(1, s.spread)), buffer))
            cands.prune(state, 2.0 * buffer)
        for r, h in enumerate(state.region_hits(flat, buffer)):
            if h is not None and len(h[0]):
                watched.add(r, h[0], p.regions[r].clearance[np.searchsorted(p.regions[r].agents, h[1])])
        # Linearise every kept constraint at the current result.
        ca, cb, ck = cands.split()
        cands.blocked = state.held(ca, cb, ck)
        need = _clearance(state, ca, cb)
        normal = cands.linearise(_separation_normals(state, ca, cb, ck), np.cos(np.radians(s.keep_degrees)))
        va, wa = state.sample_terms(ca, ck)
        vb, wb = state.sample_terms(cb, ck)
        rows = _Rows()
        state.fixed_rows(rows, fixed_force, fixed_force1)
        fixed = rows.count
        on = ~cands.blocked
        aim = need * (1.0 + s.overshoot * (1.0 + cands.resistance(ca, cb)))
        sep = rows.add(normal[on], aim[on], SEPARATION_SOFTNESS,
                       np.concatenate([va, vb], axis=1)[on], np.concatenate([wa, -wb], axis=1)[on],
                       at_least=True, force=cands.force[on], force1=cands.force1[on])
        rnormal, rrhs = watched.linearise(state, flat)
        reg = rows.add(rnormal, rrhs + watched.clearance * s.overshoot, SEPARATION_SOFTNESS,
                       watched.vertex[:, None], np.ones((len(watched.vertex), 1)), at_least=True,
                       force=watched.force, force1=watched.force1)
        ahead = forward.add(rows)
        # Small problems afford a converged Gauss-Seidel; big ones carry it on from iteration
        # to iteration (warm start) within a budget of row updates.
        sweeps = int(np.clip(s.sweep_budget / max(rows.count, 1), s.sweeps, 10 * s.sweeps))
        out = rows.solve(solver, tolerance=s.tolerance * float(np.min(need, initial=1.0)), max_sweeps=sweeps,
                         relaxation=s.relaxation, split_from=s.split_from_frames)
        run.solved(rows, out)
        force, force1 = out.forces, out.shape_forces
        fixed_force, fixed_force1 = force[:fixed], force1[:fixed]
        cands.force[on], cands.force1[on] = force[sep], force1[sep]
        watched.force, watched.force1 = force[reg], force1[reg]
        forward.solved(force[ahead], force1[ahead])
        flat = out.positions
        angles = out.rigid_angles
    return flat, angles


def _only_blocked(cands: _Candidates, found) -> bool:
    """True when every collision left involves a pair hard constraints hold together."""
    if len(found) == 0 or not cands.blocked.any():
        return False
    ca, cb, _ = cands.split()
    held = set(zip(ca[cands.blocked].tolist(), cb[cands.blocked].tolist()))
    return all((int(a), int(b)) in held for a, b in zip(found.agent_a, found.agent_b))


def _blocked(state: _State, found: collisions.Collisions) -> list[tuple[int, int, float]]:
    """Overlaps left where hard constraints hold both agents: (agent a, agent b, shot time)."""
    a, b, k = (found.agent_a.astype(np.int64), found.agent_b.astype(np.int64), found.deepest.astype(np.int64))
    held = state.held(a, b, k)
    return [(int(x), int(y), float(state.sampling.times[z])) for x, y, z in zip(a[held], b[held], k[held])]


def _link_held(state: _State) -> list[tuple[str, int, int, float, float, float]]:
    """(link name, agent a, agent b, first and last shot time, distance the link holds)."""
    t = state.sampling.times
    return [(state.p.links[i].name, a, b, float(t[first]), float(t[last]), float(np.linalg.norm(state.p.links[i].offset)))
            for i, a, b, first, last in state.link_holds]


# ---- waiting: delays through the time maps ---------------------------------------------------

#: Cosine of the angle between two walkers' directions beyond which they pass head-on or
#: overtake: waiting cannot part them, only a step aside can.
PASSING_COS = 0.7
#: Slowest fraction of the source pace a walker slows to while it takes up a delay.
SLOWEST_PACE = 0.5


def smooth_delay(times: np.ndarray, start: float, end: float, delay: float) -> np.ndarray:
    """(F,) the time map ``times`` with ``delay`` time codes taken up between shot times
    ``start`` and ``end`` (a smoothstep: no interval shrinks, every one after ``end`` is
    unchanged, the pace is continuous)."""
    return _solver.smooth_delay(np.ascontiguousarray(times, dtype=np.float64), float(start), float(end), float(delay))


@dataclass
class _Waits:
    """Per-agent delays found so far (time codes), and the collision intervals they left."""
    frame_times: list[np.ndarray]
    delay: np.ndarray
    span: tuple[float, float] | None = None
    rounds: int = 0
    #: (a, b), a < b: pairs a wait would part whose timing is fixed on both sides
    refused: set[tuple[int, int]] = field(default_factory=set)
    #: the agents sampled over ``span`` at the time maps ``frame_times`` (None: not sampled),
    #: the sampling the solve that follows would make again
    sampling: collisions.Sampling | None = None


def _velocities(positions: np.ndarray, k: np.ndarray, cols: np.ndarray) -> np.ndarray:
    k1 = np.minimum(k + 1, len(positions) - 1)
    k0 = np.maximum(k - 1, 0)
    return (positions[k1, cols] - positions[k0, cols]) / np.maximum(k1 - k0, 1)[:, None]


def _waits(problem: Problem, settings: Settings, fixed: np.ndarray) -> _Waits:
    """Delays the walker that arrives later at each crossing until the other has passed.

    Rounds of: detect at the current time maps; for every collision interval of two
    walkers whose directions cross take the one that reaches the crossing point of their
    lines later (of two walking the same way, the one behind), unless its timing is
    ``fixed``; find the least delay (in steps of ``wait_step_s`` from a step below the time
    the other needs to clear the crossing, at most what it may still add within
    ``max_wait_s``) after which the pair keeps its clearance over the encounter; take that delay
    up smoothly before the encounter, slowing to no less than ``SLOWEST_PACE``, and after the
    last frame whose moment is fixed (``Problem.waits_after``: a frame pinned in place plays
    when it did). Each agent takes up at most one delay per round (its earliest), so delays
    that create new encounters are seen by the next round. Collisions waiting
    cannot part (head-on, standing agents, no room) are left to the lateral solve; so are
    those neither agent may wait for, which ``refused`` lists.
    """
    fps = settings.time_codes_per_second
    names = list(range(len(problem.names)))
    times = [np.asarray(t, dtype=np.float64).copy() for t in problem.frame_times]
    delay = np.zeros(len(names))
    budget = settings.max_wait_s * fps
    out = _Waits(times, delay)
    if budget <= 0 or not problem.collide_agents or not times:
        return out
    step = max(settings.wait_step_s * fps, problem.sample_step)
    paths = {i: np.ascontiguousarray(g, dtype=np.float64) for i, g in enumerate(problem.paths)}
    source = [np.ascontiguousarray(t, dtype=np.float64) for t in problem.frame_times]
    # What plays after the last frame of the shot as it was (a delayed walker's last steps)
    # is not compared: nobody else walks there then.
    span = problem.span or (min(float(t[0]) for t in times), max(float(t[-1]) for t in times))
    out.span = span
    tried = _solver.WaitMemory()
    # The shot time of each agent's last pinned frame: no wait is taken up before it, so it stays.
    after = np.full(len(names), -1) if problem.waits_after is None else np.asarray(problem.waits_after)
    earliest = np.array([float(times[i][min(int(f), len(times[i]) - 1)]) if f >= 0 and len(times[i]) else -np.inf
                         for i, f in enumerate(after)])
    walking_paths = [paths[i] for i in names]
    sampling = collisions.sample(names, {i: t for i, t in enumerate(times)}, paths, problem.sample_step, span)
    out.sampling = sampling
    for rnd in range(settings.wait_rounds):
        found = collisions.detect(sampling, problem.radius, problem.height, problem.margin,
                                  report_distance=problem.margin)
        out.rounds = rnd
        if len(found) == 0:
            break
        pos, st = sampling.positions, sampling.times
        a, b, k = (found.agent_a.astype(np.int64), found.agent_b.astype(np.int64), found.deepest.astype(np.int64))
        va, vb = _velocities(pos, k, a), _velocities(pos, k, b)
        sa, sb = np.linalg.norm(va, axis=1), np.linalg.norm(vb, axis=1)
        walking = (sa > 1e-9) & (sb > 1e-9)
        cos = np.sum(va * vb, axis=1) / np.maximum(sa * sb, 1e-300)
        crossing = walking & (np.abs(cos) < PASSING_COS)
        # Time (in samples) each needs to reach the crossing point of the two lines.
        det = va[:, 0] * (-vb[:, 1]) - va[:, 1] * (-vb[:, 0])
        rel = pos[k, b] - pos[k, a]
        safe = np.where(np.abs(det) > 1e-300, det, 1.0)
        ta = (rel[:, 0] * (-vb[:, 1]) - rel[:, 1] * (-vb[:, 0])) / safe
        tb = (va[:, 0] * rel[:, 1] - va[:, 1] * rel[:, 0]) / safe
        later_a = ta >= tb
        # Walking the same way, the one behind waits for the one ahead (it would otherwise
        # catch up with a walker that waited in front of it).
        following = walking & (cos >= PASSING_COS)
        behind_a = np.sum((pos[k, b] - pos[k, a]) * (va + vb), axis=1) > 0.0
        later_a = np.where(following, behind_a, later_a)
        who = np.where(later_a, a, b)
        other = np.where(later_a, b, a)
        ok = (crossing | following) & ~fixed[who]
        stuck = (crossing | following) & fixed[a] & fixed[b]
        out.refused.update(zip(np.minimum(a, b)[stuck].tolist(), np.maximum(a, b)[stuck].tolist()))
        # First guess of each delay (time codes): crossing, from when the other leaves the
        # crossing point by the clearance to when the waiting one would come within it;
        # following, the time to fall back by the clearance missing between them.
        need = problem.radius[a] + problem.radius[b] + problem.margin
        sw, so = np.where(later_a, sa, sb), np.where(later_a, sb, sa)
        tw, to = np.where(later_a, ta, tb), np.where(later_a, tb, ta)
        cross_guess = (to + need / np.maximum(so, 1e-300)) - (tw - need / np.maximum(sw, 1e-300))
        gap = np.linalg.norm(pos[k, a] - pos[k, b], axis=1)
        guess = np.where(following, (need - gap) / np.maximum(sw, 1e-300), cross_guess) * problem.sample_step
        # The least delay of each walker (C++): in steps, from a step below the first guess
        # (rounded to steps) up to three steps above it, that parts it from the other over
        # their encounter and meets nobody new but walkers going its way; it starts after
        # the clip does and keeps the pace at or above SLOWEST_PACE of the source's.
        search = _solver.WaitSearch(positions=pos.reshape(-1, 2), times=st, radius=problem.radius.astype(np.float64),
                                    time_codes_per_second=fps, sample_step=problem.sample_step, step=step,
                                    margin=problem.margin * (1.0 + settings.overshoot), slowest_pace=SLOWEST_PACE,
                                    passing_cos=PASSING_COS, block=max(1, int(round(fps / problem.sample_step))))
        # The encounters in the order they begin, each walker waiting for the first it can (at
        # most once a round); a pair tried before, neither of which has waited since, fails
        # again and is passed over.
        order = np.argsort(found.first, kind="stable")
        order = order[ok[order]]
        taken = set()
        for w, found_delay in _solver.wait_round(
                search=search, walkers=who[order].astype(np.int32), others=other[order].astype(np.int32),
                firsts=found.first[order].astype(np.int32), lasts=found.last[order].astype(np.int32),
                guesses=guess[order].astype(np.float64), paths=walking_paths, times=times, source_times=source,
                budget=float(budget), step=float(step), delay=delay, tried=tried, earliest=earliest):
            times[w], delay[w] = found_delay.times, delay[w] + found_delay.delay
            taken.add(w)
        if not taken:
            break
        moved = np.array(sorted(taken), dtype=np.int64)   # only the agents that waited move in the sampling
        for w in moved:
            sampling.frames[:, w] = collisions.frames_at(times[w], st)
        collisions.Resampler(sampling, np.concatenate([[0], np.cumsum([len(paths[w]) for w in moved])]), moved)(
            np.concatenate([paths[w] for w in moved]))
    return out
