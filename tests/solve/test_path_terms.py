"""The fast paths that build a component's path problem, against straightforward numpy
references on generated problems: the solver's batched terms (``_solver.component_chain_terms``,
``group_sample_frames``, ``frame_partners``, ``group_mesh_terms``, ``null_space_support``,
``block_deformation_turns``) and ComponentProblem's vectorised key frames, interpolation and
freedom analysis. Each reference does the work one agent, one sampled time or one dense
elimination at a time."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mocapedit import _solver
from mocapedit.inspect import metrics
from mocapedit.solve import path_edit

FPS = 24.0
SETTINGS = path_edit.Settings(min_baseline=0.01, rigid_min_extent=0.02, still=1e-5, group_step=12.0)


def _walk(frames, origin=(0.0, 0.0), heading=np.pi / 2, stand=None, step=1.4 / FPS):
    f = np.arange(frames, dtype=np.float64)
    along = f * step
    if stand is not None:   # stands still over [first, last]
        first, last = stand
        along = np.where(f < first, along, np.where(f <= last, first * step, along - (last - first) * step))
    d = np.array([np.cos(heading), np.sin(heading)])
    n = np.array([-d[1], d[0]])
    return np.asarray(origin) + along[:, None] * d + (0.03 * np.sin(2 * np.pi * f / FPS))[:, None] * n


def _agent(path, rest, stationary=(), times=None):
    from mocapedit.geometry import trajectory
    return path_edit.AgentInput(path=path, rest=rest, source=rest,
                                source_heading=trajectory.headings(rest, list(stationary), 1.0),
                                stationary=list(stationary), stationary_refs=[f"{path}:{r}" for r in stationary],
                                sample_times=np.arange(len(rest), dtype=np.float64) if times is None else times)


# ---- references ----------------------------------------------------------------------

def ref_frame_partners(rest, offsets, min_baseline):
    out = np.full(len(rest), -1, np.int64)
    for lo, hi in zip(offsets[:-1], offsets[1:]):
        a = rest[lo:hi]
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(a, axis=0), axis=1))])
        idx = np.arange(len(a))
        for cand in (np.searchsorted(arc, arc + min_baseline, side="left"),
                     np.searchsorted(arc, arc - min_baseline, side="right") - 1):
            c = np.clip(cand, 0, len(a) - 1)
            far = np.linalg.norm(a[c] - a, axis=1) >= min_baseline
            take = (out[lo:hi] < 0) & far & (cand >= 0) & (cand < len(a)) & (c != idx)
            out[lo:hi][take] = c[take] + lo
    return out


def ref_group_mesh(rest, vert, k, partner, connect=True):
    """Each member to its k nearest at every sampled time (a stable sort of distances); then,
    while the joined members fall into several clusters, each cluster to its nearest other
    cluster (smallest squared distance, then members) by the k nearest pairs between them."""
    pairs = []
    m = len(vert)
    for t in range(vert.shape[1]):
        p = rest[vert[:, t]]
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)
        d[np.arange(m), np.arange(m)] = np.inf
        joined = []
        for a in range(m):
            for b in np.argsort(d[a], kind="stable")[:k]:
                joined.append((a, int(b)))
        if k > 0 and connect:
            dx, dy = p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1]
            sq = dx * dx + dy * dy
            while True:
                label = np.arange(m)
                for _ in range(m):   # clusters of the joined pairs
                    for a, b in joined:
                        label[a] = label[b] = min(label[a], label[b])
                best = {}
                for a in range(m):
                    for b in range(a + 1, m):
                        if label[a] != label[b]:
                            for c in (label[a], label[b]):
                                best[c] = min(best.get(c, (np.inf, m, m)), (sq[a, b], a, b))
                if not best:
                    break
                for pair in sorted({tuple(sorted((label[a], label[b]))) for _, a, b in best.values()}):
                    across = sorted((sq[a, b], a, b) for a in range(m) for b in range(a + 1, m)
                                    if {label[a], label[b]} == set(pair))
                    joined += [(a, b) for _, a, b in across[:k]]
        for a, b in joined:
            pairs.append((min(vert[a, t], vert[b, t]), max(vert[a, t], vert[b, t])))
    edg = np.unique(np.array(pairs, np.int64).reshape(-1, 2), axis=0)
    tri = [(v, w, partner[w]) for v, w in np.concatenate([edg, edg[:, ::-1]])
           if partner[w] >= 0 and np.linalg.norm(rest[v] - rest[w]) > 0]
    return np.array(tri, np.int64).reshape(-1, 3), edg


def ref_null_columns(m, tol=1e-9):
    """Reduced row echelon form by dense Gaussian elimination with partial pivoting."""
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
    used = np.ones(cols, dtype=bool)
    used[pivots] = False
    free = used.copy()
    for row, c in enumerate(pivots):
        used[c] = np.abs(a[row, free]).max(initial=0.0) > tol
    return used


def ref_keys(agents, handles, links, groups, s):
    """Key frames of each group member, one member at a time."""
    full = {a.path: a for a in agents}
    out = {}
    for g in groups:
        if g.stiffness <= 0:
            continue
        inside = [full[m] for m in g.members if m in full]
        start = max(float(m.sample_times[0]) for m in inside)
        end = min(float(m.sample_times[-1]) for m in inside)
        times = ref_sample_times(start, end, s.group_step)
        for m in inside:
            f = np.clip(np.searchsorted(m.sample_times, times - 1e-9), 0, m.frames - 1)
            out.setdefault(m.path, set()).update(f[np.abs(m.sample_times[f] - times) < 1e-6].tolist())
    keys = {}
    for path in sorted(out):
        a = full[path]
        key = np.zeros(a.frames, bool)
        key[sorted(out[path])] = True
        key[0] = key[-1] = True
        for h in handles:
            if h.agent == path and h.weight > 0:
                key[h.frame] = True
        for k in links:
            if k.weight > 0:
                key[k.frame] |= k.agent == path
                key[k.target_frame] |= k.target == path
        for first, last in a.stationary:
            key[max(first - 1, 0):min(last + 2, a.frames)] = True
        at = np.flatnonzero(key)
        short = np.linalg.norm(a.rest[at[1:]] - a.rest[at[:-1]], axis=1) < s.min_baseline
        for lo, hi in zip(at[:-1][short], at[1:][short]):
            key[lo:hi] = True
        keys[path] = np.flatnonzero(key)
    return keys


def ref_sample_times(start, end, step):
    """A group's sampled times: start, start + step, ..., and the end, which takes the last
    regular time's place when within half a step of it."""
    if end < start:
        return np.zeros(0)
    times = [start + i * step for i in range(int(np.floor((end - start) / step + 1e-9)) + 1)]
    if end - times[-1] > 1e-6:
        if len(times) > 1 and end - times[-1] < step / 2:
            times[-1] = end
        else:
            times.append(end)
    return np.array(times)


