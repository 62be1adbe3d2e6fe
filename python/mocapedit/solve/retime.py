"""Time-map helpers around the solver's time warp (numpy).

- :func:`speed_matched_times`: the time map that keeps an agent's speed along an edited
  path that of its source clip (``MocapSolveSettings.matchSpeed``; section 4.2 of the
  deliverable: stretching a path without re-timing it makes the agent hurry and its feet
  slide).
- :func:`shot_times`: the shot times a warped clip is authored at.
"""
from __future__ import annotations

import numpy as np

#: Half-width (in frames) of the window over which path stretch is measured: the stretch
#: of single steps follows the sway of the root within a stride, which is not a change
#: of speed.
SPEED_WINDOW = 2


def _window_sums(values: np.ndarray, half: int) -> np.ndarray:
    """Sum of ``values`` over ``[i - half, i + half]`` (clipped to the array) for each i."""
    c = np.concatenate([[0.0], np.cumsum(values)])
    n = len(values)
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) + half + 1, 0, n)
    return c[hi] - c[lo]


def speed_matched_times(sample_times: np.ndarray, source_ground: np.ndarray, edited_ground: np.ndarray,
                        min_fraction: float, still: float, window: int = SPEED_WINDOW) -> np.ndarray:
    """(F,) shot times at which the edited path is travelled at the source speed.

    Each source interval is scaled by the ratio of edited to source path length over a
    window of ``2 * window + 1`` steps around it; intervals where the source stands still
    (less than ``still`` stage units travelled over the window) keep their length, and no
    interval shrinks below ``min_fraction`` of the source one. The first frame keeps its
    time.

    Args:
      sample_times: (F,) source times of the frames.
      source_ground: (F,2) source ground path.
      edited_ground: (F,2) edited ground path.
      min_fraction: smallest interval, as a fraction of the source interval.
      still: stage units below which the source counts as standing still.
    """
    times = np.asarray(sample_times, dtype=np.float64)
    if len(times) < 2:
        return times.copy()
    src = np.linalg.norm(np.diff(np.asarray(source_ground, dtype=np.float64), axis=0), axis=1)
    new = np.linalg.norm(np.diff(np.asarray(edited_ground, dtype=np.float64), axis=0), axis=1)
    src_w, new_w = _window_sums(src, window), _window_sums(new, window)
    moving = src_w > still
    ratio = np.ones_like(src_w)
    ratio[moving] = new_w[moving] / src_w[moving]
    intervals = np.diff(times) * np.maximum(ratio, min_fraction)
    return times[0] + np.concatenate([[0.0], np.cumsum(intervals)])


def shot_times(time_map: np.ndarray, frames=()) -> np.ndarray:
    """Sorted shot times to author a warped clip at.

    The shot's whole frames the clip covers, plus the times of the clip's first and last
    frames and of ``frames`` (those the constraints name) where these fall between whole
    frames, so that each of them plays exactly at its time.
    """
    tm = np.asarray(time_map, dtype=np.float64)
    whole = np.arange(np.ceil(tm[0] - 1e-9), np.floor(tm[-1] + 1e-9) + 1.0)
    keys = tm[np.unique(np.concatenate([[0, len(tm) - 1], np.asarray(frames, dtype=np.int64)]))]
    # A key within 1e-9 of a whole frame is that frame.
    keys = keys[np.abs(keys - np.round(keys)) > 1e-9]
    return np.union1d(whole, keys)
