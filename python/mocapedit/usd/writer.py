"""Authors the edits layer. Write-only; no linear algebra.

The layer holds only ``over`` opinions on edited agents and new prims under
``/MocapEdit``; placed over the input stage it plays the edited motion through plain
UsdSkel and UsdGeom. Layout:

- an edited agent gets ``xformOp:translate:mocapEdit`` and ``xformOp:rotateY:mocapEdit``
  (``rotateZ`` on a Z-up stage; ``xformOp:transform:mocapEdit`` under a parent that is not
  upright), time-sampled and prepended to its ``xformOpOrder``: the rigid ground motion of
  its path edit (for a re-timed agent whose own transform ops are animated, the ops stand
  for those too and replace them in the order: they would play at shot time; likewise on
  its skeleton prim when that prim's own transform ops are animated);
- an agent whose joints changed only in timing (time warp, time and sync constraints,
  speed matching) gets a SkelAnimation under ``/MocapEdit/Animations`` that references its
  source clip and re-times it with USD value clips (``clips:times`` maps shot time to the
  clip's own time, ``clips:active`` plays the one clip): nothing is baked, the layer grows
  by one time pair per source frame (an edit op of such an agent is sampled at the same
  shot times);
- an agent whose locked legs change only joint rotations gets that re-timed animation
  too, with the rotations baked over it (local time samples are stronger than the value
  clip's; translations and scales still play the source's, and a lowered pelvis is carried
  by the agent's transform op);
- an agent whose poses changed otherwise (layering) gets a baked SkelAnimation there
  instead; each is bound to its skeleton with ``skel:animationSource``, and agents whose
  animations are identical share one;
- an instance the layer authors under (an instanced agent whose skeleton gets an animation,
  the instanced group of an edited agent) gets ``instanceable = false``: opinions under an
  instance are ignored;
- guide geometry goes under ``/MocapEdit/Guides`` with purpose ``guide``;
- ``customLayerData["mocapedit"]`` (:mod:`mocapedit.usd.edits_format`) records the version,
  the input layers, a content hash, the solve statistics and the whole solve report
  (``report``: compact JSON text, sorted keys, no timings, so the same input still gives the
  same bytes); ``mocapedit report`` reads it back.

Prims and samples are authored in sorted order so the same input gives the same bytes.
Files are written to a temporary name beside the target and renamed into place.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np
from pxr import Sdf, UsdGeom, Vt

from mocapedit.usd import edits_format, outputs, sdf
from mocapedit.model.data import Agent, StageInfo
from mocapedit.model.names import unique_identifier

#: The suffix of the transform ops the writer prepends (``xformOp:<kind>:mocapEdit``).
EDIT_SUFFIX = "mocapEdit"
#: USD value type of each kind of op it writes (all in double precision), and what turns its
#: (T,...) float64 values into T sample values in one conversion (angles: Python floats, which
#: USD takes faster than the items of a Vt.DoubleArray).
_OP_TYPES = {"translate": (Sdf.ValueTypeNames.Double3, Vt.Vec3dArray.FromNumpy),
             "rotateY": (Sdf.ValueTypeNames.Double, np.ndarray.tolist),
             "rotateZ": (Sdf.ValueTypeNames.Double, np.ndarray.tolist),
             "transform": (Sdf.ValueTypeNames.Matrix4d, Vt.Matrix4dArray.FromNumpy)}
ROOT = Sdf.Path("/MocapEdit")
GUIDES = ROOT.AppendChild("Guides")
ANIMATIONS = ROOT.AppendChild("Animations")


@dataclass
class BakedAnimation:
    """Joint transforms baked at stage times. Over a :class:`RetimedClip` (``AgentEdit.retimed``)
    a channel left None plays the re-timed source's."""
    joints: list[str]
    times: np.ndarray                  # (T,) stage times
    translations: np.ndarray | None    # (T,J,3)
    rotations: np.ndarray              # (T,J,4) (x,y,z,w)
    scales: np.ndarray | None          # (T,J,3)


@dataclass
class RetimedClip:
    """A source clip played on a new timing by USD value clips: nothing is baked."""
    layer: str                   # identifier of the layer whose spec holds the clip's samples
    prim_path: str               # that SkelAnimation spec's path in the layer
    joints: list[str]
    stage_times: np.ndarray      # (F,) shot time at which each clip sample plays, increasing
    clip_times: np.ndarray       # (F,) the samples' own times in the clip layer