def ref_expand(a, keys, g):
    """(F,2) path from its key frames: each interval's similarity (keys' rest positions to
    their solved ones), blended with its neighbours' by (1-t)^2/2 and t^2/2."""
    z = a.rest[:, 0] + 1j * a.rest[:, 1]
    k = np.asarray(keys)
    x = np.empty(a.frames, complex)
    xk = g[:, 0] + 1j * g[:, 1]
    x[k] = xk

    def similarity(j):  # interval (k[j-1], k[j]) as a function of rest positions, or None
        if j < 1 or j >= len(k) or k[j] - k[j - 1] < 2 or z[k[j]] == z[k[j - 1]]:
            return None
        m = (xk[j] - xk[j - 1]) / (z[k[j]] - z[k[j - 1]])
        return lambda w: xk[j - 1] + (w - z[k[j - 1]]) * m

    for j in range(1, len(k)):
        frames = np.arange(k[j - 1] + 1, k[j])
        if not len(frames):
            continue
        t = (frames - k[j - 1]) / (k[j] - k[j - 1])
        s, before, after = similarity(j), similarity(j - 1), similarity(j + 1)
        if s is None:  # keys at one rest position: the frames between move in time
            x[frames] = xk[j - 1] + t * (xk[j] - xk[j - 1])
            continue
        here = s(z[frames])
        if before is not None:
            here = here + (1 - t) ** 2 / 2 * (before(z[frames]) - s(z[frames]))
        if after is not None:
            here = here + t ** 2 / 2 * (after(z[frames]) - s(z[frames]))
        x[frames] = here
    return np.stack([x.real, x.imag], axis=1)


