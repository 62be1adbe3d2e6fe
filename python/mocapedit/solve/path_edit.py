"""Builds and solves the path-editing problem of a component of agents (numpy + _solver).

A component is a set of agents tied together by relative constraints and groups; it is
one sparse two-step ARAP problem (``_solver.path_edit_*``, see
``solver/include/mocapedit/path_edit.h``) over every frame of every member, one vertex
per frame:

- each agent's path keeps its local shape (triangle terms) and its step lengths (edge
  terms), widening the local frame around frames that stand still;
- each stationary range moves rigidly, turned by the rotation the solve gives it;
- where an agent's whole path stays about one spot (``_solver.spot_weight``: a bounce, a dance,
  an idle's shuffle), soft terms keep each step as its source's turned by the body's turn (the
  heading's, below), so the wiggles move as a whole instead of each turning its own way
  (``SPOT_WEIGHT``); group members turn with their formation and take none;
- position constraints are handles, relative constraints links (hard ones eliminated,
  so they hold exactly);
- a group joins its members' paths at sampled shared times (every ``group_step`` time
  codes, and the last shared time: ``group_sample_times``): each member is linked to its
  nearest neighbours there (and clusters of members apart to each other), its position kept
  in their local path frames (step 1) and its distance to them kept (step 2), weighted by
  the group's stiffness (Kwon et al. 2008). Group members are solved on key frames only (the
  sampled times, constrained frames, stationary ranges, the ends); each frame between two
  keys follows them by their similarity, blended with the neighbouring keys' so that the
  path turns smoothly through a key (``_solver.expand_key_frames``); it keeps its shape and
  sway.

The constraints leave some motions free; these are resolved so that an edit moves no more
than it must:

- a body (an agent, or a whole group) held at fewer than two frames moves by one
  translation, keeping its heading: one handle drags it along, a relative constraint on
  an otherwise free agent carries it with its partner;
- a component with no position constraint at all keeps its mean position: it is solved
  with one link end pinned, then shifted back so the ends of its links move by zero on
  average (the two sides of a handshake each walk half way);
- an agent whose turn and scale the constraints still leave free (a chain of agents
  linked end to end) keeps the direction and distance between the two farthest frames it
  is held at, by a weak soft term.

Headings: an edited agent's body turns, at each frame, by the rotation the edit applies to
its path around that frame, on top of its source heading (``trajectory.deformation_turns``),
never by the tangent of the edited path; a stationary range turns by its own rigid rotation.

Relative constraints in the target's space turn with the target: the target's heading at
targetFrame is that of its edited path, found by re-solving (no refactoring) until it
stops changing.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import chain

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import shape, trajectory
from mocapedit.geometry.components import UnionFind

HARD = np.inf
#: Raised by a solve whose hard constraints cannot all hold; ``constraints`` names them, as
#: (kind, index) pairs ('handle', 'link', 'rigid'), and ``mismatch`` says by how much they miss.
ContradictionError = _solver.ContradictionError
#: Weight of the soft terms that keep free agents' turn and scale (see ComponentProblem).
GAUGE_WEIGHT = 0.01
#: Target-space links: re-solve until the target headings change less than this (radians).
HEADING_TOLERANCE = 1e-12
MAX_HEADING_ITERATIONS = 30
#: Weight, against the shape terms, of the terms that keep the steps of a path about one spot
#: as its source's, turned only by the body's turn: a boxer's bounce, a dance or an idle's
#: shuffle moved by an edit slides as a whole and keeps its wiggles, where the shape terms alone
#: turned each wiggle its own way, unfolding the tangle into a path that swings about. Scaled by
#: ``_solver.spot_weight`` (1 for a path about one spot, 0 for any path with a frame sure of its turn).
SPOT_WEIGHT = 10.0
#: Re-solves that bring the turn of those terms to the body's (the turn of the edited path).
SPOT_ITERATIONS = 3
#: Radians: the turn of those terms has settled when it changes less than this.
SPOT_TOLERANCE = 1e-3
#: Metres: an agent's handles whose source positions all lie closer together than this say
#: nothing of its turn. Their direction is its sway's (an idle's first and last frames are a
#: few centimetres apart): the turn from it onto the handles' drag turned a whole idle 90 or
#: 180 degrees. Such an agent drifts: its spot terms hold every step to its source step,
#: unturned (SPOT_WEIGHT), so it slides from one handle's displacement to the next.
DRIFT_SPREAD_M = 0.5
#: Weight, against the other shape terms' 1, of those that span a cut in an agent's rest path
#: (a step longer than its ``turn_max_step``: a rest pose left in a clip's first frame, a
#: teleport). The jump is no motion to keep the shape of: held rigid in the take's local frame,
#: a 3.6 m jump swung the rest frame round as an edit turned the take, and a handle on the rest
#: frame then dragged the take's start, squeezing its first steps to two thirds of their length.
#: Weak, the terms still carry a free rest frame along with its take (they alone place it), and a
#: held one pulls on the take by a thousandth of a millimetre per metre it is off.
CUT_WEIGHT = 1e-6
#: Weight, against 1, of the shape and spot terms of a take about one spot at the frames where
#: its source has no foot planted (``AgentInput.stance``: the flight of a jump or a hop). Moved by
#: an edit, such a take travels in the air, where no foot slides, and keeps its own motion on the
#: ground: a generated stand with a hop, its end dragged 60 cm, slid its feet 15 cm/s before foot
#: locking with the drag spread evenly over its 4 s, and 1.4 cm/s so; a CMU jump into a balance
#: bent 1 m, 49 cm/s (18.4 locked, against its source's 9.2), and 31 (13.2).
AIRBORNE_WEIGHT = 0.01
#: Metres: the local frames of the shape terms along an agent's path are at least this long
#: (the frame of a frame that stands still or sways widens to the walk around it), in path
#: editing and in collision avoidance alike (solver/src/energy/two_step_energy.h).
MIN_BASELINE_M = 0.01


@dataclass
class AgentInput:
    """One agent's rest path and tags, in the solve's vertex order."""
    path: str
    rest: np.ndarray                      # (F,2) rest ground path (source, or remapped on a curve)
    source: np.ndarray                    # (F,2) source ground path
    source_heading: np.ndarray            # (F,) source headings (trajectory.extract)
    stationary: list[tuple[int, int]]     # inclusive frame ranges, sorted, disjoint
    stationary_refs: list[str] = field(default_factory=list)  # who each range comes from
    rest_turn: np.ndarray | None = None   # (R,) rotation of each range from source to rest
    sample_times: np.ndarray | None = None  # (F,) shot time of each frame (groups)
    # The windows of the edit's turn at this agent's own sample rate (turn_settings); None: the
    # Settings' (a clip sampled at the stage's rate).
    turn: dict | None = None
    # (F,) weight of the shape terms at each frame of a take about one spot, in (0, 1]: 1 where a
    # foot is planted in the source, less where none is (:func:`stance_weights`); None: 1 everywhere.
    # :func:`may_hold_spot` says which agents may use it.
    stance: np.ndarray | None = None

    @property
    def frames(self) -> int:
        return int(self.rest.shape[0])


@dataclass
class Handle:
    agent: str
    frame: int
    position: np.ndarray                  # (2,) ground
    weight: float                         # HARD or a soft weight
    ref: str                              # prim path, for messages


@dataclass
class Link:
    agent: str
    frame: int
    target: str
    target_frame: int
    offset: np.ndarray                    # (2,) ground, agent minus target
    space: str                            # "world" | "target"
    weight: float
    ref: str


@dataclass
class Group:
    members: list[str]
    stiffness: float
    ref: str


def group_sample_times(start: float, end: float, step: float) -> np.ndarray:
    """Times at which a group's mesh joins its members, over their shared range [start, end]:
    every ``step`` from ``start``, and ``end`` itself, so that the formation holds up to the
    end of the shared range. ``end`` replaces the last regular time when it would follow it
    by less than half a step. Empty when the range is empty."""
    if not (np.isfinite(step) and step > 0) or not (np.isfinite(start) and np.isfinite(end)):
        raise ValueError(f"group sampling needs a finite range and a positive step, got [{start}, {end}] "
                         f"every {step}")
    if end < start:
        return np.zeros(0)
    times = np.arange(start, end + 1e-9, step)
    if end - times[-1] > 1e-6:
        if len(times) > 1 and end - times[-1] < 0.5 * step:
            times[-1] = end
        else:
            times = np.append(times, end)
    return times


@dataclass
class Settings:
    min_baseline: float                   # stage units: shortest local frame of a triangle
    rigid_min_extent: float               # stage units: smaller stationary ranges turn with their ends
    still: float                          # stage units: tangent steps below this stand still
    turn_window: int = 2                  # frames: half-width of the windows of the edit's turn
    turn_min_travel: float = 0.0          # stage units: less source travel in a window is slow
    turn_max_step: float = 0.0            # stage units: a longer source step is a cut (0: none)
    drift_spread: float = 0.0             # stage units: closer handles cannot turn an agent (DRIFT_SPREAD_M)
    group_step: float = 12.0              # time codes between the sampled times of a group mesh
    group_neighbours: int = 3


def turn_args(a: AgentInput, settings: "Settings") -> tuple[int, float, float]:
    """(window, min_travel, max_step) of :func:`trajectory.deformation_turns` for agent ``a``:
    its own (``AgentInput.turn``), else the settings'."""
    t = a.turn or {"turn_window": settings.turn_window, "turn_min_travel": settings.turn_min_travel,
                   "turn_max_step": settings.turn_max_step}
    return int(t["turn_window"]), float(t["turn_min_travel"]), float(t["turn_max_step"])


