"""The tolerant layer comparison that checked-in files are held to across machines."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Vt

from layer_compare import assert_layers_close


def _layer(angle: float, extra: float = 0.0) -> Sdf.Layer:
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.customLayerData = {"stats": {"residual": 1.0 + extra}}
    prim = Sdf.CreatePrimInLayer(layer, "/Anim")
    prim.specifier = Sdf.SpecifierDef
    attr = Sdf.AttributeSpec(prim, "rotations", Sdf.ValueTypeNames.QuatfArray)
    for t in range(3):
        half = 0.5 * (angle + 0.1 * t)
        q = Gf.Quatf(float(np.cos(half)), Gf.Vec3f(float(np.sin(half)), 0.0, 0.0))
        layer.SetTimeSample(attr.path, float(t), Vt.QuatfArray([q, q]))
    return layer


def test_last_bit_differences_in_time_sampled_quaternions_are_equal():
    a, b = 0.3, float(np.nextafter(np.float32(0.3), np.float32(1.0)))
    assert_layers_close(_layer(a), _layer(b), "quats")


def test_real_differences_fail():
    with pytest.raises(AssertionError):
        assert_layers_close(_layer(0.3), _layer(0.31), "quats")
    with pytest.raises(AssertionError):
        assert_layers_close(_layer(0.3), _layer(0.3, extra=1e-3), "customLayerData")
