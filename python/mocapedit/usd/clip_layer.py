"""The layout of a clip layer: one Skeleton and its SkelAnimation, and the stationary tags on it.

::

    def Skeleton "Skel" (apiSchemas = ["SkelBindingAPI"])   # joints, rest/bind transforms
        rel skel:animationSource = </Skel/Anim>
        def SkelAnimation "Anim"                            # samples at time codes 0..F-1

Generated clips (:mod:`mocapedit.data.examples`) and imported ones
(:mod:`mocapedit.usd.bvh_usd`) share it, so either is referenced into an agent the same way.
A stationary range is a ``MocapStationaryAPI:<name>`` instance on the SkelAnimation with its
``uniform int2 stationary:<name>:frames`` (inclusive clip frames).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from pxr import Gf, Sdf, Usd

from mocapedit.usd import sdf

__all__ = ["SKELETON_PATH", "ANIMATION_PATH", "STATIONARY_API", "new_layer", "set_property",
           "tag_stationary"]

#: The Skeleton (the default prim) and its SkelAnimation in a clip layer.
SKELETON_PATH = Sdf.Path("/Skel")
ANIMATION_PATH = Sdf.Path("/Skel/Anim")
STATIONARY_API = "MocapStationaryAPI"


def new_layer(path) -> Sdf.Layer:
    """An empty layer that will be saved at path, replacing what is there.

    Call inside an Sdf.ChangeBlock: a layer already open (on a stage) is
    cleared and refilled, and stages see only the result.
    """
    path = os.fspath(path)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    layer = Sdf.Layer.Find(path)
    if layer is not None:
        layer.Clear()
        return layer
    return Sdf.Layer.CreateNew(path)


def set_property(prim: Usd.Prim, name: str, type_name: Sdf.ValueTypeName, value) -> Usd.Attribute:
    """Sets an attribute of a prim on a stage (in its edit target), creating it when absent."""
    # With the schema registered the property is built in: keep its type and
    # variability. Without it, author what the schema declares (uniform).
    attr = prim.GetAttribute(name)
    if not attr:
        attr = prim.CreateAttribute(name, type_name, False, Sdf.VariabilityUniform)
    attr.Set(value)
    return attr


def tag_stationary(anim: Usd.Prim | Sdf.PrimSpec, name: str, frames: Sequence[int]) -> None:
    """Tag an inclusive frame range of a SkelAnimation as stationary.

    Applies ``MocapStationaryAPI:<name>`` and authors
    ``uniform int2 stationary:<name>:frames``. `anim` is a prim on a stage
    (authored in its edit target) or a prim spec in a layer (a clip layer).
    """
    if not name or ":" in name or not Sdf.Path.IsValidIdentifier(name):
        raise ValueError(f"stationary range name must be an identifier, got {name!r}")
    first, last = (int(v) for v in frames)
    if not 0 <= first <= last:
        raise ValueError(f"stationary range {name!r} must satisfy 0 <= first <= last, "
                         f"got ({first}, {last})")
    attr_name = f"stationary:{name}:frames"
    value = Gf.Vec2i(first, last)
    if isinstance(anim, Sdf.PrimSpec):
        sdf.prepend_api(anim, f"{STATIONARY_API}:{name}")
        spec = anim.properties.get(attr_name) if attr_name in anim.properties else None
        if spec is None:
            spec = sdf.attr(anim, attr_name, Sdf.ValueTypeNames.Int2, uniform=True)
        spec.default = value
        return
    anim.AddAppliedSchema(f"{STATIONARY_API}:{name}")
    set_property(anim, attr_name, Sdf.ValueTypeNames.Int2, value)
