"""The time warp of time and sync constraints (sections 5.4.2.3, 5.4.2.4, 5.4.2.6 of the
deliverable): a keyword-argument wrapper over the solver's Laplacian time warp
(``_solver.time_warp``, see ``solver/include/mocapedit/time_warp.h``).
"""
from __future__ import annotations

import numpy as np

from mocapedit import _solver

#: Raised when hard constraints contradict each other or the minimum interval (an
#: InvalidInput, so a ValueError); its attributes say which: ``kind`` ('cycle' or
#: 'backwards'), ``time_constraints`` and ``sync_constraints`` (indices), ``mismatch``,
#: ``agent``, ``frames``, ``gap``, ``minimum``.
TimeWarpConflict = _solver.TimeWarpConflict


def warp(*, rest_times: list[np.ndarray], min_intervals: list[np.ndarray], min_interval_fraction: float,
         time_frames: np.ndarray, time_hard: np.ndarray, time_weights: np.ndarray, times: np.ndarray,
         sync_frames: np.ndarray, sync_hard: np.ndarray, sync_weights: np.ndarray,
         offsets: np.ndarray) -> _solver.TimeWarpResult:
    """Warps every agent's time map so the constraints hold.

    Args:
      rest_times: per agent, (F_a,) increasing shot times (the time map at rest)
      min_intervals: per agent, (F_a - 1,) smallest intervals allowed (time codes)
      min_interval_fraction: smallest warped interval as a fraction of the rest one, in (0, 1]
      time_frames: (T,2) int32 (agent index, frame) of each time constraint
      time_hard, time_weights, times: (T,) bool, soft weights, shot times of the time constraints
      sync_frames: (S,4) int32 (agent, frame, target, target frame) of each sync constraint
      sync_hard, sync_weights, offsets: (S,) bool, soft weights, time offsets of the sync constraints

    Returns:
      TimeWarpResult: ``time_maps`` (per agent (F_a,)), ``time_residuals`` (T,), ``sync_residuals``
      (S,), ``min_interval`` (A,), ``min_enforced`` (A,), ``solver`` (A,) 'rest' | 'LDLT' | 'SPQR fallback'

    Raises:
      TimeWarpConflict: hard constraints contradict each other or the minimum interval.
    """
    return _solver.time_warp(rest_times=rest_times, time_frames=time_frames, time_hard=time_hard,
                             time_weights=time_weights, times=times, sync_frames=sync_frames, sync_hard=sync_hard,
                             sync_weights=sync_weights, offsets=offsets,
                             min_interval_fraction=min_interval_fraction, min_intervals=min_intervals)
