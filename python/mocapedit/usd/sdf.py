"""Sdf authoring helpers shared by every writer of layers (edits layer, clip layers, tag layers).

Authoring goes straight to layer specs through the Sdf API (fast inside ``Sdf.ChangeBlock``);
nothing here composes a stage.
"""
from __future__ import annotations

from pxr import Sdf

__all__ = ["attr", "over_chain", "define", "prepend_api", "set_time_metadata", "set_stage_metadata"]


def attr(spec: Sdf.PrimSpec, name: str, type_name: Sdf.ValueTypeName, value=None,
         uniform: bool = False) -> Sdf.AttributeSpec:
    """A new attribute spec on ``spec`` (varying unless ``uniform``), with ``value`` as its default
    when given."""
    out = Sdf.AttributeSpec(spec, name, type_name, Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying)
    if value is not None:
        out.default = value
    return out


def over_chain(layer: Sdf.Layer, path: Sdf.Path) -> Sdf.PrimSpec:
    """The prim spec at ``path``, made (with its missing ancestors) as ``over`` when absent."""
    spec = layer.GetPrimAtPath(path)
    if spec:
        return spec
    parent = layer.pseudoRoot if path.GetParentPath() == Sdf.Path.absoluteRootPath else \
        over_chain(layer, path.GetParentPath())
    return Sdf.PrimSpec(parent, path.name, Sdf.SpecifierOver)


def define(layer: Sdf.Layer, path: Sdf.Path, type_name: str) -> Sdf.PrimSpec:
    """A ``def`` prim spec of ``type_name`` at ``path``, under a parent spec that exists."""
    parent = layer.GetPrimAtPath(path.GetParentPath())
    return Sdf.PrimSpec(parent, path.name, Sdf.SpecifierDef, type_name)


def prepend_api(prim: Sdf.PrimSpec, schema: str) -> None:
    """Adds ``schema`` to the prim spec's prepended ``apiSchemas`` (once)."""
    ops = prim.GetInfo("apiSchemas") if prim.HasInfo("apiSchemas") else Sdf.TokenListOp()
    items = list(ops.prependedItems)
    if schema not in items:
        items.append(schema)
    ops.prependedItems = items
    prim.SetInfo("apiSchemas", ops)


def set_time_metadata(layer: Sdf.Layer, fps: float, start: float | None = None,
                      end: float | None = None) -> None:
    """Time codes (and frames) per second, and the time range where given."""
    layer.timeCodesPerSecond = fps
    layer.framesPerSecond = fps
    if start is not None:
        layer.startTimeCode = start
    if end is not None:
        layer.endTimeCode = end


def set_stage_metadata(layer: Sdf.Layer, up_axis: str, meters_per_unit: float) -> None:
    """The layer's ``upAxis`` and ``metersPerUnit``."""
    layer.pseudoRoot.SetInfo("upAxis", up_axis)
    layer.pseudoRoot.SetInfo("metersPerUnit", float(meters_per_unit))
