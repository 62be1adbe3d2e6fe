"""Compare USD layers field by field with float tolerances.

Files written on one machine are compared with files written on another only through
this module: the last bit of a sin() or a quaternion may differ between CPUs, which is
no reason to call a layer different. Exact bytes are compared only for determinism
within one run on one machine.
"""
from __future__ import annotations

import numpy as np
from pxr import Sdf

ATOL = 1e-5
RTOL = 1e-6


def layer_values(layer: Sdf.Layer) -> dict:
    """Every field of every spec in a layer: {(path, field): value}, time samples included."""
    values = {}

    def visit(path):
        spec = layer.GetObjectAtPath(path)
        if spec is None:   # a relationship target or a connection
            values[(str(path), "target")] = True
            return
        for key in spec.ListInfoKeys():
            if key == "subLayerOffsets":  # no Python converter for the vector of offsets
                values[(str(path), key)] = [(o.offset, o.scale) for o in layer.subLayerOffsets]
            elif key != "timeSamples":
                values[(str(path), key)] = spec.GetInfo(key)
        if path.IsPropertyPath() and layer.GetNumTimeSamplesForPath(path):
            for t in layer.ListTimeSamplesForPath(path):
                values[(str(path), f"sample {t}")] = layer.QueryTimeSample(path, t)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return values


def _numeric(value):
    """A float64 array for numbers, numeric tuples and Vt/Gf values; None for anything else."""
    if isinstance(value, (bool, str, Sdf.Path)) or value is None:
        return None
    if isinstance(value, (int, float, np.number)):
        return np.array(float(value))
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return array if array.dtype.kind == "f" else None


def assert_values_close(a, b, where: str, atol: float = ATOL, rtol: float = RTOL) -> None:
    """Asserts two field values are equal, numbers within tolerance, recursing into containers."""
    if isinstance(a, dict) or isinstance(b, dict):
        assert isinstance(a, dict) and isinstance(b, dict), where
        assert sorted(map(str, a)) == sorted(map(str, b)), f"{where}: keys differ"
        for key in a:
            assert_values_close(a[key], b[key], f"{where}[{key}]", atol, rtol)
        return
    x, y = _numeric(a), _numeric(b)
    if x is not None and y is not None:
        assert x.shape == y.shape, f"{where}: shapes {x.shape} and {y.shape}"
        np.testing.assert_allclose(x, y, atol=atol, rtol=rtol, err_msg=where)
        return
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        assert len(a) == len(b), f"{where}: lengths differ"
        for i, (u, v) in enumerate(zip(a, b)):
            assert_values_close(u, v, f"{where}[{i}]", atol, rtol)
        return
    assert a == b, where


def assert_layers_close(new: Sdf.Layer, old: Sdf.Layer, name: str) -> None:
    """Asserts two layers hold the same specs and fields, floats within tolerance."""
    a, b = layer_values(new), layer_values(old)
    assert sorted(a) == sorted(b), f"{name}: the layers hold different specs or fields"
    for key, value in a.items():
        assert_values_close(value, b[key], f"{name} {key}")
