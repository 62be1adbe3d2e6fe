"""Shape of a ground path: its length, and the local coordinates that a similarity transform keeps
(what a path edit preserves, and what measures how well it did).

Paths are ``(N, 2)`` ground points (or ``(N, 3)`` where said), in stage units.
"""
from __future__ import annotations

import numpy as np

__all__ = ["as_points", "path_length", "length_ratio", "local_coordinates", "shape_change"]


def as_points(points, name: str, dims=(2, 3)) -> np.ndarray:
    """``points`` as a float64 ``(N, d)`` array, ``d`` in ``dims``; a ValueError naming ``name`` else."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in dims:
        want = " or ".join(f"(N, {d})" for d in dims)
        raise ValueError(f"{name} must have shape {want}, got {p.shape}")
    return p


def path_length(points) -> float:
    """Length of the polyline through ``points`` ``(N, 2)`` or ``(N, 3)``; 0 for fewer than 2."""
    p = as_points(points, "points")
    if len(p) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def length_ratio(edited, source) -> float:
    """Distance travelled on the edited path over that of the source path.

    1 means the edit kept the distance travelled. A source that does not move gives 1.0 when the
    edited path does not move either and ``inf`` when it does.
    """
    le, ls = path_length(edited), path_length(source)
    if ls == 0.0:
        return 1.0 if le == 0.0 else float("inf")
    return le / ls


def local_coordinates(points, min_base: float = 0.0) -> np.ndarray:
    """Local coordinates ``(x, y)`` of each interior path point in its neighbour triangle.

    ``points`` is ``(N, 2)``; the result is ``(N - 2, 2)``, row ``k`` for point ``i = k + 1``:
    ``P_i = P_{i-1} + x (P_{i+1} - P_{i-1}) + y R90 (P_{i+1} - P_{i-1})`` with
    ``R90 = [[0, 1], [-1, 0]]``. These coordinates do not change under translation, rotation and
    uniform scale of the whole path. A triangle whose base ``|P_{i+1} - P_{i-1}|`` is not longer
    than ``min_base`` has no local frame: its row is NaN.
    """
    p = as_points(points, "points", dims=(2,))
    if len(p) < 3:
        return np.zeros((0, 2))
    d = p[2:] - p[:-2]
    e = p[1:-1] - p[:-2]
    rd = np.stack((d[:, 1], -d[:, 0]), axis=1)
    dd = np.einsum("ij,ij->i", d, d)
    ok = dd > float(min_base) ** 2
    safe = np.where(ok, dd, 1.0)
    along = np.einsum("ij,ij->i", e, d)
    across = np.einsum("ij,ij->i", e, rd)
    xy = np.stack((along, across), axis=1) / safe[:, None]
    xy[~ok] = np.nan
    return xy


def shape_change(source, edited, min_base: float | None = None) -> float:
    """RMS change of the interior points' local coordinates between two paths ``(N, 2)``.

    Zero for any similarity transform of the source (translation, rotation, uniform scale); a
    reflection or a bend is not. Points whose source triangle is degenerate (base not longer than
    ``min_base``; default 1e-9 of the source's bounding-box diagonal) carry no shape and are
    skipped. A point whose source triangle is fine but whose edited triangle collapsed has lost its
    shape entirely: the result is ``inf``. Returns 0 when no point is measurable.
    """
    s = as_points(source, "source", dims=(2,))
    e = as_points(edited, "edited", dims=(2,))
    if s.shape != e.shape:
        raise ValueError(f"source {s.shape} and edited {e.shape} must have the same shape")
    if min_base is None:
        diag = float(np.linalg.norm(np.ptp(s, axis=0))) if len(s) else 0.0
        min_base = 1e-9 * diag
    ls = local_coordinates(s, min_base)
    measured = np.isfinite(ls).all(axis=1)
    if not measured.any():
        return 0.0
    le = local_coordinates(e, 0.0)[measured]
    if not np.isfinite(le).all():
        return float("inf")
    diff = le - ls[measured]
    return float(np.sqrt(np.mean(np.einsum("ij,ij->i", diff, diff))))