def ref_freedom(p):
    """The freedom analysis one body at a time, the null space by dense elimination: which
    agents only translate, and the gauge links (vertex pairs) added."""
    bodies = {}
    for i, path in enumerate(p.order):
        root = min((g for g in p.groups if g.stiffness > 0 and path in g.members),
                   key=lambda g: p.groups.index(g), default=None)
        bodies.setdefault(root.ref if root else path, []).append(i)
    bodies = list(bodies.values())
    rest, off = p.rest, p.offset
    hv = np.array([p.vertex(h.agent, h.frame) for h in p.handles], np.int64)
    lv = np.array([(p.vertex(k.agent, k.frame), p.vertex(k.target, k.target_frame)) for k in p.links],
                  np.int64).reshape(-1, 2)
    hw = np.array([h.weight for h in p.handles], float)
    lw = np.array([k.weight for k in p.links], float)

    def anchors(body):
        verts = {int(v) for h, v in zip(p.handles, hv) if h.weight > 0 and p.index[h.agent] in body}
        verts |= {int(a) for k, (a, b) in zip(p.links, lv) if k.weight > 0 and p.index[k.agent] in body}
        verts |= {int(b) for k, (a, b) in zip(p.links, lv) if k.weight > 0 and p.index[k.target] in body}
        return sorted(verts)
    translate = set()
    for body in bodies:
        if len({tuple(rest[v]) for v in anchors(body)}) < 2:
            translate.update(body)
    if not (hw > 0).any() and len(lv):
        hv, hw = np.append(hv, lv[0, 0]), np.append(hw, np.inf)

    def kernel(lv, lw):
        cols = [1 if body[0] in translate else 2 for body in bodies]
        start = np.cumsum([0] + cols)
        rows = []
        for signs in ([(v, 1)] for v, w in zip(hv, hw) if w > 0), ([(a, 1), (b, -1)] for (a, b), w in zip(lv, lw) if w > 0):
            for terms in signs:
                row = np.zeros(start[-1], complex)
                for v, sign in terms:
                    b = next(n for n, body in enumerate(bodies) if any(off[i] <= v < off[i + 1] for i in body))
                    verts = np.concatenate([np.arange(off[i], off[i + 1]) for i in bodies[b]])
                    row[start[b]] += sign
                    if cols[b] == 2:
                        d = rest[v] - rest[verts].mean(axis=0)
                        row[start[b] + 1] += sign * complex(d[0], d[1])
                rows.append(row)
        if not rows:
            return set(range(len(p.order)))
        used = ref_null_columns(np.array(rows))
        return {i for b, body in enumerate(bodies) if used[start[b]:start[b + 1]].any() for i in body}
    gauge = []
    free = kernel(lv, lw)
    if free:
        for body in bodies:
            anchor = anchors(body)
            if len(anchor) >= 2 and free & set(body):
                d = np.linalg.norm(rest[anchor][:, None] - rest[anchor][None], axis=-1)
                i, j = np.unravel_index(int(np.argmax(d)), d.shape)
                gauge.append((anchor[min(i, j)], anchor[max(i, j)]))
    if gauge:
        lv = np.concatenate([lv, np.array(gauge, np.int64)])
        lw = np.append(lw, np.full(len(gauge), path_edit.GAUGE_WEIGHT))
    return translate, gauge, bool(free) and bool(kernel(lv, lw))


# ---- the solver's batched terms ------------------------------------------------------

