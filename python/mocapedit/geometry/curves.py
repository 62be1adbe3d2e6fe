"""Path curves: evaluating UsdGeom curves in numpy, and remapping a trajectory onto one.

An agent with ``mocap:pathCurve`` follows that curve (section 5.1 of the deliverable):
its source trajectory is split into a smooth centreline and the sway about it; the
centreline is straightened onto the curve, keeping the distance travelled on it from
frame to frame, and the sway is put back across the curve. The agent starts at the
curve's first point and walks along it; past the last point it carries on along the end
tangent. Frames of a stationary range move by one rigid motion (the one of the range's
first frame), so the range stays rigid.

Curves are evaluated densely into a polyline (:func:`evaluate`): BasisCurves of type
linear, or cubic with basis bezier, bspline or catmullRom (wrap nonperiodic, pinned or
periodic), and NurbsCurves (rational when pointWeights are authored). Only the first
curve of a batch is used. No USD here: the reader hands over the curve's attributes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import ground
from mocapedit.model.errors import prim_error

#: Polyline samples per curve segment (per knot span for NURBS).
SAMPLES_PER_SEGMENT = 32
#: Width (seconds) of the window that separates the centreline from the sway.
CENTRELINE_WINDOW_S = 1.0
#: Metres per second below which the centreline does not walk (it shuffles, turns on the spot,
#: sets off or stops): there it keeps the heading of the walk around it and its sideways
#: steps stay sideways; they ease back onto the curve over SETTLE_M metres of walking.
SLOW_M_S = 0.6
SETTLE_M = 2.0

_BASES = {  # cubic basis matrices: row-vector [1 t t^2 t^3] @ M @ [P0 P1 P2 P3]
    "bezier": np.array([[1, 0, 0, 0], [-3, 3, 0, 0], [3, -6, 3, 0], [-1, 3, -3, 1]], dtype=np.float64),
    "bspline": np.array([[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]], dtype=np.float64) / 6.0,
    "catmullRom": np.array([[0, 2, 0, 0], [-1, 0, 1, 0], [2, -5, 4, -1], [-1, 3, -3, 1]], dtype=np.float64) / 2.0,
}


def _cubic_segments(p: np.ndarray, basis: str, wrap: str) -> np.ndarray:
    """(S,4,3) control points of each cubic segment."""
    n = len(p)
    if basis == "bezier":
        if wrap == "periodic":
            if n < 3 or n % 3:
                raise ValueError(f"a periodic cubic bezier curve needs a multiple of 3 points, got {n}")
            q = np.concatenate([p, p[:1]])
        else:
            if n < 4 or (n - 4) % 3:
                raise ValueError(f"a cubic bezier curve needs 4, 7, 10, ... points, got {n}")
            q = p
        starts = np.arange(0, len(q) - 3, 3)
    else:
        if wrap == "periodic":
            q = np.concatenate([p, p[:3]])
        elif wrap == "pinned":
            q = np.concatenate([2 * p[:1] - p[1:2], p, 2 * p[-1:] - p[-2:-1]])
        else:
            if n < 4:
                raise ValueError(f"a cubic {basis} curve needs at least 4 points, got {n}")
            q = p
        starts = np.arange(0, len(q) - 3)
    return np.stack([q[starts + k] for k in range(4)], axis=1)


def _nurbs(p: np.ndarray, order: int, knots: np.ndarray, weights: np.ndarray | None) -> np.ndarray:
    n = len(p)
    if order < 2 or n < order:
        raise ValueError(f"a NURBS curve of order {order} needs at least {order} points, got {n}")
    if len(knots) != n + order:
        raise ValueError(f"{n} points of order {order} need {n + order} knots, got {len(knots)}")
    if np.any(np.diff(knots) < 0):
        raise ValueError("knots must not decrease")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
    if len(w) != n or np.any(w <= 0):
        raise ValueError("pointWeights must hold one positive weight per point")
    hw = np.concatenate([p * w[:, None], w[:, None]], axis=1)     # homogeneous points
    k = order - 1                                                  # degree
    lo, hi = knots[k], knots[n]
    spans = np.flatnonzero(np.diff(knots[k:n + 1]) > 0) + k
    out = []
    for s in spans:
        for u in np.linspace(knots[s], knots[s + 1], SAMPLES_PER_SEGMENT, endpoint=s == spans[-1]):
            d = hw[s - k:s + 1].copy()                              # de Boor
            for r in range(1, k + 1):
                for j in range(k, r - 1, -1):
                    i = s - k + j
                    den = knots[i + k + 1 - r] - knots[i]
                    a = 0.0 if den == 0 else (u - knots[i]) / den
                    d[j] = (1 - a) * d[j - 1] + a * d[j]
            out.append(d[k, :3] / d[k, 3])
    if not out or hi <= lo:
        raise ValueError("the knots leave no parameter range to evaluate")
    return np.array(out)


def evaluate(curve: dict, prim: str = "") -> np.ndarray:
    """(K,3) world-space polyline of the first curve of a reader curve record.

    Raises MocapEditError naming ``prim`` when the curve cannot be evaluated.
    """
    counts = np.asarray(curve["counts"], dtype=np.int64)
    points = np.asarray(curve["points"], dtype=np.float64)
    if counts.size == 0 or counts.min() < 1 or counts.sum() != len(points):
        raise prim_error(prim, f"curveVertexCounts {counts.tolist()} do not add up to the {len(points)} points",
                         "curveVertexCounts")
    p = points[:counts[0]]
    try:
        if curve["type"] == "NurbsCurves":
            orders = np.asarray(curve["order"], dtype=np.int64)
            knots = np.asarray(curve["knots"], dtype=np.float64)
            weights = curve.get("weights")
            local = _nurbs(p, int(orders[0]), knots[:counts[0] + orders[0]],
                           None if weights is None else np.asarray(weights)[:counts[0]])
        elif curve["curve_type"] == "linear" or len(p) < 3:
            local = p if curve["wrap"] != "periodic" else np.concatenate([p, p[:1]])
        else:
            basis = curve["basis"]
            if basis not in _BASES:
                raise prim_error(prim, f"basis '{basis}' is not supported (bezier, bspline, catmullRom)", "basis")
            seg = _cubic_segments(p, basis, curve["wrap"])
            t = np.linspace(0.0, 1.0, SAMPLES_PER_SEGMENT, endpoint=False)
            powers = np.stack([np.ones_like(t), t, t * t, t * t * t], axis=1) @ _BASES[basis]   # (T,4)
            local = np.einsum("tk,skc->stc", powers, seg).reshape(-1, 3)
            end = np.array([1.0, 1.0, 1.0, 1.0]) @ _BASES[basis] @ seg[-1]
            local = np.concatenate([local, end[None]])
    except ValueError as exc:
        raise prim_error(prim, f"cannot evaluate the path curve: {exc}", "points") from None
    m = np.asarray(curve["local_to_world"], dtype=np.float64)
    return local @ m[:3, :3] + m[3, :3]


@dataclass
class Remap:
    ground: np.ndarray            # (F,2) remapped ground path
    range_turn: np.ndarray        # (R,) rotation (radians) each stationary range was given


def _unit_tangents(poly: np.ndarray) -> np.ndarray:
    d = np.diff(poly, axis=0)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    return d / np.where(n > 0, n, 1.0)


def smooth(uv: np.ndarray, sigma_frames: float) -> np.ndarray:
    """Gaussian low-pass of a (F,2) path, reflecting about its end points."""
    f = len(uv)
    if f < 3 or sigma_frames <= 0:
        return uv.copy()
    r = int(min(np.ceil(3 * sigma_frames), f - 1))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_frames) ** 2)
    k /= k.sum()
    pad = np.concatenate([2 * uv[:1] - uv[r:0:-1], uv, 2 * uv[-1:] - uv[-2:-r - 2:-1]])
    return np.stack([np.convolve(pad[:, c], k, mode="valid") for c in (0, 1)], axis=1)


def _slow_frames(centre: np.ndarray, head: np.ndarray, arc: np.ndarray, fps: float, slow: float,
                 settle: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(heading, distance along, lateral offset) of each frame of a centreline where it moves
    slower than ``slow`` stage units per second (shuffling, turning on the spot, setting off):
    the heading is interpolated from the faster frames around (held before the first and
    after the last), the centreline's steps count along the curve only as far as they go that
    way, and the rest is a lateral offset that eases back to the curve over ``settle`` stage
    units of walking. Measured against its own tangents there, which point anywhere, the sway
    swung round with them (a start-walk-stop take drew loops on the curve), and a shuffle
    sideways was walked forward along the curve."""
    speed = np.linalg.norm(np.gradient(centre, axis=0), axis=1) * fps
    fast = speed >= slow
    if fast.all() or not fast.any():
        return head, arc, np.zeros(len(centre))
    h = np.unwrap(head)
    k = np.flatnonzero(fast)
    h = np.where(fast, h, np.interp(np.arange(len(h)), k, h[k]))
    step = np.diff(centre, axis=0)
    mid = 0.5 * (h[1:] + h[:-1])
    forward = np.where(fast[1:] & fast[:-1], np.diff(arc), step[:, 0] * np.cos(mid) + step[:, 1] * np.sin(mid))
    sideways = np.where(fast[1:] & fast[:-1], 0.0, step[:, 1] * np.cos(mid) - step[:, 0] * np.sin(mid))
    decay = np.exp(-np.abs(forward) / settle) if settle > 0 else np.zeros(len(forward))
    lateral = np.zeros(len(centre))
    for i in range(len(forward)):
        lateral[i + 1] = lateral[i] * decay[i] + sideways[i]
    return h, np.concatenate([[0.0], np.cumsum(forward)]), lateral


