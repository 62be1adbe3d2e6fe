"""Overlaps between agents' collision capsules, found on sampled ground positions.

An inspection measure (what is left to look at after a solve, or on any stage), not a
solve: agents are vertical capsules standing on the ground, so two agents overlap at a
time sample when the distance between their ground positions is below the sum of their
radii. The pairs come from the solve's own detection (:func:`mocapedit.solve.collisions.detect_at`,
a grid per sample), so the inspection and the solve count overlaps the same way.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit.solve import collisions


@dataclass
class Proximity:
    """Pairs of agents closer than ``reach`` at some time sample, one row per (pair, sample).

    Attributes:
      sample: #N list of time sample indices
      a, b: #N lists of agent indices, a < b
      clearance: #N list of distances minus the two radii (negative: overlap), stage units
    """
    sample: np.ndarray
    a: np.ndarray
    b: np.ndarray
    clearance: np.ndarray

    def overlapping(self) -> "Proximity":
        keep = self.clearance < 0.0
        return Proximity(self.sample[keep], self.a[keep], self.b[keep], self.clearance[keep])

    def __len__(self) -> int:
        return int(self.sample.shape[0])


def proximity(positions: np.ndarray, radii: np.ndarray, reach: float = 0.0,
              active: np.ndarray | None = None) -> Proximity:
    """Every pair of active agents whose clearance is below ``reach`` at a time sample.

    Args:
      positions: #A by #T by 2 list of ground positions of each agent at each time sample
        (non-finite: the agent is absent at that sample)
      radii: #A list of collision radii, stage units (> 0 for the active agents)
      reach: clearance (stage units, >= 0) below which a pair is reported; 0 gives the
        overlaps only
      active: #A list of bools, agents taking part (default: all)
    Returns:
      a :class:`Proximity`, ordered by sample, then a, then b.
    """
    pos = np.asarray(positions, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    n_agents = pos.shape[0]
    if pos.ndim != 3 or pos.shape[2] != 2 or radii.shape != (n_agents,):
        raise ValueError(f"positions must be #A by #T by 2 and radii #A, got {pos.shape} and {radii.shape}")
    if reach < 0:
        raise ValueError(f"reach must not be negative, got {reach}")
    on = np.ones(n_agents, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    present = np.all(np.isfinite(pos), axis=2) & on[:, None]
    by_sample = np.ascontiguousarray(np.where(present[..., None], pos, 0.0).transpose(1, 0, 2))
    found = [_rows(by_sample, radii, reach, first, end, idx) for first, end, idx in collisions.sample_runs(present)]
    if not found:
        return Proximity(*(np.zeros(0, np.int64),) * 3, np.zeros(0))
    sample, a, b = (np.concatenate(x) for x in zip(*found))
    order = np.lexsort((b, a, sample))
    a, b, sample = a[order], b[order], sample[order]
    return Proximity(sample, a, b, collisions.ground_clearances(by_sample, radii, a, b, sample))


def _rows(by_sample, radii, reach, first, end, idx):
    """(sample, a, b) of the pairs of agents ``idx`` closer than ``reach`` at samples
    ``first .. end-1`` of #T by #A by 2 positions: the detection's intervals (below the reach,
    its near intervals), one row per sample."""
    # Every capsule of the same height on one ground: the clearance is the ground distance
    # minus the radii.
    height = np.full(len(idx), 2.0 * float(radii[idx].max()))
    found = collisions.detect_at(np.ascontiguousarray(by_sample[first:end, idx]), radii[idx], height, 0.0,
                                 watch=reach)
    runs = found if reach <= 0.0 else found.near
    counts = (runs.last - runs.first + 1).astype(np.int64)
    sample = np.repeat(runs.first.astype(np.int64), counts) + np.arange(int(counts.sum())) \
        - np.repeat(np.cumsum(counts) - counts, counts)
    return first + sample, idx[np.repeat(runs.agent_a, counts)], idx[np.repeat(runs.agent_b, counts)]


def worst_per_pair(found: Proximity) -> Proximity:
    """One row per agent pair: the sample where its clearance is smallest."""
    if len(found) == 0:
        return found
    order = np.lexsort((found.clearance, found.b, found.a))
    a, b = found.a[order], found.b[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = (a[1:] != a[:-1]) | (b[1:] != b[:-1])
    pick = order[first]
    return Proximity(found.sample[pick], found.a[pick], found.b[pick], found.clearance[pick])


def min_clearance(found: Proximity, n_agents: int) -> np.ndarray:
    """#A list: each agent's smallest clearance among the pairs found (inf when none)."""
    out = np.full(n_agents, np.inf)
    np.minimum.at(out, found.a, found.clearance)
    np.minimum.at(out, found.b, found.clearance)
    return out