def _paths(seed):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(5):
        frames = int(rng.integers(2, 90))
        stand = (frames // 3, frames // 3 + int(rng.integers(0, 20))) if k % 2 else None
        out.append(_walk(frames, rng.normal(size=2), rng.uniform(-3, 3), stand))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_component_chain_terms_and_partners_are_each_agents(seed):
    paths = _paths(seed)
    rest = np.concatenate(paths)
    offsets = np.cumsum([0] + [len(p) for p in paths]).astype(np.int32)
    tri, edg = _solver.component_chain_terms(rest, offsets, 0.01)
    each = [_solver.chain_terms(rest, int(lo), int(hi - lo), 0.01) for lo, hi in zip(offsets[:-1], offsets[1:])]
    np.testing.assert_array_equal(tri, np.concatenate([t for t, _ in each]))
    np.testing.assert_array_equal(edg, np.concatenate([e for _, e in each]))
    np.testing.assert_array_equal(_solver.frame_partners(rest, offsets, 0.05), ref_frame_partners(rest, offsets, 0.05))
    with pytest.raises(ValueError, match="offsets"):
        _solver.component_chain_terms(rest, offsets[:-1], 0.01)


def test_group_sample_frames_match_searchsorted():
    rng = np.random.default_rng(3)
    times = [np.arange(40, dtype=float) + 3, np.arange(30, dtype=float) + 0.5, np.arange(50, dtype=float),
             np.sort(rng.uniform(0, 40, 35))]
    sampled = np.arange(0.0, 45.0, 4.0)
    got = _solver.group_sample_frames(np.concatenate(times), np.cumsum([0] + [len(t) for t in times]).astype(np.int32),
                                      sampled)
    for m, t in enumerate(times):
        f = np.clip(np.searchsorted(t, sampled - 1e-9), 0, len(t) - 1)
        np.testing.assert_array_equal(got[m], np.where(np.abs(t[f] - sampled) < 1e-6, f, -1))
    assert (got[1] == -1).all() and (got[2] >= 0).all() and (got[0] == -1).sum() == 2  # before its first and after its last


@pytest.mark.parametrize("layout", ["grid", "jittered", "coincident", "large", "clusters", "clumps"])
def test_group_mesh_terms_match_a_stable_sort(layout):
    rng = np.random.default_rng(4)
    # "large": 60 members x 43 sampled times, enough for the search to split the times
    # between two threads. "clusters": four blocks of six, 10 m apart, whose nearest
    # neighbours stay inside each block.
    members, frames = (60, 300) if layout == "large" else (24, 30)
    if layout == "large":
        layout = "jittered"
    origin = np.array([(1.0 * (m % 6), -1.2 * (m // 6)) for m in range(members)])
    if layout == "jittered":
        origin += rng.normal(scale=0.3, size=origin.shape)
    if layout == "coincident":
        origin[5] = origin[4]
    if layout == "clusters":
        origin = np.array([(1.0 * (m % 3) + 10.0 * (m // 6), -1.2 * ((m // 3) % 2)) for m in range(members)])
    if layout == "clumps":   # eight clumps of three scattered over 60 m: several rounds of joins
        origin = np.repeat(rng.uniform(0.0, 60.0, (8, 2)), 3, axis=0) + rng.normal(scale=0.3, size=(members, 2))
    rest = np.concatenate([_walk(frames, o) for o in origin])
    offsets = np.cumsum([0] + [frames] * members).astype(np.int32)
    partner = _solver.frame_partners(rest, offsets, 0.01)
    vert = (offsets[:-1, None] + np.arange(0, frames, 7)[None]).astype(np.int32)
    for k in (1, 3, 5):
        tri, edg = _solver.group_mesh_terms(rest, vert, k, partner)
        ref_tri, ref_edg = ref_group_mesh(rest, vert, k, partner)
        np.testing.assert_array_equal(edg, ref_edg)
        np.testing.assert_array_equal(tri, ref_tri)
        # At every sampled time the edges join all the members into one piece.
        at = edg[:, 0] % frames
        for f in range(0, frames, 7):
            e = edg[at == f] // frames
            joined = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(members, members))
            assert connected_components(joined, directed=False)[0] == 1, (layout, k, f)
    with pytest.raises(ValueError, match="neighbours"):
        _solver.group_mesh_terms(rest, vert, members, partner)


def test_group_mesh_ties_go_to_the_earlier_member():
    """Equal distances rank the earlier member first, as a stable sort of the distances
    does, also where the squared distances differ and their square roots do not."""
    angle = next(a for a in np.linspace(0.3, 0.4, 10000)
                 if (5 * np.cos(a)) ** 2 + (5 * np.sin(a)) ** 2 > 25 and np.hypot(5 * np.cos(a), 5 * np.sin(a)) == 5
                 and np.sqrt((5 * np.cos(a)) ** 2 + (5 * np.sin(a)) ** 2) == 5)
    tilted = 5 * np.array([np.cos(angle), np.sin(angle)])
    points = np.array([
        (0, 0), tilted, (5, 0), 1.1 * tilted, (5.5, 0),          # 0 ties 1 (farther squared) and 2
        (100, 0), (101, 0), (99, 0), (98.5, 0), (101.5, 0)])    # 5 ties 6 and 7 exactly
    rest = np.repeat(points, 3, axis=0)
    vert = (3 * np.arange(len(points)))[:, None].astype(np.int32)
    partner = np.full(len(rest), -1, np.int32)
    _, edg = _solver.group_mesh_terms(rest, vert, 1, partner)
    np.testing.assert_array_equal(edg, ref_group_mesh(rest, vert, 1, partner)[1])
    # The nearest-neighbour joins (before the pieces they leave are joined):
    nearest = (ref_group_mesh(rest, vert, 1, partner, connect=False)[1] // 3).tolist()
    assert [0, 1] in nearest and [5, 6] in nearest
    assert [0, 2] not in nearest and [5, 7] not in nearest


def _similarity_system(rng, bodies, rows, coincide):
    """A handle-and-link system over bodies of one or two complex unknowns (as the freedom
    analysis builds it), some rows repeated or on coinciding points."""
    cols = rng.integers(1, 3, bodies)
    start = np.cumsum(np.concatenate([[0], cols]))
    m = np.zeros((rows, start[-1]), complex)
    points = rng.normal(size=(bodies, 4)) + 1j * rng.normal(size=(bodies, 4))
    if coincide:
        points[:, 1] = points[:, 0]
    for r in range(rows):
        ends = rng.integers(0, bodies, 1 if r % 3 == 0 else 2)
        for sign, b in zip((1, -1), ends):
            m[r, start[b]] += sign
            if cols[b] == 2:
                m[r, start[b] + 1] += sign * points[b, rng.integers(0, 4 if not coincide else 2)]
    if rows > 2:
        m[-1] = m[0] * (0.5 - 2j)   # a dependent row
    return m


@pytest.mark.parametrize("seed", range(12))
def test_null_space_support_matches_dense_elimination(seed):
    rng = np.random.default_rng(seed)
    m = _similarity_system(rng, int(rng.integers(1, 12)), int(rng.integers(1, 20)), coincide=seed % 3 == 0)
    r, c = np.nonzero(m)
    got = _solver.null_space_support(rows=r.astype(np.int32), cols=c.astype(np.int32), values=m[r, c],
                                     num_rows=m.shape[0], num_cols=m.shape[1])
    np.testing.assert_array_equal(got, ref_null_columns(m))
    # And the truth: the columns the SVD's null vectors reach.
    _, sv, vh = np.linalg.svd(m)
    null = vh[np.sum(sv > 1e-9 * sv.max()):]
    np.testing.assert_array_equal(got, np.abs(null).max(axis=0, initial=0.0) > 1e-9)


def test_null_space_support_of_known_matrices():
    one = np.array([0], np.int32)
    # x0 = 0 leaves x1 free; x0 - x1 = 0 and x1 = 0 fix both; no rows: all free.
    support = _solver.null_space_support(rows=one, cols=one, values=np.array([1 + 0j]), num_rows=1, num_cols=2)
    assert support.tolist() == [False, True]
    rows, cols = np.array([0, 0, 1], np.int32), np.array([0, 1, 1], np.int32)
    support = _solver.null_space_support(rows=rows, cols=cols, values=np.array([1, -1, 1 + 0j]), num_rows=2,
                                         num_cols=2)
    assert support.tolist() == [False, False]
    assert _solver.null_space_support(rows=one[:0], cols=one[:0], values=np.zeros(0, complex), num_rows=0,
                                      num_cols=3).tolist() == [True] * 3
    # Repeated entries are summed: 1 - 1 = 0 leaves x0 free.
    assert _solver.null_space_support(rows=np.zeros(2, np.int32), cols=np.zeros(2, np.int32),
                                      values=np.array([1, -1 + 0j]), num_rows=1, num_cols=1)[0]
    with pytest.raises(ValueError, match="out of range"):
        _solver.null_space_support(rows=one, cols=one + 5, values=np.array([1 + 0j]), num_rows=1, num_cols=2)


def _edited(paths):
    """Each path bent a little about its start: a different turn at every frame."""
    out = []
    for p in paths:
        a = 0.3 * np.linspace(0.0, 1.0, len(p))[:, None]
        d = p - p[0]
        out.append(p[0] + np.concatenate([np.cos(a) * d[:, :1] - np.sin(a) * d[:, 1:],
                                          np.sin(a) * d[:, :1] + np.cos(a) * d[:, 1:]], axis=1))
    return out


def test_block_deformation_turns_are_each_agents():
    paths = _paths(5)
    g, e = np.concatenate(paths), np.concatenate(_edited(paths))
    offsets = np.cumsum([0] + [len(p) for p in paths])
    blocks = np.array([(offsets[i], offsets[i + 1]) for i in (0, 2, 3)], np.int32)
    fixed = np.array([(1, 1, len(paths[2]) // 2), (2, 0, 0), (2, 1, 1)], np.int32)
    turn = np.array([0.5, -1.0, 2.0])
    got = _solver.block_deformation_turns(source=g, edited=e, blocks=blocks, fixed=fixed, fixed_turn=turn,
                                          window=2, min_travel=0.01)
    for b, (lo, hi) in enumerate(blocks):
        mine = fixed[:, 0] == b
        ref = _solver.deformation_turns(source=g[lo:hi], edited=e[lo:hi],
                                        fixed=[tuple(r) for r in fixed[mine, 1:].tolist()], fixed_turn=turn[mine],
                                        window=2, min_travel=0.01)
        np.testing.assert_array_equal(got[lo:hi], ref)
    assert not got[offsets[1]:offsets[2]].any()
    with pytest.raises(ValueError, match="grouped by block"):
        _solver.block_deformation_turns(source=g, edited=e, blocks=blocks, fixed=fixed[::-1].copy(), fixed_turn=turn,
                                        window=2, min_travel=0.01)


def test_many_turns_split_between_threads_are_each_agents():
    # Over 20,000 frames: computed on two threads, the same as one agent at a time.
    paths = [p for seed in range(100) for p in _paths(seed)]
    g, e = np.concatenate(paths), np.concatenate(_edited(paths))
    offsets = np.cumsum([0] + [len(p) for p in paths])
    assert offsets[-1] > 20000
    blocks = np.array([(offsets[i], offsets[i + 1]) for i in range(len(paths))], np.int32)
    fixed = np.array([(b, 0, 1) for b in range(0, len(paths), 3)], np.int32)
    turn = np.linspace(-1.0, 1.0, len(fixed))
    got = _solver.block_deformation_turns(source=g, edited=e, blocks=blocks, fixed=fixed, fixed_turn=turn,
                                          window=3, min_travel=0.01)
    for b, (lo, hi) in enumerate(blocks):
        mine = fixed[:, 0] == b
        ref = _solver.deformation_turns(source=g[lo:hi], edited=e[lo:hi],
                                        fixed=[tuple(r) for r in fixed[mine, 1:].tolist()], fixed_turn=turn[mine],
                                        window=3, min_travel=0.01)
        np.testing.assert_array_equal(got[lo:hi], ref)


# ---- whole problems ------------------------------------------------------------------

def _problems():
    """name -> (agents, handles, links, groups): single paths, relays, groups, mixtures."""
    H, L, G = path_edit.Handle, path_edit.Link, path_edit.Group
    out = {}
    rest = _walk(300, stand=(120, 160))
    single = [_agent("a", rest, [(120, 160)])]
    out["single"] = (single, [H("a", 0, rest[0], np.inf, "h0"), H("a", 200, rest[200] + [0.5, 0], np.inf, "h1"),
                              H("a", 299, rest[299], np.inf, "h2")], [], [])
    out["single-one-soft-handle"] = (single, [H("a", 50, rest[50] + 1, 2.0, "s")], [], [])
    relay = [_agent(f"r{k}", _walk(60, (0.4 * np.sin(k), k * 3.8)), times=np.arange(60.0) + 59 * k) for k in range(9)]
    links = [L(f"r{k}", 59, f"r{k + 1}", 0, np.array([0.4, 0.0]), "world", np.inf, f"/l{k}") for k in range(8)]
    ends = [H("r0", 0, relay[0].rest[0], np.inf, "first"), H("r8", 59, relay[8].rest[59] + [2.0, -1.0], np.inf, "last")]
    out["relay"] = (relay, ends, links, [])
    out["relay-target-space"] = (relay, ends, [L(k.agent, k.frame, k.target, k.target_frame, k.offset, "target",
                                                 k.weight, k.ref) for k in links], [])
    out["relay-soft-links-one-handle"] = (relay, ends[:1], [L(k.agent, k.frame, k.target, k.target_frame, k.offset,
                                                              "world", 4.0, k.ref) for k in links], [])
    out["relay-no-handles"] = (relay, [], links, [])
    block = [_agent(f"m{m:02d}", _walk(120, (1.0 * (m % 5), -1.2 * (m // 5)), stand=(40, 52) if m == 7 else None),
                    [(40, 52)] if m == 7 else [], times=np.arange(120.0) + (0.5 if m == 9 else 0.0))
             for m in range(15)]
    lead = block[0].rest
    turn = [H("m00", 0, lead[0], np.inf, "start"), H("m00", 60, lead[60], np.inf, "half"),
            H("m00", 119, lead[60] + [2.0, 0.0], np.inf, "turn")]
    group = G([a.path for a in block], 1.0, "/group")
    out["group"] = (block, turn, [], [group])
    out["group-one-handle"] = (block, turn[2:], [], [group])
    other = _agent("zz", _walk(120, (9.0, 0.0)))
    tie = [L("zz", 70, "m03", 70, np.array([2.0, 0.0]), "world", np.inf, "/tie")]
    out["groups-and-a-link"] = (block + [other], turn, tie, [group, G([a.path for a in block[:6]], 0.5, "/g2")])
    out["group-no-handles"] = (block + [other], [], tie, [group])
    return out


@pytest.mark.parametrize("name", list(_problems()))
def test_component_problems_match_the_reference_build(name):
    agents, handles, links, groups = _problems()[name]
    p = path_edit.ComponentProblem(agents, handles, links, groups, SETTINGS)
    # Key frames and the solve's vertices.
    keys = ref_keys(agents, handles, links, groups, SETTINGS)
    assert sorted(p.keys) == sorted(keys)
    for path, k in keys.items():
        np.testing.assert_array_equal(p.keys[path], k)
    full = {a.path: a for a in agents}
    reduced = [full[q].rest[keys[q]] if q in keys else full[q].rest for q in sorted(full)]
    np.testing.assert_array_equal(p.rest, np.concatenate(reduced))
    offsets = np.cumsum([0] + [len(r) for r in reduced])
    for h in handles:
        frame = int(np.searchsorted(keys[h.agent], h.frame)) if h.agent in keys else h.frame
        assert p.vertex(h.agent, h.frame) == offsets[sorted(full).index(h.agent)] + frame
    # Terms: every agent's chain, then each group's mesh at its shared sampled times.
    tri = [_solver.chain_terms(p.rest, int(lo), int(hi - lo), SETTINGS.min_baseline) for lo, hi in
           zip(offsets[:-1], offsets[1:])]
    tris, edgs = [t for t, _ in tri], [e for _, e in tri]
    partner = ref_frame_partners(p.rest, offsets, SETTINGS.min_baseline)
    for g in groups:
        inside = [sorted(full).index(m) for m in g.members]
        sampled = ref_sample_times(max(full[m].sample_times[0] for m in g.members),
                                   min(full[m].sample_times[-1] for m in g.members), SETTINGS.group_step)
        vert = []
        for m, i in zip(g.members, inside):
            t = full[m].sample_times[keys[m]]
            f = np.clip(np.searchsorted(t, sampled - 1e-9), 0, len(t) - 1)
            vert.append(np.where(np.abs(t[f] - sampled) < 1e-6, f + offsets[i], -1))
        vert = np.array(vert)[:, (np.array(vert) >= 0).all(axis=0)]
        t, e = ref_group_mesh(p.rest, vert, min(SETTINGS.group_neighbours, len(inside) - 1), partner)
        tris.append(t), edgs.append(e)
    np.testing.assert_array_equal(p.triangles, np.concatenate(tris))
    np.testing.assert_array_equal(p.edges, np.concatenate(edgs))
    # The freedom the constraints leave.
    translate, gauge, free = ref_freedom(p)
    assert p.translate_only == translate
    assert [(a, b) for a, b, _ in p.extra_links] == gauge
    assert any("free to move" in n for n in p.notes) == free
    # Solved paths: frames between keys follow them; headings as each agent's own call.
    result = p.solve()
    target_space = any(k.space == "target" for k in links)
    offsets_used = p._link_offsets({q: r.heading for q, r in result.agents.items()} if target_space else None)
    positions = np.asarray(_solver.path_edit_solve(p.data, p.handle_positions(), offsets_used).positions)
    if p.pinned is not None:
        ends = np.unique(p.link_vertex[:len(links)].ravel())
        positions = positions - (positions[ends] - p.rest[ends]).mean(axis=0)
    for i, path in enumerate(sorted(full)):
        a, r = full[path], result.agents[path]
        mine = positions[offsets[i]:offsets[i + 1]]
        ground = ref_expand(a, keys[path], mine) if path in keys else mine
        # Target-space offsets: the last solve used the offsets before the last (settled) update.
        np.testing.assert_allclose(r.ground, ground, rtol=0, atol=1e-9 if target_space else 1e-12)
        if r.translate_only:
            np.testing.assert_array_equal(r.heading, a.source_heading)
        elif result.solver == "rigid":
            assert np.ptp(r.heading - a.source_heading) < 1e-12
        else:
            # The component's headings, computed for all agents at once, are each agent's own.
            np.testing.assert_allclose(r.heading, path_edit.edited_heading(a, r.ground, r.range_turn, SETTINGS),
                                       rtol=0, atol=1e-12)


@pytest.mark.parametrize("start, end, expected", [
    (0.0, 48.0, [0, 12, 24, 36, 48]),            # the end on the grid
    (0.0, 45.0, [0, 12, 24, 36, 45]),            # the end after the grid: added
    (0.0, 40.0, [0, 12, 24, 40]),                # within half a step: it takes 36's place
    (3.0, 8.0, [3, 8]),
    (5.0, 5.0, [5]),
    (6.0, 5.0, []),
])
def test_group_sample_times_reach_the_end_of_the_shared_range(start, end, expected):
    np.testing.assert_allclose(path_edit.group_sample_times(start, end, 12.0), expected)
    np.testing.assert_allclose(ref_sample_times(start, end, 12.0), expected)


@pytest.mark.parametrize("start, end, step", [(0.0, 10.0, 0.0), (0.0, 10.0, -1.0), (0.0, np.inf, 1.0),
                                              (0.0, 10.0, np.nan)])
def test_group_sample_times_reject_a_bad_step_or_range(start, end, step):
    with pytest.raises(ValueError, match="positive step"):
        path_edit.group_sample_times(start, end, step)


def test_a_group_keeps_its_formation_to_the_end_of_a_range_off_the_sampling_grid():
    # 46 frames: regular samples at 0, 12, 24, 36; the mesh also joins the members at
    # frame 45, so pulling the lead's last frame sideways takes the group along to the end.
    # (Sampled at 0..36 only, the last frames moved apart by 14% of their spacing.)
    frames = 46
    agents = [_agent(f"/m{r}{c}", _walk(frames, (1.0 * c, -1.2 * r))) for r in range(2) for c in range(3)]
    lead = agents[0]
    handles = [path_edit.Handle(lead.path, 0, lead.rest[0], np.inf, "start"),
               path_edit.Handle(lead.path, frames - 1, lead.rest[-1] + [-3.0, 0.0], np.inf, "end")]
    group = path_edit.Group([a.path for a in agents], 1.0, "/group")
    result = path_edit.ComponentProblem(agents, handles, [], [group], SETTINGS).solve()
    source = np.array([a.rest for a in agents])
    edited = np.array([result.agents[a.path].ground for a in agents])
    change = np.nanmean(metrics.neighbour_distance_change(source, edited), axis=(1, 2))
    assert change[-1] < 0.08, change[-6:]


def _large_group(rows=6, cols=10, frames=500):
    """rows x cols members walking in a block, the front-left one turned left over the
    second half: 2,581 key vertices for 6 x 10 x 500 frames, enough for the supernodal
    factorization."""
    agents = [_agent(f"/m{r}{c}", _walk(frames, (1.0 * c, -1.2 * r))) for r in range(rows) for c in range(cols)]
    lead, half = agents[0], frames // 2
    handles = [path_edit.Handle(lead.path, 0, lead.rest[0], np.inf, "start"),
               path_edit.Handle(lead.path, half, lead.rest[half], np.inf, "half"),
               path_edit.Handle(lead.path, frames - 1, lead.rest[half] + [-1.4 / FPS * (frames - 1 - half), 0.0],
                                np.inf, "turn")]
    return agents, handles, path_edit.Group([a.path for a in agents], 1.0, "/group")


def test_a_large_group_is_ordered_by_position_and_time_without_changing_its_answer(monkeypatch):
    # The reference: the same problem without vertex times, factored in AMD order.
    agents, handles, group = _large_group()
    problem = path_edit.ComponentProblem(agents, handles, [], [group], SETTINGS)
    times = problem._vertex_times()
    assert times is not None and len(times) == len(problem.rest) > 2000
    result = problem.solve()
    assert result.step1.solver == "CHOLMOD supernodal (nested dissection)"
    monkeypatch.setattr(path_edit.ComponentProblem, "_vertex_times", lambda self: None)
    reference = path_edit.ComponentProblem(agents, handles, [], [group], SETTINGS).solve()
    assert reference.step1.solver == "CHOLMOD supernodal"
    for a in agents:
        np.testing.assert_allclose(result.agents[a.path].ground, reference.agents[a.path].ground, rtol=0, atol=1e-9)
    for h in handles:
        assert np.abs(result.agents[h.agent].ground[h.frame] - h.position).max() < 1e-9


def test_vertex_times_must_match_the_vertices():
    rest = _walk(10)
    with pytest.raises(ValueError, match="vertex times: expected 10, got 9"):
        _solver.path_edit_precompute(rest=rest, vertex_times=np.zeros(9))
    with pytest.raises(ValueError, match="vertex times must be finite"):
        _solver.path_edit_precompute(rest=rest, vertex_times=np.full(10, np.nan))


def test_a_group_in_blocks_apart_moves_as_one():
    # Two blocks of four, 10 m apart: each member's three nearest neighbours are in its own
    # block, so the nearest-neighbour mesh alone left the far block free (a singular system,
    # solved by QR, the far block moving wherever the least-squares answer put it). The
    # mesh now joins the blocks.
    frames = 200
    origins = [(0, 0), (1, 0), (0, -1.2), (1, -1.2), (10, 0), (11, 0), (10, -1.2), (11, -1.2)]
    agents = [_agent(f"/m{i}", _walk(frames, o)) for i, o in enumerate(origins)]
    lead, half = agents[0], frames // 2
    handles = [path_edit.Handle(lead.path, 0, lead.rest[0], np.inf, "start"),
               path_edit.Handle(lead.path, half, lead.rest[half], np.inf, "half"),
               path_edit.Handle(lead.path, frames - 1, lead.rest[half] + [-1.4 / FPS * (frames - 1 - half), 0.0],
                                np.inf, "turn")]
    group = path_edit.Group([a.path for a in agents], 1.0, "/group")
    result = path_edit.ComponentProblem(agents, handles, [], [group], SETTINGS).solve()
    assert not result.solver.startswith("SPQR") and not result.notes
    source = np.array([a.rest for a in agents])
    edited = np.array([result.agents[a.path].ground for a in agents])
    apart = lambda p: np.linalg.norm(p[4:].mean(axis=0) - p[:4].mean(axis=0), axis=1)   # noqa: E731
    assert np.abs(apart(edited) / apart(source) - 1).mean() < 0.03
    assert np.linalg.norm(edited[4:, -1] - source[4:, -1], axis=1).min() > 5.0   # it turned with the group


def test_a_group_whose_members_share_no_time_leaves_the_unheld_ones_alone():
    # No sampled time joins them: each member is its own body, and one nothing holds stays
    # where it is (the two used to be one body, and the solve failed).
    frames = 100
    a = _agent("/a", _walk(frames, (0.0, 0.0)))
    b = _agent("/b", _walk(frames, (2.0, 0.0)), times=np.arange(frames, dtype=np.float64) + 500.0)
    handles = [path_edit.Handle("/a", 0, a.rest[0], np.inf, "start"),
               path_edit.Handle("/a", frames - 1, a.rest[-1] + [1.0, 0.0], np.inf, "end")]
    result = path_edit.ComponentProblem([a, b], handles, [], [path_edit.Group(["/a", "/b"], 1.0, "/g")],
                                        SETTINGS).solve()
    np.testing.assert_array_equal(result.agents["/b"].ground, b.rest)
    np.testing.assert_allclose(result.agents["/a"].ground[-1], a.rest[-1] + [1.0, 0.0], atol=1e-9)

