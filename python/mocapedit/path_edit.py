"""Builds and solves the path-editing problem of a component of agents (numpy + _solver).

A component is a set of agents tied together by relative constraints and groups; it is
one sparse two-step ARAP problem (``_solver.path_edit_*``, see
``solver/include/mocapedit/path_edit.h``) over every frame of every member, one vertex
per frame:

- each agent's path keeps its local shape (triangle terms) and its step lengths (edge
  terms), widening the local frame around frames that stand still;
- each stationary range moves rigidly, turned by the rotation the solve gives it;
- position constraints are handles, relative constraints links (hard ones eliminated,
  so they hold exactly);
- a group joins its members' paths at sampled shared times: each member is linked to its
  nearest neighbours there, its position kept in their local path frames (step 1) and its
  distance to them kept (step 2), weighted by the group's stiffness (Kwon et al. 2008).

The constraints leave some motions free; these are resolved so that an edit moves no more
than it must:

- a body (an agent, or a whole group) held at fewer than two frames moves by one
  translation, keeping its heading: one handle drags it along, a relative constraint on
  an otherwise free agent carries it with its partner;
- a component with no position constraint at all keeps its mean position: it is solved
  with one link end pinned, then shifted back so the ends of its links move by zero on
  average (the two sides of a handshake each walk half way);
- an agent held at exactly two frames, whose turn the constraints still leave free (a
  chain of agents linked end to end), keeps the direction between them (a soft term).

Relative constraints in the target's space turn with the target: the target's heading at
targetFrame is that of its edited path, found by re-solving (no refactoring) until it
stops changing.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _solver, metrics

HARD = np.inf
#: Target-space links: re-solve until the target headings change less than this (radians).
HEADING_TOLERANCE = 1e-12
MAX_HEADING_ITERATIONS = 30


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


@dataclass
class Settings:
    min_baseline: float                   # stage units: shortest local frame of a triangle
    rigid_min_extent: float               # stage units: smaller stationary ranges turn with their ends
    still: float                          # stage units: tangent steps below this stand still
    group_step: float = 4.0               # time codes between the sampled times of a group mesh
    group_neighbours: int = 3


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
    step1: dict | None = None
    step2: dict | None = None


class ComponentProblem:
    """The solver problem of one component. Build once; ``solve`` any number of times."""

    def __init__(self, agents: list[AgentInput], handles: list[Handle], links: list[Link],
                 groups: list[Group], settings: Settings, precompute_responses: bool = False):
        self.full = {a.path: a for a in agents}
        self.handles, self.links, self.groups = list(handles), list(links), list(groups)
        self.settings = settings
        self.notes: list[str] = []
        # Group members are solved on key frames; the frames between follow (see _keys).
        self.keys = self._keys()
        self.agents = [self._reduced(self.full[p]) for p in sorted(self.full)]
        self.index = {a.path: i for i, a in enumerate(self.agents)}
        self.offset = np.concatenate([[0], np.cumsum([a.frames for a in self.agents])]).astype(np.int64)
        self.rest = np.concatenate([a.rest for a in self.agents]).astype(np.float64)
        self._build_terms()
        self._resolve_freedom()
        self.data = _solver.path_edit_precompute(
            self.rest, self.triangles, self.triangle_weights, self.edges, self.edge_weights, self.rigid,
            self.handle_vertex, self.handle_weight, self.link_vertex, self.link_weight,
            settings.rigid_min_extent, precompute_responses=precompute_responses)

    # ---- key frames --------------------------------------------------------------------

    def _keys(self) -> dict[str, np.ndarray]:
        """Key frames of each group member: the group's sampled shared times, constrained
        frames, stationary ranges (and the frames around them), the ends, and every frame of
        a stretch too short to interpolate across. Other agents keep every frame.

        Kwon et al. build the group mesh on sampled frames too; here the frames between two
        keys follow them as one similarity, so they keep their shape and their sway."""
        s = self.settings
        out = {}
        members = {m for g in self.groups if g.stiffness > 0 for m in g.members if m in self.full}
        for g in self.groups:
            if g.stiffness <= 0:
                continue
            inside = [self.full[m] for m in g.members if m in self.full]
            start = max(float(m.sample_times[0]) for m in inside)
            end = min(float(m.sample_times[-1]) for m in inside)
            times = np.arange(start, end + 1e-9, s.group_step) if end >= start else np.zeros(0)
            for m in inside:
                f = np.clip(np.searchsorted(m.sample_times, times - 1e-9), 0, m.frames - 1)
                hit = f[np.abs(m.sample_times[f] - times) < 1e-6]
                out.setdefault(m.path, set()).update(int(x) for x in hit)
        for path in sorted(members):
            a = self.full[path]
            key = np.zeros(a.frames, bool)
            key[sorted(out.get(path, ()))] = True
            key[0] = key[-1] = True
            for h in self.handles:
                if h.agent == path and h.weight > 0:
                    key[h.frame] = True
            for k in self.links:
                if k.weight > 0:
                    key[k.frame] |= k.agent == path
                    key[k.target_frame] |= k.target == path
            for first, last in a.stationary:
                key[max(first - 1, 0):min(last + 2, a.frames)] = True
            at = np.flatnonzero(key)
            short = np.linalg.norm(a.rest[at[1:]] - a.rest[at[:-1]], axis=1) < s.min_baseline
            for lo, hi in zip(at[:-1][short], at[1:][short]):
                key[lo:hi] = True
            out[path] = np.flatnonzero(key)
        return out

    def _reduced(self, a: AgentInput) -> AgentInput:
        keys = self.keys.get(a.path)
        if keys is None:
            return a
        where = np.searchsorted(keys, [f for f, _ in a.stationary] + [l for _, l in a.stationary])
        n = len(a.stationary)
        return AgentInput(path=a.path, rest=a.rest[keys], source=a.source[keys], source_heading=a.source_heading[keys],
                          stationary=[(int(where[r]), int(where[n + r])) for r in range(n)],
                          stationary_refs=a.stationary_refs,
                          rest_turn=a.rest_turn, sample_times=a.sample_times[keys])

    def _expand(self, path: str, g: np.ndarray) -> np.ndarray:
        """The (F,2) path of an agent from its key frames: each frame between two keys is
        carried by the similarity that takes the keys' rest positions to their new ones."""
        keys = self.keys.get(path)
        a = self.full[path]
        if keys is None:
            return g
        z = a.rest[:, 0] + 1j * a.rest[:, 1]
        x = np.empty(a.frames, complex)
        x[keys] = g[:, 0] + 1j * g[:, 1]
        k1 = np.searchsorted(keys, np.arange(a.frames))
        between = np.flatnonzero((k1 > 0) & (k1 < len(keys)) & ~np.isin(np.arange(a.frames), keys))
        lo, hi = keys[k1[between] - 1], keys[k1[between]]
        gamma = (z[between] - z[lo]) / (z[hi] - z[lo])
        x[between] = x[lo] + gamma * (x[hi] - x[lo])
        return np.stack([x.real, x.imag], axis=1)

    # ---- structure ---------------------------------------------------------------------

    def vertex(self, agent: str, frame: int) -> int:
        keys = self.keys.get(agent)
        if keys is not None:
            frame = int(np.searchsorted(keys, frame))
        return int(self.offset[self.index[agent]] + frame)

    def _build_terms(self) -> None:
        s = self.settings
        tri, edg = [np.zeros((0, 3), np.int32)], [np.zeros((0, 2), np.int32)]
        tw, ew = [], []
        for a in self.agents:
            t, e = _solver.chain_terms(self.rest, int(self.offset[self.index[a.path]]), a.frames, s.min_baseline)
            tri.append(t), edg.append(e)
            tw.append(np.ones(len(t))), ew.append(np.ones(len(e)))
        for g in self.groups:
            t, e, w = self._group_terms(g)
            tri.append(t), edg.append(e)
            tw.append(np.full(len(t), w)), ew.append(np.full(len(e), w))
        self.triangles = np.concatenate(tri).astype(np.int32)
        self.edges = np.concatenate(edg).astype(np.int32)
        self.triangle_weights = np.concatenate(tw + [np.zeros(0)])
        self.edge_weights = np.concatenate(ew + [np.zeros(0)])
        # Handles and links, in input order (the solver reports contradictions by index).
        self.handle_vertex = np.array([self.vertex(h.agent, h.frame) for h in self.handles], dtype=np.int32)
        self.handle_weight = np.array([h.weight for h in self.handles], dtype=np.float64)
        self.handle_refs = [h.ref for h in self.handles]
        self.link_vertex = np.array([[self.vertex(k.agent, k.frame), self.vertex(k.target, k.target_frame)]
                                     for k in self.links], dtype=np.int32).reshape(-1, 2)
        self.link_weight = np.array([k.weight for k in self.links], dtype=np.float64)
        self.link_refs = [k.ref for k in self.links]
        self.extra_links: list[tuple[int, int, np.ndarray]] = []   # gauge terms: (a, b, offset)
        self.extra_handle_positions: list[np.ndarray] = []          # gauge pins

    def _group_terms(self, g: Group):
        """Triangles and edges joining the members of a group at every sampled shared time:
        each member to its nearest neighbours there, its position in their local path frame
        (step 1) and its distance to them (step 2)."""
        s = self.settings
        members = [self.agents[self.index[m]] for m in g.members if m in self.index]
        if g.stiffness <= 0 or len(members) < 2:
            return np.zeros((0, 3), np.int32), np.zeros((0, 2), np.int32), 0.0
        start = max(float(m.sample_times[0]) for m in members)
        end = min(float(m.sample_times[-1]) for m in members)
        if end < start:
            return np.zeros((0, 3), np.int32), np.zeros((0, 2), np.int32), 0.0
        times = np.arange(start, end + 1e-9, s.group_step)
        # (M,T) frame of each member at each time (-1 where it has no sample there).
        frames = np.empty((len(members), len(times)), np.int64)
        for k, m in enumerate(members):
            f = np.clip(np.searchsorted(m.sample_times, times - 1e-9), 0, m.frames - 1)
            frames[k] = np.where(np.abs(m.sample_times[f] - times) < 1e-6, f, -1)
        ok = (frames >= 0).all(axis=0)
        frames = frames[:, ok]
        vert = frames + np.array([self.offset[self.index[m.path]] for m in members])[:, None]   # (M,T)
        k = min(s.group_neighbours, len(members) - 1)
        pairs = []
        for chunk in range(0, vert.shape[1], 256):   # bounded memory: (M, M, 256) distances
            v = vert[:, chunk:chunk + 256]
            p = self.rest[v]                                                       # (M,t,2)
            d = np.linalg.norm(p[:, None] - p[None], axis=-1)                      # (M,M,t)
            d[np.arange(len(members)), np.arange(len(members))] = np.inf
            near = np.argsort(d, axis=1, kind="stable")[:, :k]                     # (M,k,t)
            a = np.broadcast_to(v[:, None, :], near.shape)
            b = np.take_along_axis(np.broadcast_to(v[None], (len(members),) + v.shape), near, axis=1)
            pairs.append(np.stack([np.minimum(a, b).ravel(), np.maximum(a, b).ravel()], axis=1))
        edg = np.unique(np.concatenate(pairs), axis=0)
        partner = self._frame_partners()
        tri = []
        for v, w in ((edg[:, 0], edg[:, 1]), (edg[:, 1], edg[:, 0])):
            f = partner[w]
            keep = (f >= 0) & (np.linalg.norm(self.rest[v] - self.rest[w], axis=1) > 0)
            tri.append(np.stack([v[keep], w[keep], f[keep]], axis=1))
        weight = g.stiffness
        return np.concatenate(tri).astype(np.int32), edg.astype(np.int32), weight

    def _frame_partners(self) -> np.ndarray:
        """(V,) per vertex: the nearest later frame of the same agent at least min_baseline
        away (an earlier one near the end; -1 if none), to frame a group triangle."""
        out = np.full(len(self.rest), -1, np.int64)
        for i, a in enumerate(self.agents):
            lo = int(self.offset[i])
            arc = _solver.cumulative_arc_length(np.ascontiguousarray(a.rest))
            idx = np.arange(a.frames)
            ahead = np.searchsorted(arc, arc + self.settings.min_baseline, side="left")
            behind = np.searchsorted(arc, arc - self.settings.min_baseline, side="right") - 1
            for cand in (ahead, behind):
                c = np.clip(cand, 0, a.frames - 1)
                far = np.linalg.norm(a.rest[c] - a.rest, axis=1) >= self.settings.min_baseline
                take = (out[lo:lo + a.frames] < 0) & far & (cand >= 0) & (cand < a.frames) & (c != idx)
                out[lo:lo + a.frames][take] = c[take] + lo
        return out

    # ---- the freedom the constraints leave -------------------------------------------

    def _bodies(self) -> list[list[int]]:
        """Agent indices of each body: a group joins its members, an agent is its own."""
        parent = list(range(len(self.agents)))

        def find(i):
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i
        for g in self.groups:
            ids = [self.index[m] for m in g.members if m in self.index]
            if g.stiffness > 0:
                for k in ids[1:]:
                    parent[find(k)] = find(ids[0])
        out: dict[int, list[int]] = {}
        for i in range(len(self.agents)):
            out.setdefault(find(i), []).append(i)
        return [sorted(v) for _, v in sorted(out.items())]

    def _anchors(self, body: list[int]) -> list[int]:
        verts = set()
        owner = set(body)
        for h, v in zip(self.handles, self.handle_vertex):
            if h.weight > 0 and self.index[h.agent] in owner:
                verts.add(int(v))
        for k, (a, b) in zip(self.links, self.link_vertex):
            if k.weight > 0:
                if self.index[k.agent] in owner:
                    verts.add(int(a))
                if self.index[k.target] in owner:
                    verts.add(int(b))
        return sorted(verts)

    def _resolve_freedom(self) -> None:
        bodies = self._bodies()
        self.translate_only = set()
        self.rigid, self.rigid_refs = [], []
        anchors = [self._anchors(b) for b in bodies]
        for body, anchor in zip(bodies, anchors):
            distinct = {tuple(self.rest[v]) for v in anchor}
            if len(distinct) < 2:
                self.translate_only.update(body)
                verts = np.concatenate([np.arange(self.offset[i], self.offset[i + 1]) for i in body])
                self.rigid.append((verts.astype(np.int64).tolist(), "translate"))
                self.rigid_refs.append(("body", [self.agents[i].path for i in body]))
        for i, a in enumerate(self.agents):
            if i in self.translate_only:
                continue
            for r, (first, last) in enumerate(a.stationary):
                verts = np.arange(first, last + 1) + int(self.offset[i])
                self.rigid.append((verts.astype(np.int64).tolist(), "rotate"))
                self.rigid_refs.append(("stationary", a.path, r))
        # No position constraint: pin one link end; the solve is shifted back afterwards.
        self.pinned = None
        if not any(h.weight > 0 for h in self.handles) and len(self.links):
            self.pinned = int(self.link_vertex[0, 0])
            self._append_handle(self.pinned, self.rest[self.pinned], HARD, None)
        kernel = self._similarity_kernel(bodies)
        if kernel:
            for body, anchor in zip(bodies, anchors):
                if len(anchor) == 2 and any(i in kernel for i in body):
                    a, b = anchor
                    self.extra_links.append((a, b, self.rest[a] - self.rest[b]))
            for a, b, offset in self.extra_links:
                self.link_vertex = np.concatenate([self.link_vertex, np.array([[a, b]], np.int32)])
                self.link_weight = np.append(self.link_weight, 1.0)
                self.link_refs.append(None)
            if self.extra_links:
                self.notes.append("the constraints leave some agents free to turn: each keeps the direction "
                                  "between the two frames it is held at")
            if self._similarity_kernel(bodies):
                self.notes.append("the constraints leave some agents free to move; add a position constraint")

    def _append_handle(self, v: int, position: np.ndarray, weight: float, ref) -> None:
        self.handle_vertex = np.append(self.handle_vertex, np.int32(v)).astype(np.int32)
        self.handle_weight = np.append(self.handle_weight, weight)
        self.handle_refs.append(ref)
        self.extra_handle_positions.append(np.asarray(position, dtype=np.float64))

    def _similarity_kernel(self, bodies: list[list[int]]) -> set[int]:
        """Agents that some motion of the bodies (a similarity each) leaves every constraint
        unchanged for: the freedom the constraints do not fix. Empty when there is none."""
        cols, centre = {}, {}
        for b, body in enumerate(bodies):
            verts = np.concatenate([np.arange(self.offset[i], self.offset[i + 1]) for i in body])
            centre[b] = self.rest[verts].mean(axis=0)
            cols[b] = 1 if body[0] in self.translate_only else 2
        start = np.cumsum([0] + [cols[b] for b in range(len(bodies))])
        body_of = np.empty(len(self.rest), np.int64)
        for b, body in enumerate(bodies):
            for i in body:
                body_of[self.offset[i]:self.offset[i + 1]] = b
        rows = []

        def term(v, sign, row):
            b = body_of[v]
            row[start[b]] += sign
            if cols[b] == 2:
                d = self.rest[v] - centre[b]
                row[start[b] + 1] += sign * complex(d[0], d[1])
        for v, w in zip(self.handle_vertex, self.handle_weight):
            if w > 0:
                row = np.zeros(start[-1], complex)
                term(v, 1, row)
                rows.append(row)
        for (a, b), w in zip(self.link_vertex, self.link_weight):
            if w > 0:
                row = np.zeros(start[-1], complex)
                term(a, 1, row)
                term(b, -1, row)
                rows.append(row)
        if not rows:
            return set(range(len(self.agents)))
        moving = _null_columns(np.array(rows))
        free = set()
        for b, body in enumerate(bodies):
            if moving[start[b]:start[b + 1]].any():
                free.update(body)
        return free

    # ---- solving -----------------------------------------------------------------------

    def handle_positions(self, positions: np.ndarray | None = None) -> np.ndarray:
        """(H,2) positions for the solver: the handles' own, then the gauge pins'."""
        own = np.array([h.position for h in self.handles], dtype=np.float64).reshape(-1, 2)
        if positions is not None:
            own = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        return np.concatenate([own, np.array(self.extra_handle_positions, dtype=np.float64).reshape(-1, 2)])

    def _link_offsets(self, headings: dict[str, np.ndarray] | None) -> np.ndarray:
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
        return np.array(out, dtype=np.float64).reshape(-1, 2)

    def solve(self, handle_positions: np.ndarray | None = None) -> ComponentResult:
        """Solves for the handles' positions (default: their own), ``(H,2)`` in handle order."""
        hp = self.handle_positions(handle_positions)
        needs_headings = any(k.space == "target" for k in self.links)
        headings = None
        offsets = self._link_offsets(None)
        for _ in range(MAX_HEADING_ITERATIONS):
            result = _solver.path_edit_solve(self.data, hp, offsets)
            agents = self._agents(result)
            if not needs_headings:
                break
            headings = {p: r.heading for p, r in agents.items()}
            new = self._link_offsets(headings)
            change = np.abs(new - offsets).max(initial=0.0)
            offsets = new
            if change <= HEADING_TOLERANCE * max(1.0, np.abs(offsets).max(initial=0.0)):
                break
        else:
            self.notes.append("target-space relative constraints: the target headings did not settle")
        step1, step2 = result.step1, result.step2
        solver = step1["solver"] if step1["solver"] == step2["solver"] or step2["solver"] == "none" \
            else f"{step1['solver']}; {step2['solver']}"
        return ComponentResult(agents=agents, solver=solver, notes=list(self.notes),
                               link_offsets=offsets[:len(self.links)], step1=step1, step2=step2)

    def _agents(self, result) -> dict[str, AgentResult]:
        positions = np.asarray(result.positions)
        if self.pinned is not None:
            ends = np.unique(self.link_vertex[:len(self.links)].ravel())
            positions = positions - (positions[ends] - self.rest[ends]).mean(axis=0)
        angles = np.asarray(result.rigid_angles)
        turn_of: dict[tuple[str, int], float] = {}
        for (ref, angle) in zip(self.rigid_refs, angles):
            if ref[0] == "stationary":
                turn_of[(ref[1], ref[2])] = float(angle)
        out = {}
        for i, reduced in enumerate(self.agents):
            a = self.full[reduced.path]
            g = self._expand(a.path, positions[self.offset[i]:self.offset[i + 1]].copy())
            rest_turn = a.rest_turn if a.rest_turn is not None else np.zeros(len(a.stationary))
            if i in self.translate_only:
                # Moved by one translation: the heading is the rest path's.
                turn = rest_turn.copy()
                heading = rest_heading(a)
                out[a.path] = AgentResult(ground=g, heading=heading, range_turn=turn, translate_only=True)
                continue
            if result.rigid_motion:
                turn = rest_turn + result.rigid_angle
            else:
                turn = rest_turn + np.array([turn_of.get((a.path, r), 0.0) for r in range(len(a.stationary))])
            out[a.path] = AgentResult(ground=g, heading=edited_heading(a, g, turn, self.settings.still,
                                                                       result.rigid_angle if result.rigid_motion
                                                                       else None),
                                      range_turn=turn)
        return out


