"""The two-step ARAP path solve written with scipy.sparse: the peer of ``bench_path``.

Same terms as ``mocapedit._solver.path_edit_*`` (triangles, edges, hard and soft handles
and links; no rigid ranges), the textbook way: real 2N unknowns, hard constraints by
Lagrange multipliers, the KKT system of the normal equations factored by SuperLU.
``PeerProblem`` factors both steps once; ``solve`` re-solves for new handle positions.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla


def _complex_rows(rows, cols, vals, m, n):
    """Real 2m x 2n matrix of a complex m x n one given as COO triplets."""
    rows, cols, vals = np.asarray(rows), np.asarray(cols), np.asarray(vals, dtype=complex)
    r = np.concatenate([2 * rows, 2 * rows, 2 * rows + 1, 2 * rows + 1])
    c = np.concatenate([2 * cols, 2 * cols + 1, 2 * cols, 2 * cols + 1])
    v = np.concatenate([vals.real, -vals.imag, vals.imag, vals.real])
    return sp.csr_matrix((v, (r, c)), shape=(2 * m, 2 * n))


class PeerProblem:
    def __init__(self, rest, triangles, triangle_weights, edges, edge_weights, handles, handle_weights,
                 links=None, link_weights=None):
        self.rest = np.asarray(rest, dtype=np.float64)
        n = len(self.rest)
        z = self.rest[:, 0] + 1j * self.rest[:, 1]
        t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        tw = np.sqrt(np.asarray(triangle_weights, dtype=np.float64))
        c = (z[t[:, 0]] - z[t[:, 1]]) / (z[t[:, 2]] - z[t[:, 1]])
        m = len(t)
        rows = np.repeat(np.arange(m), 3)
        cols = t.ravel()
        vals = (np.stack([np.ones(m), c - 1, -c], axis=1) * tw[:, None]).ravel()
        self.handles = np.asarray(handles, dtype=np.int64)
        hw = np.asarray(handle_weights, dtype=np.float64)
        self.links = np.zeros((0, 2), np.int64) if links is None else np.asarray(links, np.int64).reshape(-1, 2)
        lw = np.zeros(0) if link_weights is None else np.asarray(link_weights, dtype=np.float64)
        self.hard_h, self.soft_h = np.flatnonzero(np.isinf(hw)), np.flatnonzero(np.isfinite(hw) & (hw > 0))
        self.hard_l, self.soft_l = np.flatnonzero(np.isinf(lw)), np.flatnonzero(np.isfinite(lw) & (lw > 0))
        self.sh, self.sl = np.sqrt(hw[self.soft_h]), np.sqrt(lw[self.soft_l])
        # Soft rows after the triangles (step 1) or edges (step 2): handles, then links.
        soft_rows, soft_cols, soft_vals = [], [], []
        for k, h in enumerate(self.soft_h):
            soft_rows.append(k), soft_cols.append(self.handles[h]), soft_vals.append(self.sh[k])
        base = len(self.soft_h)
        for k, l in enumerate(self.soft_l):
            a, b = self.links[l]
            soft_rows += [base + k, base + k]
            soft_cols += [a, b]
            soft_vals += [self.sl[k], -self.sl[k]]
        nsoft = base + len(self.soft_l)
        a1 = _complex_rows(np.concatenate([rows, np.asarray(soft_rows, dtype=np.int64) + m]),
                           np.concatenate([cols, soft_cols]), np.concatenate([vals, soft_vals]), m + nsoft, n)
        e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        ew = np.sqrt(np.asarray(edge_weights, dtype=np.float64))
        me = len(e)
        self.edges, self.ew, self.rest_len = e, ew, np.abs(z[e[:, 1]] - z[e[:, 0]])
        a2 = _complex_rows(np.concatenate([np.repeat(np.arange(me), 2), np.asarray(soft_rows, dtype=np.int64) + me]),
                           np.concatenate([e[:, ::-1].ravel(), soft_cols]),
                           np.concatenate([(np.stack([ew, -ew], axis=1)).ravel(), soft_vals]), me + nsoft, n)
        # Hard constraints C x = d.
        crow, ccol, cval = [], [], []
        for k, h in enumerate(self.hard_h):
            crow.append(k), ccol.append(self.handles[h]), cval.append(1.0)
        for k, l in enumerate(self.hard_l):
            a, b = self.links[l]
            r = len(self.hard_h) + k
            crow += [r, r]
            ccol += [a, b]
            cval += [1.0, -1.0]
        nc = len(self.hard_h) + len(self.hard_l)
        cm = _complex_rows(crow, ccol, cval, nc, n)
        self.a1, self.a2, self.m1, self.m2 = a1, a2, m, me
        self.lu1 = sla.splu(sp.bmat([[a1.T @ a1, cm.T], [cm, None]], format="csc"))
        self.lu2 = sla.splu(sp.bmat([[a2.T @ a2, cm.T], [cm, None]], format="csc"))
        self.n = n

    def _rhs(self, a, rows, targets, hp, lo):
        """Right-hand side of the KKT system for row targets (complex) of the shape rows."""
        soft = np.concatenate([hp[self.soft_h] * self.sh, lo[self.soft_l] * self.sl]) if len(hp) else \
            np.zeros(0, complex)
        t = np.concatenate([targets, soft])
        tr = np.empty(2 * len(t))
        tr[0::2], tr[1::2] = t.real, t.imag
        d = np.concatenate([hp[self.hard_h], lo[self.hard_l]])
        dr = np.empty(2 * len(d))
        dr[0::2], dr[1::2] = d.real, d.imag
        return np.concatenate([a.T @ tr, dr])

    def solve(self, handle_positions, link_offsets=None) -> np.ndarray:
        hp = np.asarray(handle_positions, dtype=np.float64).reshape(-1, 2)
        hp = hp[:, 0] + 1j * hp[:, 1]
        lo = np.zeros(0, complex) if link_offsets is None else \
            np.asarray(link_offsets, dtype=np.float64).reshape(-1, 2) @ np.array([1.0, 1j])
        x1 = self.lu1.solve(self._rhs(self.a1, None, np.zeros(self.m1, complex), hp, lo))[:2 * self.n]
        x1 = x1[0::2] + 1j * x1[1::2]
        self.shape = np.stack([x1.real, x1.imag], axis=1)
        e = self.edges
        d = x1[e[:, 1]] - x1[e[:, 0]]
        target = np.where(np.abs(d) > 0, d / np.where(np.abs(d) > 0, np.abs(d), 1) * self.rest_len, 0) * self.ew
        x2 = self.lu2.solve(self._rhs(self.a2, None, target, hp, lo))[:2 * self.n]
        return np.stack([x2[0::2], x2[1::2]], axis=1)