def spot_weight(a: AgentInput, settings: "Settings | None" = None) -> float:
    """How far agent ``a``'s path stays about one spot (``_solver.spot_weight``): the weight of
    its spot terms (``SPOT_WEIGHT``). 0 for an agent with stationary ranges (they turn it) or laid
    along a path curve (its rest path is the artist's shape). ``settings``: the turn windows, when
    ``a.turn`` does not give them."""
    if a.stationary or a.frames < 2 or a.rest_turn is not None:
        return 0.0
    window, min_travel, max_step = turn_args(a, settings)
    return _solver.spot_weight(source=a.source, window=window, min_travel=min_travel, max_step=max_step)


def _spread(points: np.ndarray) -> float:
    """The largest distance between two of (N,2) ``points``."""
    return float(np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1).max())


def stance_weights(planted: np.ndarray) -> np.ndarray | None:
    """(F,) ``AgentInput.stance`` from (F,) bool frames where a foot is planted in the source:
    1 there, AIRBORNE_WEIGHT elsewhere; None where that tells nothing, every frame planted or none
    (a take whose feet were never found on the ground is not in the air throughout: weighed so,
    its shape would count for less against every other term of its component)."""
    planted = np.asarray(planted, dtype=bool)
    if planted.all() or not planted.any():
        return None
    return np.where(planted, 1.0, AIRBORNE_WEIGHT)


def may_hold_spot(a: AgentInput, frames: list[int], settings: Settings) -> bool:
    """Whether agent ``a``, held at ``frames`` by its handles, may get spot terms (and so use
    ``AgentInput.stance``): its path stays about one spot (:func:`spot_weight`), or its handles
    lie closer together than ``Settings.drift_spread`` (a drift, see ``DRIFT_SPREAD_M``). A cheap
    superset of the agents :class:`ComponentProblem` gives spot terms to."""
    if a.stationary or a.rest_turn is not None:
        return False
    if len(set(frames)) >= 2 and settings.drift_spread > 0 and \
            _spread(a.rest[np.unique(frames)]) < settings.drift_spread:
        return True
    return spot_weight(a, settings) > 0.0


def turn_settings(fps: float, meters_per_unit: float) -> dict:
    """``turn_window``, ``turn_min_travel`` and ``turn_max_step`` of :class:`Settings` for a clip at
    ``fps``: the source is slow where it walks slower than ``trajectory.TURN_MIN_SPEED_M`` over the
    window, and a step faster than ``trajectory.CUT_SPEED_M`` is a cut."""
    h = trajectory.turn_window(fps)
    return {"turn_window": h, "turn_min_travel": trajectory.TURN_MIN_SPEED_M / meters_per_unit * 2 * h / fps,
            "turn_max_step": trajectory.CUT_SPEED_M / meters_per_unit / fps,
            "drift_spread": DRIFT_SPREAD_M / meters_per_unit}


@dataclass
class AgentResult:
    ground: np.ndarray                    # (F,2)
    heading: np.ndarray                   # (F,)
    range_turn: np.ndarray                # (R,) total turn of each stationary range from source
    translate_only: bool = False