def remap(uv: np.ndarray, curve: np.ndarray, stationary: list[tuple[int, int]], fps: float,
          still: float, slow: float = 0.0, settle: float = 0.0) -> Remap:
    """Remaps a (F,2) ground trajectory onto a (K,2) ground polyline (see the module doc).

    ``stationary``: inclusive frame ranges moved rigidly; ``still``: ground steps (stage
    units) below which the centreline is said to stand still; ``slow`` (stage units per
    second, 0: none): frames where the centreline moves slower keep the heading of the walk
    around them, and their sideways steps stay sideways, easing back to the curve over
    ``settle`` stage units of walking (see ``SLOW_M_S``, ``SETTLE_M``).
    """
    uv = np.asarray(uv, dtype=np.float64)
    centre = smooth(uv, CENTRELINE_WINDOW_S * fps / 2.0)
    head = _solver.tangent_headings(np.ascontiguousarray(centre), [], np.zeros(0), still)
    arc = _solver.cumulative_arc_length(np.ascontiguousarray(centre))
    lateral = np.zeros(len(uv))
    if slow > 0 and len(centre) > 2:
        head, arc, lateral = _slow_frames(centre, head, arc, fps, slow, settle)
    tangent = np.stack([np.cos(head), np.sin(head)], axis=1)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    rel = uv - centre
    along = np.einsum("ij,ij->i", rel, tangent)
    across = np.einsum("ij,ij->i", rel, normal) + lateral
    s = arc + along

    # The curve by arc length, with its tangent angle interpolated so normals turn smoothly.
    # Steps below the rounding of the evaluation (a B-spline of coincident points comes out
    # as a few ulps of noise, pointing anywhere) are no steps.
    tiny = 1e-9 * max(1.0, float(np.abs(curve).max(initial=0.0)))
    keep = np.concatenate([[True], np.linalg.norm(np.diff(curve, axis=0), axis=1) > tiny])
    poly = curve[keep]
    if len(poly) < 2:
        raise ValueError("the path curve has no length")
    cs = _solver.cumulative_arc_length(np.ascontiguousarray(poly))
    seg_angle = np.unwrap(np.arctan2(*_unit_tangents(poly)[:, ::-1].T))
    mids = 0.5 * (cs[1:] + cs[:-1])

    def frame_at(sv):
        sv = np.asarray(sv, dtype=np.float64)
        ang = np.interp(sv, mids, seg_angle)
        before, after = sv < 0, sv > cs[-1]
        pos = np.stack([np.interp(sv, cs, poly[:, c]) for c in (0, 1)], axis=-1)
        t0, t1 = _unit_tangents(poly[:2])[0], _unit_tangents(poly[-2:])[0]
        pos[before] = poly[0] + sv[before, None] * t0
        pos[after] = poly[-1] + (sv[after] - cs[-1])[:, None] * t1
        return pos, ang

    pos, ang = frame_at(s)
    out = pos + across[:, None] * np.stack([-np.sin(ang), np.cos(ang)], axis=1)
    turns = []
    for first, last in stationary:
        # One rigid motion for the whole range: the one that carries its first frame.
        turn = float(ang[first] - head[first])
        c, sn = np.cos(turn), np.sin(turn)
        rot = np.array([[c, sn], [-sn, c]])   # row vectors: p @ rot turns by +turn
        out[first:last + 1] = out[first] + (uv[first:last + 1] - uv[first]) @ rot
        turns.append(turn)
    return Remap(ground=out, range_turn=np.array(turns, dtype=np.float64))


def ground_polyline(curve: dict, prim: str, up_axis: str) -> np.ndarray:
    """(K,2) ground polyline of a path curve."""
    return ground.to_ground(evaluate(curve, prim), up_axis)