@dataclass
class AgentEdit:
    """What the writer authors for one agent; every part optional. With both ``retimed`` and
    ``animation``, the animation's channels are authored over the re-timed source clip (the
    pose changes only there: locked legs' rotations); with one of them, that one alone."""
    times: np.ndarray | None = None          # (T,) stage times of the xform op samples
    # The prepended ops, outermost first: (kind, (T,...) values), kind one of translate,
    # rotateY, rotateZ (degrees) or transform ((T,4,4) matrices).
    xform_ops: list[tuple[str, np.ndarray]] = field(default_factory=list)
    # The ops stand for the agent prim's authored ones too, which leave its xformOpOrder (a
    # re-timed agent whose own transform is animated: see processor.compose_edits).
    replaces_ops: bool = False
    # Ops that replace the skeleton prim's own animated ones, sampled at ``times`` (a re-timed
    # agent whose travel is on its skeleton prim).
    skeleton_ops: list[tuple[str, np.ndarray]] = field(default_factory=list)
    animation: BakedAnimation | None = None
    retimed: RetimedClip | None = None


@dataclass
class GuideCurves:
    name: str                    # prim name under /MocapEdit/Guides
    curves: list[np.ndarray]     # each (K,3) world points
    color: tuple[float, float, float]
    width: float                 # stage units
    doc: str = ""
    colors: np.ndarray | None = None  # (C,3) one colour per curve, overrides color


@dataclass
class GuidePoints:
    name: str
    points: np.ndarray           # (K,3) world
    colors: np.ndarray           # (K,3)
    width: float
    doc: str = ""


@dataclass
class LayerContent:
    info: StageInfo
    agents: dict[str, Agent]
    edits: Mapping[str, AgentEdit]   # read once per agent, in sorted order
    guides: list = field(default_factory=list)
    provenance: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    report: dict | None = None   # JSON-ready solve report, stored as compact JSON text
    # Folder the layer will be saved in: asset paths (value clips) are written relative to
    # it; None writes them absolute.
    anchor: str | None = None


def _safe_name(path: str, taken: set[str]) -> str:
    return unique_identifier(path.strip("/"), taken, "agent")


def _deinstance_above(layer: Sdf.Layer, agent: Agent, path: Sdf.Path) -> None:
    """Makes the agent's instances that hold ``path`` below them not instanceable: an opinion
    authored under an instance is ignored (the agent, or its group, then composes on its own;
    the agents that are not edited stay instanced)."""
    for instance in agent.instances:
        held = Sdf.Path(instance)
        if path != held and path.HasPrefix(held):
            sdf.over_chain(layer, held).instanceable = False


def _author_xform_ops(layer: Sdf.Layer, agent: Agent, edit: AgentEdit) -> None:
    if edit.xform_ops:
        _author_ops(layer, agent, agent.path, agent.xform_op_order, edit.xform_ops, edit.times, edit.replaces_ops)
    if edit.skeleton_ops:
        _author_ops(layer, agent, agent.skeleton_path, agent.skeleton_xform_op_order, edit.skeleton_ops,
                    edit.times, True)


def _author_ops(layer: Sdf.Layer, agent: Agent, prim_path: str, authored: list[str], ops, times,
                replaces: bool) -> None:
    """``ops`` time-sampled on the prim, first in its xformOpOrder after any
    ``!resetXformStack!``: prepended to its ``authored`` ops, or instead of them.

    Ops an earlier solve wrote are the input's like any other (a shot edited again over its
    composed stage): the new ones go on top, under a suffix of their own (``mocapEdit2``, ...),
    since an opinion on the same attribute would override the earlier edit."""
    _deinstance_above(layer, agent, Sdf.Path(prim_path))
    spec = sdf.over_chain(layer, Sdf.Path(prim_path))
    order = list(authored)
    at = 1 if order and order[0] == "!resetXformStack!" else 0
    if replaces:
        order = order[:at]
    suffix, n = EDIT_SUFFIX, 1
    while any(o.endswith(":" + suffix) for o in authored):
        n += 1
        suffix = f"{EDIT_SUFFIX}{n}"
    names = [f"xformOp:{kind}:{suffix}" for kind, _ in ops]
    order[at:at] = names
    sdf.attr(spec, "xformOpOrder", Sdf.ValueTypeNames.TokenArray, Vt.TokenArray(order), uniform=True)
    times = np.asarray(times, dtype=np.float64).tolist()
    for name, (kind, values) in zip(names, ops):
        type_name, convert = _OP_TYPES[kind]
        path = sdf.attr(spec, name, type_name).path
        # One conversion of the whole array: per-sample Gf values from lists took half the time.
        converted = convert(np.ascontiguousarray(values, dtype=np.float64))
        for t, v in zip(times, converted):
            layer.SetTimeSample(path, t, v)