@dataclass
class ComponentResult:
    agents: dict[str, AgentResult]
    solver: str                           # e.g. "LDLT", "SPQR (ill-conditioned)", "rigid"
    notes: list[str]
    link_offsets: np.ndarray              # (L,2) world offsets the links were solved with
    step1: _solver.StepInfo | None = None  # how each step was solved
    step2: _solver.StepInfo | None = None


class ComponentProblem:
    """The solver problem of one component. Build once; ``solve`` any number of times.

    Agents are sorted by path and concatenated, one vertex per frame (per key frame for
    group members). The terms come from ``_solver`` in one call per kind rather than one
    per agent or sampled time (``solver/include/mocapedit/path_terms.h``), and the
    freedom analysis asks the solver only when the hard handles do not pin every body down."""

    def __init__(self, agents: list[AgentInput], handles: list[Handle], links: list[Link],
                 groups: list[Group], settings: Settings, precompute_responses: bool = False):
        self.full = {a.path: a for a in agents}
        self.handles, self.links, self.groups = list(handles), list(links), list(groups)
        self.settings = settings
        self.notes: list[str] = []
        self.order = sorted(self.full)
        self.index = {p: i for i, p in enumerate(self.order)}
        self._inputs = [self.full[p] for p in self.order]
        fo = [0]
        for a in self._inputs:
            fo.append(fo[-1] + a.frames)
        self._full_offset = fo
        if len(self._inputs) == 1:
            self._rest_full = np.ascontiguousarray(self._inputs[0].rest, dtype=np.float64)
        else:
            self._rest_full = np.concatenate([a.rest for a in self._inputs], dtype=np.float64)
        # cut_into[f]: the rest step into frame f is a cut (longer than the agent's turn_max_step).
        self._cut_into = np.zeros(len(self._rest_full), dtype=np.int64)
        for i, a in enumerate(self._inputs):
            max_step = turn_args(a, settings)[2]
            if max_step > 0 and a.frames > 1:
                steps = np.diff(self._rest_full[fo[i]:fo[i + 1]], axis=0)
                self._cut_into[fo[i] + 1:fo[i + 1]] = np.hypot(steps[:, 0], steps[:, 1]) > max_step
        # Group members are solved on key frames; the frames between follow (see _keys).
        self._keys()
        self._build_terms()
        self._resolve_freedom()
        self._spot_links()
        self._needs_headings = any(k.space == "target" for k in self.links)
        self._rest_headings: dict[int, np.ndarray] = {}
        self._source_full: np.ndarray | None = None   # every agent's source path, concatenated
        try:
            self.data = _solver.path_edit_precompute(
                rest=self.rest, triangles=self.triangles, triangle_weights=self.triangle_weights, edges=self.edges,
                edge_weights=self.edge_weights, rigid=self.rigid, handles=self.handle_vertex,
                handle_weights=self.handle_weight, links=self.link_vertex, link_weights=self.link_weight,
                rigid_min_extent=settings.rigid_min_extent, precompute_responses=precompute_responses,
                vertex_times=self._vertex_times())
        except ContradictionError as exc:
            exc.problem = self   # its handle, link and rigid references name the constraints
            raise

    # ---- key frames --------------------------------------------------------------------

    def _keys(self) -> None:
        """Key frames of each group member: the group's sampled shared times, constrained
        frames, stationary ranges (and the frames around them), the ends, and every frame of
        a stretch too short to interpolate across. Other agents keep every frame.

        Kwon et al. build the group mesh on sampled frames too; here the frames between two
        keys follow them as one similarity, so they keep their shape and their sway.

        Sets ``rest``/``offset`` (the solve's vertices) and, when there are members, the maps
        between frames and vertices (``keys`` gives each member's key frames)."""
        s, fo = self.settings, self._full_offset
        self._samples: dict[int, np.ndarray] = {}   # group -> (M,T) frame of each member, -1 none
        self._sel = None                             # (V,) frame of each solve vertex
        self._red_stationary = [a.stationary for a in self._inputs]
        # Groups that join their members: at least two of them present, sharing some time.
        active = []
        for n, g in enumerate(self.groups):
            ids = [self.index[m] for m in g.members if m in self.index]
            if g.stiffness <= 0 or len(ids) < 2:
                continue
            times = [self._inputs[i].sample_times for i in ids]
            start, end = max(float(t[0]) for t in times), min(float(t[-1]) for t in times)
            if end >= start:
                active.append((n, ids, times, start, end))
        members = sorted({i for _, ids, *_ in active for i in ids})
        self._members = members
        if not members:
            self.rest = self._rest_full
            self._red_offset = fo
            self.offset = np.array(fo, dtype=np.int64)
            return
        is_member = np.zeros(len(self._inputs), np.int32)
        is_member[members] = 1
        forced = []
        for n, ids, times, start, end in active:
            frames = _solver.group_sample_frames(
                np.concatenate(times, dtype=np.float64),
                np.cumsum([0] + [len(t) for t in times], dtype=np.int32),
                group_sample_times(start, end, s.group_step))
            vert = np.where(frames >= 0, frames + np.array([fo[i] for i in ids])[:, None], -1)
            forced.append(vert[vert >= 0])
            self._samples[n] = vert
        marks = []
        for i in members:
            marks += (fo[i], fo[i + 1] - 1)
            for f in np.flatnonzero(self._cut_into[fo[i]:fo[i + 1]]):   # both sides of a cut
                marks += (fo[i] + int(f) - 1, fo[i] + int(f))
            for first, last in self._inputs[i].stationary:
                marks.extend(range(fo[i] + max(first - 1, 0), fo[i] + min(last + 2, fo[i + 1] - fo[i])))
        for h in self.handles:
            if h.weight > 0 and is_member[self.index[h.agent]]:
                marks.append(fo[self.index[h.agent]] + h.frame)
        for k in self.links:
            if k.weight > 0:
                for agent, frame in ((k.agent, k.frame), (k.target, k.target_frame)):
                    if is_member[self.index[agent]]:
                        marks.append(fo[self.index[agent]] + frame)
        forced.append(np.array(marks, dtype=np.int64))
        self._sel, self._before = _solver.key_frames(
            rest=self._rest_full, offsets=np.array(fo, dtype=np.int32), keyed=is_member,
            forced=np.concatenate(forced).astype(np.int32), min_baseline=s.min_baseline)
        self.rest = self._rest_full[self._sel]
        before = self._before
        ro = [int(before[f]) for f in fo[:-1]] + [len(self._sel)]
        self._red_offset = ro
        self.offset = np.array(ro, dtype=np.int64)
        for i in members:
            self._red_stationary[i] = [(int(before[fo[i] + f]) - ro[i], int(before[fo[i] + l]) - ro[i])
                                       for f, l in self._inputs[i].stationary]

    def _vertex_times(self) -> np.ndarray | None:
        """Shot time of each solve vertex when the component has group members (frame
        numbers for agents without shot times), else None. The solver orders a large
        group's factorization by position and time (mocapedit/nested_dissection.h)."""
        if self._sel is None:
            return None
        full = np.concatenate([np.asarray(a.sample_times, dtype=np.float64) if a.sample_times is not None
                               else np.arange(a.frames, dtype=np.float64) for a in self._inputs])
        return full[self._sel]

    @property
    def keys(self) -> dict[str, np.ndarray]:
        """Group member path -> its key frames (the frames it is solved on)."""
        fo, ro = self._full_offset, self._red_offset
        return {self.order[i]: self._sel[ro[i]:ro[i + 1]] - fo[i] for i in self._members}

    def _expand(self, positions: np.ndarray) -> np.ndarray:
        """(F,2) paths of every agent, concatenated, from the solve's vertices: each frame
        between two keys is carried by the similarity that takes the keys' rest positions
        to their new ones."""
        if self._sel is None:
            return positions.copy()
        return _solver.expand_key_frames(self._rest_full, self._sel, np.ascontiguousarray(positions))

    # ---- structure ---------------------------------------------------------------------

    def vertex(self, agent: str, frame: int) -> int:
        i = self.index[agent]
        if self._sel is not None:
            return int(self._before[self._full_offset[i] + int(frame)])
        return self._red_offset[i] + int(frame)

    def _build_terms(self) -> None:
        s = self.settings
        self._offsets32 = np.array(self._red_offset, dtype=np.int32)
        self._partner = None   # frame partners, for group triangles
        tri, edg = _solver.component_chain_terms(self.rest, self._offsets32, s.min_baseline)
        tw, ew = np.empty(len(tri)), np.empty(len(edg))
        tw.fill(1.0), ew.fill(1.0)   # as np.ones, without its Python-level wrapper
        cuts = self._cuts_before()
        if cuts is not None:
            tw[cuts[tri.max(axis=1)] > cuts[tri.min(axis=1)]] = CUT_WEIGHT
            ew[cuts[edg.max(axis=1)] > cuts[edg.min(axis=1)]] = CUT_WEIGHT
        self._chain_terms = (len(tri), len(edg))   # the chain terms come first
        tri, edg, tw, ew = [tri], [edg], [tw], [ew]
        for n, g in enumerate(self.groups):
            t, e, w = self._group_terms(n, g)
            tri.append(t), edg.append(e)
            tw.append(np.full(len(t), w)), ew.append(np.full(len(e), w))
        if len(tri) == 1:
            self.triangles, self.edges, self.triangle_weights, self.edge_weights = tri[0], edg[0], tw[0], ew[0]
        else:
            self.triangles = np.concatenate(tri).astype(np.int32, copy=False)
            self.edges = np.concatenate(edg).astype(np.int32, copy=False)
            self.triangle_weights = np.concatenate(tw)
            self.edge_weights = np.concatenate(ew)
        # Handles and links, in input order (the solver reports contradictions by index).
        self._hv = [self.vertex(h.agent, h.frame) for h in self.handles]
        self._lv = [(self.vertex(k.agent, k.frame), self.vertex(k.target, k.target_frame)) for k in self.links]
        self.handle_vertex = np.array(self._hv, dtype=np.int32)
        self.handle_weight = np.array([h.weight for h in self.handles], dtype=np.float64)
        self.handle_refs = [h.ref for h in self.handles]
        if self.links:
            self.link_vertex = np.array(self._lv, dtype=np.int32)
            self.link_weight = np.array([k.weight for k in self.links], dtype=np.float64)
        else:
            self.link_vertex, self.link_weight = np.zeros((0, 2), np.int32), np.zeros(0)
        self.link_refs = [k.ref for k in self.links]
        self.extra_links: list[tuple[int, int, np.ndarray]] = []   # gauge terms: (a, b, offset)
        self.extra_handle_positions: list[np.ndarray] = []          # gauge pins

    def _cuts_before(self) -> np.ndarray | None:
        """(V,) per solve vertex, how many cuts (``_cut_into``) come before it in the component's
        concatenated rest paths; None without any. A term whose vertices have different counts
        spans a cut."""
        if not self._cut_into.any():
            return None
        before = np.cumsum(self._cut_into)
        return before if self._sel is None else before[self._sel]

    def _group_terms(self, n: int, g: Group):
        """Triangles and edges joining the members of a group at every sampled shared time:
        each member to its nearest neighbours there, its position in their local path frame
        (step 1) and its distance to them (step 2)."""
        count = sum(1 for m in g.members if m in self.index)
        if g.stiffness <= 0 or count < 2 or n not in self._samples:
            return np.zeros((0, 3), np.int32), np.zeros((0, 2), np.int32), 0.0
        vert = self._samples[n]
        vert = self._before[vert[:, (vert >= 0).all(axis=0)]]   # their solve vertices
        if self._partner is None:
            self._partner = _solver.frame_partners(self.rest, self._offsets32, self.settings.min_baseline)
        k = min(self.settings.group_neighbours, count - 1)
        tri, edg = _solver.group_mesh_terms(self.rest, vert, k, self._partner)
        return tri, edg, g.stiffness

    # ---- the freedom the constraints leave -------------------------------------------

    def _bodies(self) -> list[list[int]]:
        """Agent indices of each body: a group whose mesh joins its members (they share some
        time) makes them one, an agent is its own."""
        if not self._samples:
            return [[i] for i in range(len(self.order))]
        joined = UnionFind(range(len(self.order)))
        for n, g in enumerate(self.groups):
            ids = [self.index[m] for m in g.members if m in self.index]
            if n in self._samples:
                for k in ids[1:]:
                    joined.union(ids[0], k)
        return [sorted(v) for _, v in sorted(joined.sets(range(len(self.order))).items())]

    def _places(self, verts) -> int:
        """How many distinct rest positions the vertices have."""
        if len(verts) < 2:
            return len(verts)
        at = self.rest.item
        return len({(at(v, 0), at(v, 1)) for v in verts})

    def _resolve_freedom(self) -> None:
        bodies, index = self._bodies(), self.index
        self._centre = None
        if len(bodies) == len(self.order):   # every agent its own body, in order
            self._body_of = body_of = list(range(len(bodies)))
        else:
            self._body_of = body_of = [0] * len(self.order)
            for b, body in enumerate(bodies):
                for i in body:
                    body_of[i] = b
        # Anchors: the vertices each body is held at by a handle or a link; by a hard handle.
        held, hard = [set() for _ in bodies], [set() for _ in bodies]
        handled = False
        for h, v in zip(self.handles, self._hv):
            if h.weight > 0:
                handled = True
                b = body_of[index[h.agent]]
                held[b].add(v)
                if h.weight == HARD:
                    hard[b].add(v)
        for k, (a, b) in zip(self.links, self._lv):
            if k.weight > 0:
                held[body_of[index[k.agent]]].add(a)
                held[body_of[index[k.target]]].add(b)
        anchors = [sorted(x) for x in held]
        places = self._count_places(anchors)
        ro = self._red_offset
        # A body nothing holds (a group member whose group joins nothing, its members sharing
        # no time) is not edited: it stays where it is.
        for k, body in enumerate(bodies):
            if not anchors[k]:
                v = ro[body[0]]
                self._append_handle(v, self.rest[v], HARD, None)
                held[k].add(v)
                hard[k].add(v)
                anchors[k], places[k] = [v], 1
        self.translate_only = set()
        self.rigid, self.rigid_refs = [], []
        for body, anchor, n in zip(bodies, anchors, places):
            if n < 2:
                self.translate_only.update(body)
                self.rigid.append((list(chain.from_iterable(range(ro[i], ro[i + 1]) for i in body)), "translate"))
                self.rigid_refs.append(("body", [self.order[i] for i in body]))
        for i in range(len(self.order)):
            if i in self.translate_only:
                continue
            for r, (first, last) in enumerate(self._red_stationary[i]):
                self.rigid.append((list(range(first + ro[i], last + 1 + ro[i])), "rotate"))
                self.rigid_refs.append(("stationary", self.order[i], r))
        # No position constraint: pin one link end; the solve is shifted back afterwards.
        self.pinned = None
        if not handled and self.links:
            self.pinned = self._lv[0][0]
            self._append_handle(self.pinned, self.rest[self.pinned], HARD, None)
        kernel = set() if self._pinned_down(held, hard, places) else self._similarity_kernel(bodies)
        if kernel:
            gauged = [k for k, (body, anchor) in enumerate(zip(bodies, anchors))
                      if len(anchor) >= 2 and any(i in kernel for i in body)]
            ends = self._farthest_anchors([anchors[k] for k in gauged])
            if len(ends):
                offsets = self.rest[ends[:, 0]] - self.rest[ends[:, 1]]
                self.extra_links = [(a, b, o) for (a, b), o in zip(ends.tolist(), offsets)]
            if self.extra_links:
                self.link_vertex = np.concatenate([self.link_vertex,
                                                   np.array([(a, b) for a, b, _ in self.extra_links], np.int32)])
                self.link_weight = np.append(self.link_weight, np.full(len(self.extra_links), GAUGE_WEIGHT))
                self.link_refs.extend([None] * len(self.extra_links))
                self.notes.append("the constraints leave some agents free to turn or scale: each keeps, as far "
                                  "as it can, the direction and distance between the farthest frames it is held at")
            if self._similarity_kernel(bodies):
                self.notes.append("the constraints leave some agents free to move; add a position constraint")

    def _spot_links(self) -> None:
        """Soft links between consecutive frames of each agent whose path stays about one spot
        (``SPOT_WEIGHT``): link (f + 1, f) keeps the source step from f to f + 1, turned by the
        body's turn there (``_spot_turn``, settled by :meth:`solve`). Not on group members (they
        turn with their formation), agents moved by one translation, laid on a path curve, or with
        stationary ranges (which turn them), or cuts. Sets ``_spot``: per agent with any, its index, its
        links' first frames and source steps; None without any."""
        self._spot: list[tuple[int, np.ndarray, np.ndarray]] | None = None
        self._spot_turn: dict[int, np.ndarray] = {}
        self._drift = self._drifting()
        members = set(self._members)
        found, verts, weights = [], [], []
        for i, a in enumerate(self._inputs):
            if i in self.translate_only or i in members:
                continue
            weight = 1.0 if i in self._drift else spot_weight(a, self.settings)
            if weight <= 0.0:
                continue
            max_step = turn_args(a, self.settings)[2]
            keep = np.ones(a.frames - 1, dtype=bool)
            step = np.diff(a.source, axis=0)
            if max_step > 0:
                keep &= np.einsum("ij,ij->i", step, step) <= max_step * max_step
            frames = np.flatnonzero(keep)
            if not len(frames):
                continue
            found.append((i, frames, np.ascontiguousarray(step[frames])))
            v = self._red_offset[i] + frames
            verts.append(np.stack([v + 1, v], axis=1))
            w = np.full(len(frames), SPOT_WEIGHT * weight)
            if a.stance is not None:
                w *= np.minimum(a.stance[frames], a.stance[frames + 1])
            weights.append(w)
        if not found:
            return
        self._weigh_airborne([i for i, _, _ in found])
        self._spot = found
        self.link_vertex = np.concatenate([self.link_vertex.reshape(-1, 2)] + verts).astype(np.int32)
        self.link_weight = np.concatenate([self.link_weight] + weights)
        self.link_refs.extend([None] * sum(len(f) for _, f, _ in found))

    def _weigh_airborne(self, agents: list[int]) -> None:
        """The chain shape terms of these agents (takes about one spot) weigh their least
        ``AgentInput.stance`` over their vertices."""
        stiff = None
        for i in agents:
            stance = self._inputs[i].stance
            if stance is None or (stance == 1.0).all():
                continue
            if stiff is None:
                stiff = np.ones(len(self.rest))
            stiff[self._red_offset[i]:self._red_offset[i + 1]] = stance
        if stiff is None:
            return
        nt, ne = self._chain_terms
        self.triangle_weights[:nt] *= stiff[self.triangles[:nt]].min(axis=1)
        self.edge_weights[:ne] *= stiff[self.edges[:ne]].min(axis=1)

    def _drifting(self) -> set[int]:
        """The agents whose handles cannot turn them (``DRIFT_SPREAD_M``): held at two places or
        more, all closer together in the source than ``Settings.drift_spread``; alone in their
        body (no group, no relative constraint), without stationary ranges or a path curve."""
        if self.settings.drift_spread <= 0:
            return set()
        tied = set(self._members) | {self.index[k.agent] for k in self.links} | \
            {self.index[k.target] for k in self.links}
        held: dict[int, list[int]] = {}
        for h, v in zip(self.handles, self._hv):
            if h.weight > 0:
                held.setdefault(self.index[h.agent], []).append(v)
        out = set()
        for i, verts in held.items():
            a = self._inputs[i]
            if i in self.translate_only or i in tied or a.stationary or a.rest_turn is not None:
                continue
            p = self.rest[np.unique(verts)]
            if len(p) >= 2 and _spread(p) < self.settings.drift_spread:
                out.add(i)
        return out

    def _spot_offsets(self) -> list[np.ndarray]:
        """The offsets of the spot links: each source step turned by the mean of the body's turn
        at its two frames."""
        out = []
        for i, frames, step in self._spot:
            turn = self._spot_turn.get(i)
            if turn is None:
                out.append(step)
                continue
            t = 0.5 * (turn[frames] + turn[frames + 1])
            c, s = np.cos(t), np.sin(t)
            out.append(np.stack([c * step[:, 0] - s * step[:, 1], s * step[:, 0] + c * step[:, 1]], axis=1))
        return out

    def _start_spot_turn(self, hp: np.ndarray) -> None:
        """The spot links' turn before the first solve: the handles' rotation when one rigid
        motion of the rest path meets them all (the solve is then that motion), else none."""
        self._spot_turn = {}
        w = self.handle_weight > 0
        z, p = self.rest[self.handle_vertex[w]], hp[w]
        if len(z) < 2:
            return
        z, p = z - z.mean(axis=0), p - p.mean(axis=0)
        zc, pc = z[:, 0] + 1j * z[:, 1], p[:, 0] + 1j * p[:, 1]
        cross = np.sum(np.conj(zc) * pc)
        if abs(cross) == 0:
            return
        rot = cross / abs(cross)
        scale = max(np.abs(zc).max(), np.abs(pc).max(), 1e-300)
        if np.abs(rot * zc - pc).max() <= 1e-9 * scale and rot != 1:
            angle = float(np.angle(rot))
            self._spot_turn = {i: np.full(self._inputs[i].frames, angle) for i, _, _ in self._spot}

    def _settle_spot(self, result, hp: np.ndarray, offsets: np.ndarray):
        """Re-solves until the spot links' turn is the body's turn on the edited path."""
        agents = [i for i, _, _ in self._spot if i not in self._drift]   # drifting ones keep their steps unturned
        if not agents:
            return result, offsets
        for _ in range(SPOT_ITERATIONS):
            if result.rigid_motion:
                break
            ground, turn_of = self._ground(result)
            headings = self._headings(ground, result, {i: self._turn(i, result, turn_of) for i in agents})
            change = 0.0
            for i in agents:
                turn = headings[i] - np.asarray(self._inputs[i].source_heading, dtype=np.float64)
                old = self._spot_turn.get(i)
                change = max(change, float(np.abs(turn - (0.0 if old is None else old)).max(initial=0.0)))
                self._spot_turn[i] = turn
            if change <= SPOT_TOLERANCE:
                break
            offsets = self._link_offsets(None)
            result = _solver.path_edit_solve(self.data, hp, offsets)
        return result, offsets

    def _count_places(self, sets: list[list[int]]) -> list[int]:
        """How many distinct rest positions each list of vertices has."""
        many = [k for k, verts in enumerate(sets) if len(verts) > 1]
        if len(many) < 8:
            return [self._places(verts) for verts in sets]
        out = [len(verts) for verts in sets]
        sizes = [len(sets[k]) for k in many]
        owner = np.repeat(np.arange(len(many)), sizes)
        pts = self.rest[np.fromiter(chain.from_iterable(sets[k] for k in many), np.int64, sum(sizes))]
        order = np.lexsort((pts[:, 1], pts[:, 0], owner))
        owner, pts = owner[order], pts[order]
        new = np.ones(len(owner), bool)
        new[1:] = (owner[1:] != owner[:-1]) | (pts[1:] != pts[:-1]).any(axis=1)
        for k, n in zip(many, np.bincount(owner[new], minlength=len(many)).tolist()):
            out[k] = n
        return out

    def _farthest_anchors(self, sets: list[list[int]]) -> np.ndarray:
        """(S,2) per list of two or more vertices (sorted): the two farthest apart at rest, the
        earlier listed first (the first such pair in row order; a vertex twice when all
        coincide)."""
        out = np.zeros((len(sets), 2), np.int64)
        pairs = [k for k, verts in enumerate(sets) if len(verts) == 2]
        if pairs:
            ends = np.array([sets[k] for k in pairs], np.int64)
            apart = np.linalg.norm(self.rest[ends[:, 0]] - self.rest[ends[:, 1]], axis=1) > 0
            out[pairs, 0] = ends[:, 0]
            out[pairs, 1] = np.where(apart, ends[:, 1], ends[:, 0])
        for k, verts in enumerate(sets):
            if len(verts) > 2:
                pts = self.rest[verts]
                d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
                i, j = np.unravel_index(int(np.argmax(d)), d.shape)
                out[k] = verts[min(i, j)], verts[max(i, j)]
        return out

    def _pinned_down(self, held: list[set[int]], hard: list[set[int]], places: list[int]) -> bool:
        """True when every body carries hard handles at two or more places and no link ties
        bodies together: nothing is left free (the common case, decided without analysis).
        Per body: ``held`` its anchors (at ``places`` distinct places), ``hard`` its hard
        handles' vertices."""
        if len(self.link_vertex):
            return False
        return all((n if verts == anchors else self._places(verts)) >= 2
                   for verts, anchors, n in zip(hard, held, places))

    def _append_handle(self, v: int, position: np.ndarray, weight: float, ref) -> None:
        self.handle_vertex = np.append(self.handle_vertex, np.int32(v)).astype(np.int32)
        self.handle_weight = np.append(self.handle_weight, weight)
        self.handle_refs.append(ref)
        self.extra_handle_positions.append(np.asarray(position, dtype=np.float64))

    def _similarity_kernel(self, bodies: list[list[int]]) -> set[int]:
        """Agents that some motion of the bodies (a similarity each) leaves every constraint
        unchanged for: the freedom the constraints do not fix. Empty when there is none.

        Unknowns: each body's translation, and unless it only translates its rotation and
        scale about its centre (complex). Each handle and link of positive weight is a row;
        the solver finds the columns the null space reaches."""
        nb = len(bodies)
        similar = np.array([body[0] not in self.translate_only for body in bodies])
        start = np.concatenate([[0], np.cumsum(np.where(similar, 2, 1))])
        body_of = np.array(self._body_of, dtype=np.int64)
        if self._centre is None:   # of each body's rest vertices
            sums = np.zeros((nb, 2))
            np.add.at(sums, body_of, np.add.reduceat(self.rest, self.offset[:-1]))
            self._centre = sums / np.bincount(body_of, weights=np.diff(self.offset), minlength=nb)[:, None]
        centre = self._centre
        hv, hw = self.handle_vertex, self.handle_weight
        lv, lw = self.link_vertex, self.link_weight
        hv, lv = hv[hw > 0], lv[lw > 0]
        nh, nl = len(hv), len(lv)
        if nh + nl == 0:
            return set(range(len(self.order)))
        verts = np.concatenate([hv, lv[:, 0], lv[:, 1]]).astype(np.int64)
        rows = np.concatenate([np.arange(nh), nh + np.arange(nl), nh + np.arange(nl)])
        sign = np.concatenate([np.ones(nh + nl), -np.ones(nl)])
        b = body_of[np.searchsorted(self.offset, verts, side="right") - 1]
        d = self.rest[verts] - centre[b]
        two = similar[b]
        values = np.concatenate([sign + 0j, sign[two] * (d[two, 0] + 1j * d[two, 1])])
        used = _solver.null_space_support(rows=np.concatenate([rows, rows[two]]).astype(np.int32),
                                          cols=np.concatenate([start[b], start[b][two] + 1]).astype(np.int32),
                                          values=values, num_rows=nh + nl, num_cols=int(start[-1]))
        moved = np.logical_or.reduceat(used, start[:-1]).tolist()
        return {i for body, m in zip(bodies, moved) if m for i in body}

    # ---- solving -----------------------------------------------------------------------

    def handle_positions(self, positions: np.ndarray | None = None) -> np.ndarray:
        """(H,2) positions for the solver: the handles' own, then the gauge pins'."""
        if positions is None:
            own = np.array([h.position for h in self.handles], dtype=np.float64).reshape(-1, 2)
        else:
            own = np.array(positions, dtype=np.float64).reshape(-1, 2)
        if not self.extra_handle_positions:
            return own
        return np.concatenate([own, np.array(self.extra_handle_positions, dtype=np.float64).reshape(-1, 2)])

    def _link_offsets(self, headings: dict[str, np.ndarray] | None) -> np.ndarray:
        if not self.links and not self.extra_links and self._spot is None:
            return np.zeros((0, 2))
        out = []
        for k in self.links:
            o = np.asarray(k.offset, dtype=np.float64)
            if k.space == "target":
                h = (headings or {}).get(k.target)
                a = float(h[k.target_frame]) if h is not None else \
                    float(self.full[k.target].source_heading[k.target_frame])
                c, s = np.cos(a), np.sin(a)
                o = np.array([c * o[0] - s * o[1], s * o[0] + c * o[1]])
            out.append(o)
        out.extend(offset for _, _, offset in self.extra_links)
        out = np.array(out, dtype=np.float64).reshape(-1, 2)
        if self._spot is not None:
            out = np.concatenate([out] + self._spot_offsets())
        return out

    @property
    def settles(self) -> bool:
        """Whether a solve re-solves until something settles (spot links): :meth:`solve_positions`
        then does more than one solver call."""
        return self._spot is not None

    def solve_positions(self, hp: np.ndarray):
        """The solver's result for handle positions ``hp`` (:meth:`handle_positions`: the gauge
        pins' too), the spot links' turn settled; and the link offsets it was solved with."""
        if self._spot is not None:
            self._start_spot_turn(hp)
        offsets = self._link_offsets(None)
        result = _solver.path_edit_solve(self.data, hp, offsets)
        if self._spot is not None:
            result, offsets = self._settle_spot(result, hp, offsets)
        return result, offsets

    def solve(self, handle_positions: np.ndarray | None = None) -> ComponentResult:
        """Solves for the handles' positions (default: their own), ``(H,2)`` in handle order."""
        hp = self.handle_positions(handle_positions)
        result, offsets = self.solve_positions(hp)
        if self._needs_headings:
            targets = {self.index[k.target] for k in self.links if k.space == "target"}
            for iteration in range(MAX_HEADING_ITERATIONS):
                if iteration:
                    result = _solver.path_edit_solve(self.data, hp, offsets)
                ground, turn_of = self._ground(result)
                headings = self._headings(ground, result, {i: self._turn(i, result, turn_of) for i in targets})
                new = self._link_offsets({self.order[i]: h for i, h in headings.items()})
                change = np.abs(new - offsets).max(initial=0.0)
                offsets = new
                if change <= HEADING_TOLERANCE * max(1.0, np.abs(offsets).max(initial=0.0)):
                    break
            else:
                self.notes.append("target-space relative constraints: the target headings did not settle")
        agents = self._agents(result)
        step1, step2 = result.step1, result.step2
        solver = step1.solver if step1.solver == step2.solver or step2.solver == "none" \
            else f"{step1.solver}; {step2.solver}"
        return ComponentResult(agents=agents, solver=solver, notes=list(self.notes),
                               link_offsets=offsets[:len(self.links)], step1=step1, step2=step2)

    def _ground(self, result) -> tuple[np.ndarray, dict]:
        """(F,2) paths of every agent concatenated, and the turn of each stationary range."""
        positions = np.asarray(result.positions)
        if self.pinned is not None:
            ends = np.unique(self.link_vertex[:len(self.links)].ravel())
            positions = positions - (positions[ends] - self.rest[ends]).mean(axis=0)
        turn_of: dict[tuple[int, int], float] = {}
        if self.rigid_refs:
            for ref, angle in zip(self.rigid_refs, np.asarray(result.rigid_angles).tolist()):
                if ref[0] == "stationary":
                    turn_of[(self.index[ref[1]], ref[2])] = angle
        return self._expand(positions), turn_of

    def _turn(self, i: int, result, turn_of: dict) -> np.ndarray:
        a = self._inputs[i]
        rest_turn = a.rest_turn if a.rest_turn is not None else np.zeros(len(a.stationary))
        if i in self.translate_only or not a.stationary:
            return rest_turn.copy() if a.rest_turn is not None else rest_turn
        if result.rigid_motion:
            return rest_turn + result.rigid_angle
        return rest_turn + np.array([turn_of.get((i, r), 0.0) for r in range(len(a.stationary))])

    def _headings(self, ground: np.ndarray, result, turns: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """(F,) headings of the agents ``turns`` names (index -> turn of each stationary range)
        on their edited paths (``ground``: every agent's, concatenated), as ``edited_heading``
        gives them, the turns of the deformation from one call per sample rate; except that a
        group member about one spot turns with its formation (``keep_spot`` off)."""
        rigid = result.rigid_angle if result.rigid_motion else None
        fo = self._full_offset
        out, turned, fixed, fixed_turn = {}, [], [], []
        for i, turn in turns.items():
            a = self._inputs[i]
            if i in self.translate_only or i in self._drift:
                # Moved by one translation, or drifting (its handles cannot turn it): the
                # heading is the rest path's.
                if i not in self._rest_headings:
                    self._rest_headings[i] = rest_heading(a, self.settings)
                out[i] = self._rest_headings[i].copy()
            elif rigid is not None and a.rest_turn is None:
                out[i] = np.asarray(a.source_heading, dtype=np.float64) + rigid
            else:
                fixed.extend((len(turned), first, last) for first, last in a.stationary)
                fixed_turn.extend(turn)
                turned.append(i)
        # One call per sample rate among the agents (clips sampled at other rates than the stage's).
        by_rate: dict[tuple, list[int]] = {}
        for k, i in enumerate(turned):
            by_rate.setdefault(turn_args(self._inputs[i], self.settings), []).append(k)
        fixed = np.asarray(fixed, dtype=np.int64).reshape(-1, 3)
        fixed_turn = np.asarray(fixed_turn, dtype=np.float64).reshape(-1)
        for args, ks in by_rate.items():
            chosen = [turned[k] for k in ks]
            blocks = [(fo[i], fo[i + 1]) for i in chosen]
            if len(chosen) == len(self._inputs):
                if self._source_full is None:
                    self._source_full = np.concatenate([a.source for a in self._inputs], dtype=np.float64)
                source, edited = self._source_full, ground
            else:
                source = np.concatenate([self._inputs[i].source for i in chosen])
                edited = np.concatenate([ground[b:e] for b, e in blocks])
            offsets = np.cumsum([0] + [e - b for b, e in blocks])
            mine = np.isin(fixed[:, 0], ks)
            renumber = {k: n for n, k in enumerate(ks)}
            ranges = [(renumber[int(b)], int(f), int(l)) for b, f, l in fixed[mine]]
            # A group member turns with its formation, even one that stays about one spot.
            members = set(self._members)
            keep = [i not in members for i in chosen]
            h = trajectory.deformation_turns(source, edited, offsets, ranges, fixed_turn[mine], *args, keep_spot=keep)
            for n, i in enumerate(chosen):
                out[i] = np.asarray(self._inputs[i].source_heading, dtype=np.float64) + h[offsets[n]:offsets[n + 1]]
        return out

    def _agents(self, result) -> dict[str, AgentResult]:
        ground, turn_of = self._ground(result)
        fo = self._full_offset
        turns = {i: self._turn(i, result, turn_of) for i in range(len(self._inputs))}
        headings = self._headings(ground, result, turns)
        return {a.path: AgentResult(ground=ground[fo[i]:fo[i + 1]], heading=headings[i], range_turn=turns[i],
                                    translate_only=i in self.translate_only)
                for i, a in enumerate(self._inputs)}


def implied_handles(agents: list[AgentInput], handles: list[Handle], tolerance: float) -> list[int]:
    """Indices of hard handles that one rigid motion of a stationary range already meets: a
    range holds at most two hard handles (its rigid motion has three freedoms), and more that
    one rigid motion meets (within ``tolerance`` stage units) say no more than the two farthest
    apart. Those two are kept; the range then meets the others."""
    by_agent = {a.path: a for a in agents}
    out: list[int] = []
    for a in agents:
        for first, last in a.stationary:
            mine = [k for k, h in enumerate(handles)
                    if h.agent == a.path and h.weight == HARD and first <= h.frame <= last]
            if len(mine) < 3:
                continue
            z = np.array([by_agent[a.path].rest[handles[k].frame] for k in mine], dtype=np.float64)
            p = np.array([handles[k].position for k in mine], dtype=np.float64)
            zc, pc = z - z.mean(axis=0), p - p.mean(axis=0)
            cross = np.sum((zc[:, 0] - 1j * zc[:, 1]) * (pc[:, 0] + 1j * pc[:, 1]))
            rot = cross / abs(cross) if abs(cross) > 0 else 1.0
            moved = (zc[:, 0] + 1j * zc[:, 1]) * rot + (p.mean(axis=0) @ [1.0, 1j])
            if np.abs(moved - (p[:, 0] + 1j * p[:, 1])).max() > tolerance:
                continue   # no rigid motion meets them: the solve says which contradict
            gap = np.linalg.norm(z[:, None, :] - z[None, :, :], axis=-1)
            i, j = np.unravel_index(int(np.argmax(gap)), gap.shape)
            out.extend(k for n, k in enumerate(mine) if n not in (i, j))
    return sorted(out)


def rest_heading(a: AgentInput, settings: Settings) -> np.ndarray:
    """Headings of an agent on its rest path (the source's, turned with any remap)."""
    if a.rest_turn is None:
        return np.asarray(a.source_heading, dtype=np.float64).copy()
    return edited_heading(a, a.rest, a.rest_turn, settings)


def edited_heading(a: AgentInput, g: np.ndarray, turn: np.ndarray, settings: Settings) -> np.ndarray:
    """Headings on an edited path ``g``: the source heading turned by the rotation the edit
    applies to the path around each frame (``trajectory.deformation_turns``), and through each
    stationary range by that range's rotation ``turn``, so the range stays rigid."""
    fixed = [(0, int(f), int(l)) for f, l in a.stationary]
    h = trajectory.deformation_turns(a.source, g, [0, a.frames], fixed, turn, *turn_args(a, settings))
    return np.asarray(a.source_heading, dtype=np.float64) + h


def shape_figures(a: AgentInput, g: np.ndarray, min_base: float) -> dict:
    """Report figures of an edited path: its length over the source's, and the RMS change of
    its local shape against the rest path (frames framed by less than ``min_base``, such
    as a stand, carry no shape)."""
    return {"lengthRatio": shape.length_ratio(g, a.source),
            "shapeChange": shape.shape_change(a.rest, g, min_base=min_base)}
