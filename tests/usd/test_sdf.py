"""Tests for mocapedit.usd.sdf: the shared Sdf authoring helpers."""
from __future__ import annotations

from pxr import Sdf

from mocapedit.usd import sdf


def test_over_chain_makes_missing_ancestors_as_overs_and_reuses_specs():
    layer = Sdf.Layer.CreateAnonymous(".usda")
    spec = sdf.over_chain(layer, Sdf.Path("/A/B/C"))
    assert spec.path == Sdf.Path("/A/B/C")
    assert [layer.GetPrimAtPath(p).specifier for p in ("/A", "/A/B", "/A/B/C")] == [Sdf.SpecifierOver] * 3
    assert sdf.over_chain(layer, Sdf.Path("/A/B/C")) == spec
    child = sdf.define(layer, Sdf.Path("/A/B/D"), "Scope")
    assert (child.specifier, child.typeName) == (Sdf.SpecifierDef, "Scope")


def test_attr_variability_and_default():
    layer = Sdf.Layer.CreateAnonymous(".usda")
    spec = sdf.over_chain(layer, Sdf.Path("/A"))
    a = sdf.attr(spec, "a", Sdf.ValueTypeNames.Int, 3, uniform=True)
    b = sdf.attr(spec, "b", Sdf.ValueTypeNames.Float)
    assert (a.variability, a.default) == (Sdf.VariabilityUniform, 3)
    assert b.variability == Sdf.VariabilityVarying and not b.HasDefaultValue()


def test_prepend_api_adds_each_schema_once_and_metadata():
    layer = Sdf.Layer.CreateAnonymous(".usda")
    spec = sdf.over_chain(layer, Sdf.Path("/A"))
    for schema in ("XAPI", "YAPI:one", "XAPI"):
        sdf.prepend_api(spec, schema)
    assert list(spec.GetInfo("apiSchemas").prependedItems) == ["XAPI", "YAPI:one"]
    sdf.set_time_metadata(layer, 30.0, end=59.0)
    sdf.set_stage_metadata(layer, "Z", 0.01)
    assert (layer.timeCodesPerSecond, layer.framesPerSecond, layer.endTimeCode) == (30.0, 30.0, 59.0)
    assert not layer.HasStartTimeCode()
    assert (layer.pseudoRoot.GetInfo("upAxis"), layer.pseudoRoot.GetInfo("metersPerUnit")) == ("Z", 0.01)