def _animation_key(anim: BakedAnimation) -> tuple:
    """Identity of a baked animation's content (its arrays are hashed: the writer may be handed
    each agent's as it reaches it, and they are gone after)."""
    def digest(array) -> bytes:
        if array is None:
            return b""
        data = np.ascontiguousarray(array, dtype=np.float32)
        return hashlib.blake2b(data, digest_size=20).digest() + repr(data.shape).encode()
    return (tuple(anim.joints), np.asarray(anim.times, dtype=np.float64).tobytes(),
            digest(anim.translations), digest(anim.rotations), digest(anim.scales),
            anim.translations is None, anim.scales is None)


def _bind_animation(layer: Sdf.Layer, agent: Agent, path: Sdf.Path) -> None:
    _deinstance_above(layer, agent, Sdf.Path(agent.skeleton_path))
    skel = sdf.over_chain(layer, Sdf.Path(agent.skeleton_path))
    skel.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["SkelBindingAPI"]))
    rel = Sdf.RelationshipSpec(skel, "skel:animationSource", custom=False)
    rel.targetPathList.explicitItems = [path]


def _author_animation(layer: Sdf.Layer, anim: BakedAnimation, name: str) -> Sdf.Path:
    path = ANIMATIONS.AppendChild(name)
    spec = sdf.define(layer, path, "SkelAnimation")
    sdf.attr(spec, "joints", Sdf.ValueTypeNames.TokenArray, Vt.TokenArray(anim.joints), uniform=True)
    _author_channels(layer, spec, anim)
    return path


def _author_channels(layer: Sdf.Layer, spec: Sdf.PrimSpec, anim: BakedAnimation) -> None:
    """The animation's channels that are not None, as time samples on ``spec``."""
    values = [("translations", Sdf.ValueTypeNames.Float3Array, Vt.Vec3fArray, anim.translations),
              ("rotations", Sdf.ValueTypeNames.QuatfArray, Vt.QuatfArray, anim.rotations),
              ("scales", Sdf.ValueTypeNames.Half3Array, Vt.Vec3hArray, anim.scales)]
    times = np.asarray(anim.times, dtype=np.float64).tolist()
    for attr_name, type_name, array_type, data in values:
        if data is None:
            continue
        path = sdf.attr(spec, attr_name, type_name).path
        data = np.ascontiguousarray(data, dtype=np.float32)
        for t, frame in zip(times, data):
            layer.SetTimeSample(path, t, array_type.FromNumpy(frame))


def asset_path(identifier: str, anchor: str | None) -> str:
    """The asset path to write for a layer: relative to ``anchor`` ("./" or "../" first, so
    it resolves beside the layer that holds it), absolute without an anchor."""
    layer = Sdf.Layer.Find(identifier)
    real = os.path.abspath(layer.realPath if layer and layer.realPath else identifier)
    if anchor is None:
        return real.replace(os.sep, "/")
    rel = os.path.relpath(real, os.path.abspath(anchor)).replace(os.sep, "/")
    return rel if rel.startswith("../") else "./" + rel


def _retimed_key(clip: RetimedClip) -> tuple:
    return ("retimed", clip.layer, clip.prim_path, tuple(clip.joints),
            np.asarray(clip.stage_times, dtype=np.float64).tobytes(),
            np.asarray(clip.clip_times, dtype=np.float64).tobytes())


