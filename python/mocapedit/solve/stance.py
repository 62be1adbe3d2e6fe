"""Root motion that turns between steps and pivots on the planted foot (numpy, no USD).

A path edit moves the body as one rigid piece: each frame the source pose is turned about the
root by the edit's turn and carried onto the edited path. A planted foot then slides by
whatever that motion does to it beyond the source's own motion: the turn swings it about the
hips (a lever of a foot's length or more), and any change of speed or sideways step the path
asks for carries it along. Measured by forward kinematics on the collision scenes, the turn
made 66-89% of the extra slide, and most of it fell while both feet were down, where no move of
the whole body can hold both.

People turn between steps, on the foot that bears them. :func:`pivot` does the same with the
rigid motion of each frame, and nothing else:

- **The turn waits for a free foot.** While both feet are planted the edit's turn is held; over
  the next stretch with one foot or none down it catches up, so that it is the edit's turn
  again at the end of that stretch (:func:`gated_turn`). The body turns as much and as far as
  before, only at other moments. A body that leaves a stationary range (or a pin) on both feet
  takes the turn the edit gives it there over its first steps.
- **The body pivots on the planted foot.** A small shift of the root, added to the edited path,
  makes the planted feet move as they do in the source (the least-squares shift of
  :func:`shifts`, small everywhere, paid back where no foot is planted, and zero at the frames
  the artist fixed).

Frames the artist fixed (pinned frames, relative constraints' frames, stationary ranges) keep
the edit's path and turn exactly. Lengths are in stage units, turns in radians.
"""
from __future__ import annotations

import numpy as np

__all__ = ["EASE_SECONDS", "AIR_WEIGHT", "MAX_SPEEDUP", "STEP_TURN_RATE", "CATCH_UP_SECONDS", "BATCH", "gated_turn",
           "gated_turns", "shifts", "pivot", "tridiagonal"]

#: The shift pays itself back over about this long (seconds): the weight that keeps it small.
EASE_SECONDS = 2.0
#: The turn waits through double support fully where it then turns at most this many times as
#: fast as the edit does (a walk's double support is a fifth of its steps or less: 1.25), less
#: and less up to twice that, and not at all beyond: where both feet stay planted longer
#: (standing, shuffling on the spot) it turns as the edit does.
MAX_SPEEDUP = 2.0
#: A turn that a body leaving a fixed frame on both feet would take on them is shared by the
#: steps after it, as many as keep it this slow on average (radians per second: a quarter turn a
#: second, a brisk walker's turn; its eased peak stays far below a spin) ...
STEP_TURN_RATE = np.pi / 2
#: ... within this long (seconds).
CATCH_UP_SECONDS = 1.5
#: Frames of the agents pivoted together, at most (a bound on the arrays a batch makes: 256
#: agents of 240 frames; one agent at least, however long its clip).
BATCH = 256 * 240
#: Weight of the shift's motion where no foot is planted, against 1 where one is: a body in the
#: air (a run's flight) takes the shift back there first.
AIR_WEIGHT = 0.05


