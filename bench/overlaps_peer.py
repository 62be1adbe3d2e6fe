"""The peer of the collision detection in bench_collisions: a uniform grid over (time, cell)
in numpy, finding every pair of agents whose capsule clearance is below a reach at a sample.

It is what the inspection used before it shared the solve's detection (C++); it stays here
only to be timed against it.
"""
from __future__ import annotations

import numpy as np

#: Agent samples handled at once (memory bound for big crowds and long shots).
CHUNK_SAMPLES = 2_000_000

# Half of the 3x3 cell neighbourhood (the other half is the same pairs seen from the
# other cell); (0, 0) pairs a cell with itself.
_HALF_NEIGHBOURHOOD = ((0, 0), (1, 0), (1, 1), (0, 1), (-1, 1))


def _range_pairs(sorted_keys: np.ndarray, order: np.ndarray, query: np.ndarray):
    """For each query key, every sorted position with that key: (query index, point index)."""
    lo = np.searchsorted(sorted_keys, query, side="left")
    hi = np.searchsorted(sorted_keys, query, side="right")
    counts = hi - lo
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    qi = np.repeat(np.arange(len(query)), counts)
    starts = np.repeat(lo - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    return qi, order[starts + np.arange(total)]


def proximity(positions: np.ndarray, radii: np.ndarray, reach: float = 0.0,
              active: np.ndarray | None = None):
    """Every pair of active agents whose clearance is below ``reach`` at a time sample.

    Args:
      positions: #A by #T by 2 list of ground positions of each agent at each time sample
      radii: #A list of collision radii, stage units
      reach: clearance (stage units, >= 0) below which a pair is reported; 0 gives the
        overlaps only
      active: #A list of bools, agents taking part (default: all)
    Returns:
      (sample, a, b, clearance) #N lists, ordered by sample, then a, then b.
    """
    pos = np.asarray(positions, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    n_agents, n_samples = pos.shape[0], pos.shape[1] if pos.ndim == 3 else 0
    if pos.ndim != 3 or pos.shape[2] != 2 or radii.shape != (n_agents,):
        raise ValueError(f"positions must be #A by #T by 2 and radii #A, got {pos.shape} and {radii.shape}")
    if reach < 0:
        raise ValueError(f"reach must not be negative, got {reach}")
    idx = np.arange(n_agents) if active is None else np.flatnonzero(np.asarray(active, dtype=bool))
    empty = (*(np.zeros(0, np.int64),) * 3, np.zeros(0))
    if len(idx) < 2 or n_samples == 0:
        return empty
    pos, radii = pos[idx], radii[idx]
    cell = max(2.0 * float(radii.max()) + reach, 1e-12)
    chunk = max(1, CHUNK_SAMPLES // len(idx))
    found = []
    for first in range(0, n_samples, chunk):
        found.append(_proximity_chunk(pos[:, first:first + chunk], radii, reach, cell, first))
    sample, a, b, clearance = (np.concatenate(x) for x in zip(*found))
    order = np.lexsort((b, a, sample))
    return sample[order], idx[a[order]], idx[b[order]], clearance[order]


def _proximity_chunk(pos, radii, reach, cell, first):
    n_agents, n_samples = pos.shape[:2]
    flat = pos.transpose(1, 0, 2).reshape(-1, 2)          # sample-major
    agent = np.tile(np.arange(n_agents), n_samples)
    sample = np.repeat(np.arange(n_samples), n_agents)
    ok = np.all(np.isfinite(flat), axis=1)
    flat, agent, sample = flat[ok], agent[ok], sample[ok]
    ij = np.floor(flat / cell).astype(np.int64)
    ij -= ij.min(axis=0) - 1                              # room for the -1 neighbour
    nx, ny = int(ij[:, 0].max()) + 2, int(ij[:, 1].max()) + 2

    def key(ix, iy):
        return (sample * nx + ix) * ny + iy

    keys = key(ij[:, 0], ij[:, 1])
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]
    out = []
    for dx, dy in _HALF_NEIGHBOURHOOD:
        qi, pj = _range_pairs(sorted_keys, order, key(ij[:, 0] + dx, ij[:, 1] + dy))
        if dx == 0 and dy == 0:
            keep = agent[qi] < agent[pj]
            qi, pj = qi[keep], pj[keep]
        if len(qi) == 0:
            continue
        gap = np.linalg.norm(flat[qi] - flat[pj], axis=1) - radii[agent[qi]] - radii[agent[pj]]
        keep = gap < reach
        qi, pj, gap = qi[keep], pj[keep], gap[keep]
        a, b = agent[qi], agent[pj]
        out.append((sample[qi] + first, np.minimum(a, b), np.maximum(a, b), gap))
    if not out:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    return tuple(np.concatenate(x) for x in zip(*out))