def _null_columns(m: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(C,) bool: the columns some null vector of m uses (reduced row echelon form by
    Gaussian elimination with partial pivoting; the matrices here are small, and LAPACK's
    thread pool costs more than the work)."""
    a = np.array(m, dtype=complex)
    scale = np.abs(a).max(axis=0)
    a /= np.where(scale > 0, scale, 1.0)
    rows, cols = a.shape
    pivots, r = [], 0
    for c in range(cols):
        if r == rows:
            break
        k = r + int(np.argmax(np.abs(a[r:, c])))
        if abs(a[k, c]) <= tol:
            continue
        a[[r, k]] = a[[k, r]]
        a[r] /= a[r, c]
        others = np.abs(a[:, c]) > 0
        others[r] = False
        a[others] -= np.outer(a[others, c], a[r])
        pivots.append(c)
        r += 1
    free = np.ones(cols, dtype=bool)
    free[pivots] = False
    used = free.copy()
    for row, c in enumerate(pivots):
        if np.abs(a[row, free]).max(initial=0.0) > tol:
            used[c] = True
    return used


def rest_heading(a: AgentInput) -> np.ndarray:
    """Headings of an agent on its rest path (the source's, turned with any remap)."""
    if a.rest_turn is None:
        return np.asarray(a.source_heading, dtype=np.float64).copy()
    return edited_heading(a, a.rest, a.rest_turn, None, None)


def edited_heading(a: AgentInput, g: np.ndarray, turn: np.ndarray, still: float | None,
                   rigid_angle: float | None) -> np.ndarray:
    """Headings on an edited path: its tangent, and through each stationary range the source
    heading turned by that range's rotation, so the range stays rigid."""
    if rigid_angle is not None and a.rest_turn is None:
        return np.asarray(a.source_heading, dtype=np.float64) + rigid_angle
    fixed = [(int(f), int(l)) for f, l in a.stationary]
    fallback = np.array([a.source_heading[f] + t for (f, _), t in zip(fixed, turn)], dtype=np.float64)
    step = still if still is not None else 0.0
    return _solver.tangent_headings(np.ascontiguousarray(g, dtype=np.float64), fixed, fallback, step)


def shape_figures(a: AgentInput, g: np.ndarray) -> dict:
    """Report figures of an edited path against its source."""
    return {"lengthRatio": metrics.length_ratio(g, a.source), "shapeChange": metrics.shape_change(a.rest, g)}