def _author_retimed(layer: Sdf.Layer, clip: RetimedClip, name: str, asset: str) -> Sdf.Path:
    """A SkelAnimation that references the source clip (its joints, defaults and any other
    property) and plays its samples on the new timing through one value clip; ``asset``: the
    clip layer's :func:`asset_path`."""
    path = ANIMATIONS.AppendChild(name)
    spec = sdf.define(layer, path, "SkelAnimation")
    spec.referenceList.Prepend(Sdf.Reference(asset, Sdf.Path(clip.prim_path)))
    sdf.attr(spec, "joints", Sdf.ValueTypeNames.TokenArray, Vt.TokenArray(clip.joints), uniform=True)
    pairs = np.stack([np.asarray(clip.stage_times, dtype=np.float64),
                      np.asarray(clip.clip_times, dtype=np.float64)], axis=1)
    spec.SetInfo("clips", {"default": {
        "assetPaths": Sdf.AssetPathArray([Sdf.AssetPath(asset)]),
        "primPath": clip.prim_path,
        "active": Vt.Vec2dArray([(float(pairs[0, 0]), 0.0)]),
        "times": Vt.Vec2dArray.FromNumpy(np.ascontiguousarray(pairs)),
    }})
    return path


def _colors(spec: Sdf.PrimSpec, colors: np.ndarray, interpolation: str) -> None:
    sdf.attr(spec, "primvars:displayColor", Sdf.ValueTypeNames.Color3fArray,
          Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(colors, dtype=np.float32).reshape(-1, 3)))
    spec.attributes["primvars:displayColor"].SetInfo("interpolation", interpolation)


def _author_guides(layer: Sdf.Layer, guides: list) -> None:
    taken: set[str] = set()
    for guide in guides:
        is_curves = isinstance(guide, GuideCurves)
        if len(guide.curves if is_curves else guide.points) == 0:
            continue
        path = GUIDES.AppendChild(_safe_name(guide.name, taken))
        spec = sdf.define(layer, path, "BasisCurves" if is_curves else "Points")
        if is_curves:
            # A curve needs two vertices: a single point becomes a zero-length segment.
            curves = [np.repeat(c, 2, axis=0) if len(c) == 1 else c for c in guide.curves]
            pts = np.concatenate(curves).astype(np.float32)
            sdf.attr(spec, "type", Sdf.ValueTypeNames.Token, "linear", uniform=True)
            sdf.attr(spec, "curveVertexCounts", Sdf.ValueTypeNames.IntArray,
                  Vt.IntArray([int(len(c)) for c in curves]))
            if guide.colors is not None:
                _colors(spec, guide.colors, "uniform")
            else:
                _colors(spec, np.array([guide.color]), "constant")
        else:
            pts = np.asarray(guide.points, dtype=np.float32).reshape(-1, 3)
            _colors(spec, guide.colors, "vertex")
        points = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts))
        sdf.attr(spec, "points", Sdf.ValueTypeNames.Point3fArray, points)
        sdf.attr(spec, "widths", Sdf.ValueTypeNames.FloatArray, Vt.FloatArray([float(guide.width)]))
        spec.attributes["widths"].SetInfo("interpolation", "constant")
        # Boundables carry their extent so every USD tool frames them without computing it.
        compute = UsdGeom.Curves.ComputeExtent if is_curves else UsdGeom.Points.ComputeExtent
        # (A crowd's paths are millions of points: the widths go over as one array, not a list.)
        extent = compute(points, Vt.FloatArray.FromNumpy(np.full(len(pts), float(guide.width), dtype=np.float32)))
        sdf.attr(spec, "extent", Sdf.ValueTypeNames.Float3Array, extent)
        sdf.attr(spec, "purpose", Sdf.ValueTypeNames.Token, "guide", uniform=True)
        if guide.doc:
            spec.documentation = guide.doc


def set_input_metadata(layer: Sdf.Layer, info: StageInfo) -> None:
    """The input's time codes per second and range, up axis and units: a layer whose rate differs
    from the stage's would be rescaled when sub-layered, and one opened on its own still says in
    which units and up axis it is."""
    sdf.set_time_metadata(layer, info.time_codes_per_second, info.start_time, info.end_time)
    sdf.set_stage_metadata(layer, info.up_axis, info.meters_per_unit)