def _rotate(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(...,2) vectors turned counter-clockwise by (...) angles (broadcast)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def gated_turn(turn: np.ndarray, double: np.ndarray, fixed: np.ndarray, frame_seconds: float = 0.0) -> np.ndarray:
    """(F,) the edit's turn of each frame held while both feet are planted (``double``, (F,)
    bool) and caught up over the next stretch of frames that are not, so that it equals ``turn``
    at the end of each such stretch, at the first and last frame and at every ``fixed`` frame.
    Between two such frames the turn goes from the one's to the other's as the free frames pass,
    easing in and out (a half cosine), so that it never starts or stops within a frame; a turn
    taken so already is returned as it is. Where that would turn more than :data:`MAX_SPEEDUP`
    times as fast as the edit, the turn waits less, in proportion, and from twice that not at
    all: it turns as the edit does (a gait near the limit then waits as much at any frame rate).

    A body that leaves a fixed frame (the end of a stationary range, a pin) on both feet would
    otherwise turn on them there, as the edit turns it on its way off: that turn is shared
    evenly by the stretches off double support that follow instead, as many as it takes (within
    :data:`CATCH_UP_SECONDS`, up to the next fixed frame) to turn no faster than
    :data:`STEP_TURN_RATE` on average (``frame_seconds``: seconds per frame; 0 leaves it out).
    :func:`gated_turns` does the same for many agents at once."""
    return gated_turns(np.asarray(turn, dtype=np.float64)[None], np.asarray(double, dtype=bool)[None],
                       np.asarray(fixed, dtype=bool)[None], np.array([frame_seconds], dtype=np.float64))[0]


def gated_turns(turn: np.ndarray, double: np.ndarray, fixed: np.ndarray, frame_seconds: np.ndarray) -> np.ndarray:
    """:func:`gated_turn` of (B,F) turns, double supports and fixed frames of B agents with as
    many frames each, and (B,) seconds per frame."""
    turn = np.asarray(turn, dtype=np.float64)
    count, n = turn.shape
    if n < 3:
        return turn.copy()
    free = ~np.asarray(double, dtype=bool)
    progress = np.zeros((count, n))
    progress[:, 1:] = np.cumsum(free[:, 1:], axis=1)
    ends = free.copy()                                  # last frame of each stretch off double support
    ends[:, :-1] &= ~free[:, 1:]
    hard = np.asarray(fixed, dtype=bool).copy()
    hard[:, [0, -1]] = True
    sync = ends | hard
    frames = np.arange(n)
    # Each frame lies between the last sync frame at or before it (a) and the first after it (b);
    # the last frame, between the sync frame before it and itself.
    a = np.maximum.accumulate(np.where(sync, frames, -1), axis=1)
    later = np.full((count, n), n)
    later[:, :-1] = np.where(sync[:, 1:], frames[1:], n)
    b = np.minimum.accumulate(later[:, ::-1], axis=1)[:, ::-1]
    a[:, -1], b[:, -1] = a[:, -2], n - 1

    def at(values, index):
        return np.take_along_axis(values, index, axis=1)

    span = at(progress, b) - at(progress, a)
    speedup = (b - a) / np.maximum(span, 1e-12)
    wait = np.clip(2.0 - speedup / MAX_SPEEDUP, 0.0, 1.0)
    share = (progress - at(progress, a)) / np.maximum(span, 1e-12)
    eased = 0.5 - 0.5 * np.cos(np.pi * np.clip(share, 0.0, 1.0))
    start = at(turn, a)
    out = turn + wait * (start + (at(turn, b) - start) * eased - turn)
    # Stretches that start at a fixed frame and wait less than fully: shared by the steps after.
    slow = sync & hard & (frames < n - 1) & (speedup > MAX_SPEEDUP) & (np.asarray(frame_seconds)[:, None] > 0)
    for row in np.flatnonzero(slow.any(axis=1)):
        _share_off_fixed(out[row], turn[row], progress[row], hard[row], np.flatnonzero(sync[row]),
                         float(frame_seconds[row]))
    return out


def _share_off_fixed(out: np.ndarray, turn: np.ndarray, progress: np.ndarray, hard: np.ndarray,
                     sync: np.ndarray, frame_seconds: float) -> None:
    """In place, one agent's ``out`` (:func:`gated_turns`): the turn a body leaving a fixed frame
    on both feet would take on them, shared by the stretches off double support after it."""
    pairs = len(sync) - 1
    span = np.diff(progress[sync])
    slow = np.flatnonzero(~(span * MAX_SPEEDUP >= np.diff(sync)) & hard[sync[:-1]])
    longest = CATCH_UP_SECONDS / frame_seconds
    after = -1
    for i in slow:
        if i < after:
            continue
        first = sync[i]
        for j in range(i + 1, pairs + 1):
            last = sync[j]
            if last - first > longest:
                break
            steps = progress[last] - progress[first]
            if j > i + 1 and steps > 0 and abs(turn[last] - turn[first]) <= STEP_TURN_RATE * steps * frame_seconds:
                share = (progress[first:last + 1] - progress[first]) / steps
                out[first:last + 1] = turn[first] + (turn[last] - turn[first]) * (0.5 - 0.5 * np.cos(np.pi * share))
                after = j
                break
            if hard[last]:
                break


def tridiagonal(lower: np.ndarray, diag: np.ndarray, upper: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solves a batch of tridiagonal systems (Thomas algorithm): (B,N) ``lower[:, i]`` couples row
    i to unknown i-1, ``upper[:, i]`` to i+1, (B,N,K) right-hand sides; the matrices must be
    diagonally dominant (no pivoting)."""
    n = diag.shape[1]
    c = np.zeros_like(diag)
    d = np.zeros_like(rhs)
    c[:, 0] = upper[:, 0] / diag[:, 0]
    d[:, 0] = rhs[:, 0] / diag[:, 0, None]
    for i in range(1, n):
        m = diag[:, i] - lower[:, i] * c[:, i - 1]
        c[:, i] = upper[:, i] / m
        d[:, i] = (rhs[:, i] - lower[:, i, None] * d[:, i - 1]) / m[:, None]
    x = np.empty_like(d)
    x[:, -1] = d[:, -1]
    for i in range(n - 2, -1, -1):
        x[:, i] = d[:, i] - c[:, i, None] * x[:, i + 1]
    return x


def _slide_steps(source: np.ndarray, edited: np.ndarray, turn: np.ndarray, feet: np.ndarray,
                 planted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((...,F-1,2) the root shift from each frame to the next that makes the feet planted over
    both move as they do in the source (the mean over them), (...,F-1) whether a foot is on the
    ground at either frame: a step from one foot's contact to the other's, with no frame that
    both are down, is no flight). Leading axes (...) are agents."""
    lever = feet - source[..., None, :]                                         # (...,F,L,2)
    moved = _rotate(lever, turn[..., None]) + edited[..., None, :]              # where the edit puts the feet
    wanted = _rotate(feet[..., 1:, :, :] - feet[..., :-1, :, :], turn[..., 1:, None])  # the source's own motion, turned
    extra = (moved[..., 1:, :, :] - moved[..., :-1, :, :]) - wanted
    both = planted[..., 1:, :] & planted[..., :-1, :]                           # (...,F-1,L)
    count = both.sum(axis=-1)
    step = -(extra * both[..., None]).sum(axis=-2) / np.maximum(count, 1)[..., None]
    return step, planted[..., 1:, :].any(axis=-1) | planted[..., :-1, :].any(axis=-1)


def shifts(steps: list[np.ndarray], planted: list[np.ndarray], fixed: list[np.ndarray],
           frame_seconds: list[float], ease_seconds: float = EASE_SECONDS) -> list[np.ndarray]:
    """Per agent, the (F,2) root shift ``e`` that minimises

        sum_t w_t |e[t+1] - e[t] - steps[t]|^2 + (dt / ease_seconds)^2 sum_t |e[t]|^2

    with ``e = 0`` on its ``fixed`` frames; ``w_t`` is 1 where a foot is planted over the step
    (``planted``, (F-1,) bool), :data:`AIR_WEIGHT` where none is. Agents are solved together,
    padded to the longest."""
    count = len(steps)
    if not count:
        return []
    n = max(len(f) for f in fixed)
    w = np.zeros((count, n))
    s = np.zeros((count, n, 2))
    lam = np.zeros((count, 1))
    hold = np.ones((count, n), dtype=bool)
    for a, (step, on, fix, dt) in enumerate(zip(steps, planted, fixed, frame_seconds)):
        f = len(fix)
        w[a, :f - 1] = np.where(on, 1.0, AIR_WEIGHT)
        s[a, :f - 1] = step
        hold[a, :f] = fix
        lam[a] = (dt / ease_seconds) ** 2
    before = np.concatenate([np.zeros((count, 1)), w[:, :-1]], axis=1)   # w_{t-1}
    diag = before + w + lam
    lower, upper = -before, -w.copy()
    rhs = before[..., None] * np.concatenate([np.zeros((count, 1, 2)), s[:, :-1]], axis=1) - w[..., None] * s
    diag[hold], lower[hold], upper[hold], rhs[hold] = 1.0, 0.0, 0.0, 0.0
    e = tridiagonal(lower, diag, upper, rhs)
    return [e[a, :len(f)] for a, f in enumerate(fixed)]


def pivot(source: list[np.ndarray], edited: list[np.ndarray], turn: list[np.ndarray], feet: list[np.ndarray],
          planted: list[np.ndarray], fixed: list[np.ndarray],
          frame_seconds: list[float], ease_seconds: float = EASE_SECONDS) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per agent, (ground (F,2), turn (F,)): the edited path and the edit's turn of each frame
    with the turn taken between steps and the body pivoting on its planted feet.

    Args (one entry per agent):
      source, edited: (F,2) source and edited root ground positions
      turn: (F,) the edit's turn of each frame (edited heading minus source heading)
      feet: (F,L,2) each leg's planted point on the ground in the source (ankle and toe between)
      planted: (F,L) bool, the leg's foot contacts in the source
      fixed: (F,) bool, frames that keep the edited path and turn exactly
      frame_seconds: seconds between two of the agent's frames
      ease_seconds: how long the shift takes to pay itself back (:func:`shifts`)
    """
    count = len(source)
    turns: list = [None] * count
    steps: list = [None] * count
    on: list = [None] * count
    # Agents with as many frames are taken together, a batch at a time.
    by_length: dict[int, list[int]] = {}
    for i, th in enumerate(turn):
        by_length.setdefault(len(th), []).append(i)
    for frames, rows in by_length.items():
        size = max(1, BATCH // max(frames, 1))
        for first in range(0, len(rows), size):
            batch = rows[first:first + size]

            def stacked(values, dtype=np.float64):
                return np.stack([np.asarray(values[i], dtype=dtype) for i in batch])

            pl = stacked(planted, bool)
            gated = gated_turns(stacked(turn), pl.all(axis=-1), stacked(fixed, bool),
                                np.array([frame_seconds[i] for i in batch], dtype=np.float64))
            step, any_planted = _slide_steps(stacked(source), stacked(edited), gated, stacked(feet), pl)
            for k, i in enumerate(batch):
                turns[i], steps[i], on[i] = gated[k], step[k], any_planted[k]
    return [(ed + e, th) for ed, e, th in zip(edited, shifts(steps, on, fixed, frame_seconds, ease_seconds), turns)]