def build_layer(content: LayerContent) -> Sdf.Layer:
    """An anonymous layer holding the edits; save it with :func:`save_layer`."""
    # Held in USD's binary (crate) form: exported as .usdc it is written as it is, with no
    # second copy of the whole layer; as .usda, the same text.
    layer = Sdf.Layer.CreateAnonymous(".usdc")
    info = content.info
    set_input_metadata(layer, info)
    layer.documentation = "mocapedit edits: place over the input stage (sublayer above it)."
    # Opened on its own the layer still says what it is.
    layer.defaultPrim = ROOT.name
    data = dict(content.provenance)
    if content.stats:
        data[edits_format.STATS] = edits_format.layer_value(content.stats)
    if content.report is not None:
        data[edits_format.REPORT] = edits_format.report_text(content.report)
    edits_format.write(layer, data)
    with Sdf.ChangeBlock():
        root = Sdf.PrimSpec(layer.pseudoRoot, ROOT.name, Sdf.SpecifierDef, "Scope")
        if content.guides:   # none with guides off: no empty scope
            Sdf.PrimSpec(root, GUIDES.name, Sdf.SpecifierDef, "Scope")
        # Names an earlier solve's layer in the input already uses: a prim of the same name here
        # would compose with it.
        taken: set[str] = set(info.taken_animation_names)
        # Agents whose baked animations are identical share one prim, named after the first.
        authored: dict[tuple, Sdf.Path] = {}
        assets: dict[str, str] = {}   # clip layer -> its asset path (many agents share a clip)
        for agent_path in sorted(content.edits):
            edit, agent = content.edits[agent_path], content.agents[agent_path]
            if edit.xform_ops or edit.skeleton_ops:
                _author_xform_ops(layer, agent, edit)
            if edit.animation is not None or edit.retimed is not None:
                retimed, anim = edit.retimed, edit.animation
                key = ((_retimed_key(retimed) if retimed else ())
                       + (_animation_key(anim) if anim is not None else ()))
                path = authored.get(key)
                if path is None:
                    if not authored:   # the first animation: its scope, after the guides'
                        Sdf.PrimSpec(root, ANIMATIONS.name, Sdf.SpecifierDef, "Scope")
                    name = _safe_name(agent_path, taken)
                    if retimed:
                        if retimed.layer not in assets:
                            assets[retimed.layer] = asset_path(retimed.layer, content.anchor)
                        path = _author_retimed(layer, retimed, name, assets[retimed.layer])
                        if anim is not None:
                            _author_channels(layer, layer.GetPrimAtPath(path), anim)
                    else:
                        path = _author_animation(layer, anim, name)
                    authored[key] = path
                _bind_animation(layer, agent, path)
        _author_guides(layer, content.guides)
    return layer


def export_layer(layer: Sdf.Layer) -> Callable[[str], None]:
    """A writer for :class:`~mocapedit.usd.outputs.Writes` that exports ``layer`` to a file."""
    def write(tmp: str) -> None:
        if not layer.Export(tmp):
            raise OSError(f"USD could not write the layer to {tmp}")
    return write


def save_layer(layer: Sdf.Layer, path: str) -> None:
    """Writes the layer to ``path`` through a temporary file and a rename."""
    outputs.save_with(path, export_layer(layer))


def composed_layer(path: str, edits_path: str, input_path: str, info: StageInfo,
                   default_prim: str | None = None) -> Sdf.Layer:
    """A stage layer, to be saved at ``path``, that sub-layers the edits over the input (relative paths)."""
    here = os.path.dirname(os.path.abspath(path))
    layer = Sdf.Layer.CreateAnonymous(os.path.splitext(path)[1] or ".usda")
    layer.subLayerPaths = [os.path.relpath(os.path.abspath(edits_path), here),
                           os.path.relpath(os.path.abspath(input_path), here)]
    # A root layer that only sub-layers others still sets the stage's time and units.
    set_input_metadata(layer, info)
    if default_prim:
        layer.defaultPrim = default_prim
    return layer


def save_composed(path: str, edits_path: str, input_path: str, info: StageInfo,
                  default_prim: str | None = None) -> None:
    """Writes a stage that sub-layers the edits over the input (relative paths)."""
    save_layer(composed_layer(path, edits_path, input_path, info, default_prim), path)
