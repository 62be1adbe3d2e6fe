"""Reads a shot stage into :mod:`mocapedit.model.data` data. Read-only; no linear algebra.

The reader resolves every prim with ``MocapAgentAPI`` to its skeleton and source clip,
reads each distinct clip's samples once however many agents play it, and reads the
constraint, tag, group, region, layer and settings prims into plain Python and numpy.
It validates what can be validated against the stage (targets, frame ranges, tokens) and
raises :class:`~mocapedit.model.errors.MocapEditError` naming the prim and property.
"""
from __future__ import annotations

import re
import sys

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdSkel

from mocapedit.geometry import contacts
from mocapedit.model import data as model
from mocapedit.model import limits
from mocapedit.model.errors import MocapEditError, prim_error
from mocapedit.model.names import hips_joint, resolve_joint
from mocapedit.usd import edits_format
from mocapedit.usd.errors import USD_ERRORS, usd_diagnostics_held, usd_messages
from mocapedit.usd.evaluate import shot_range, skeleton_candidates

AGENT_API = "MocapAgentAPI"
STATIONARY_API = "MocapStationaryAPI"
FOOT_CONTACT_API = "MocapFootContactAPI"

DEFAULT_COLLISION_RADIUS_M = 0.3
DEFAULT_COLLISION_HEIGHT_M = 1.8


def open_stage(path: str) -> Usd.Stage:
    """Opens a stage, turning USD's failure into a clear error naming the file."""
    import os
    if not os.path.exists(path):
        raise MocapEditError(f"{path}: no such file")
    if os.path.isdir(path):
        raise MocapEditError(f"{path}: is a folder; give the shot's stage file (.usda, .usdc or .usd)")
    try:
        with usd_diagnostics_held() as said:
            stage = Usd.Stage.Open(str(path))
    except Exception as exc:  # pxr raises Tf.ErrorException with a multi-line text
        raise MocapEditError(f"{path}: cannot be read as a USD stage: {'; '.join(usd_messages(str(exc)))}") from None
    if stage is None:
        raise MocapEditError(f"{path}: cannot be read as a USD stage")
    if not stage.GetCompositionErrors():   # those are check_composition's to report, file by file
        for text in said:
            print(f"USD: {text}", file=sys.stderr)
    return stage


def open_layer(path: str) -> Sdf.Layer:
    """Opens one layer, turning USD's failure into a clear error naming the file."""
    import os
    if not os.path.isfile(path):
        raise MocapEditError(f"{path}: no such file")
    try:
        with usd_diagnostics_held():
            layer = Sdf.Layer.FindOrOpen(os.path.abspath(path))
    except Exception as exc:  # pxr raises Tf.ErrorException with a multi-line text
        raise MocapEditError(f"{path}: cannot be read as a USD layer: {'; '.join(usd_messages(str(exc)))}") from None
    if layer is None:
        raise MocapEditError(f"{path}: cannot be read as a USD layer")
    return layer


def _is_edits_layer(identifier: str) -> bool:
    """Whether the layer is an edits layer this tool wrote (its ``customLayerData`` says so)."""
    layer = Sdf.Layer.Find(identifier)
    return bool(layer) and edits_format.KEY in (layer.customLayerData or {})


def _plain_usd_text(text: str) -> str:
    """A USD composition error on one line, without the names of USD's C++ internals (a clip
    file that does not parse: its file:line:column and the property, not the parser's rule)."""
    text = " ".join(line.strip() for line in text.strip().splitlines() if line.strip()).rstrip(".;")
    text = re.sub(r"parse error matching \S+ at '[^']*'", "parse error", text)
    return re.sub(r"pxrInternal_v\w+?__pxrReserved__::", "", text)


def check_composition(stage: Usd.Stage) -> None:
    """Raises a MocapEditError when the stage did not compose as authored: a sublayer,
    reference or payload whose file cannot be opened (USD only warns and goes on without
    it), or a sublayer that says another ``upAxis`` or ``metersPerUnit`` than the root layer,
    which the stage follows alone. A sublayer at another ``timeCodesPerSecond`` than the one
    the root layer authors is fine: USD plays it rescaled to the root's (a 24 fps crowd under
    a shot counted in 240 ticks a second); only a root layer that does not author one, over a
    sublayer that does, is an error (the stage then counts time in USD's default 24 a second,
    which the sublayer's author did not mean)."""
    errors = stage.GetCompositionErrors()
    if errors:
        # One missing clip file referenced by a thousand agents is one problem: group by
        # what failed, and name a few of the prims where.
        where: dict[str, list[str]] = {}
        why: dict[str, str] = {}
        for error in errors:
            text = _plain_usd_text(str(error))
            arc = re.fullmatch(r"(.* introduced by @[^@]*@)(<[^>]*>)(?: -- (.*))?", text)
            what = arc[1] if arc else text
            where.setdefault(what, []).extend([arc[2]] if arc else [])
            # USD composes prims on several threads: which of them reports why the file failed
            # (the others may only say that it did) varies; the fullest reason is kept.
            reason = (arc[3] or "").strip() if arc else ""
            if len(reason) > len(why.get(what, "")):
                why[what] = reason
        where = {what: sorted(set(sites)) for what, sites in where.items()}  # USD reports in no set order
        parts = [(what if not sites else what + sites[0] if len(sites) == 1 else
                  f"{what} at {len(sites)} prims ({', '.join(sites[:3])}{', ...' if len(sites) > 3 else ''})")
                 + (f" ({why[what]})" if why.get(what) else "")
                 for what, sites in sorted(where.items())]
        raise MocapEditError(f"{stage.GetRootLayer().identifier}: the stage does not compose: " + "; ".join(parts))
    root = stage.GetRootLayer()
    stage_says = {"upAxis": str(UsdGeom.GetStageUpAxis(stage)),
                  "metersPerUnit": float(UsdGeom.GetStageMetersPerUnit(stage)),
                  "timeCodesPerSecond": float(stage.GetTimeCodesPerSecond())}
    for layer in stage.GetLayerStack(includeSessionLayers=False):
        if layer == root:
            continue
        for key, value in stage_says.items():
            if not layer.pseudoRoot.HasInfo(key):
                continue
            says = layer.pseudoRoot.GetInfo(key)
            if key == "timeCodesPerSecond" and root.pseudoRoot.HasInfo(key):
                continue    # rescaled by USD to the root's
            if (says != value) if key == "upAxis" else not np.isclose(float(says), value, rtol=1e-9, atol=0.0):
                shown = lambda v: v if isinstance(v, str) else f"{float(v):g}"  # noqa: E731
                root_says = (f"says {key} = {shown(value)}" if root.pseudoRoot.HasInfo(key) else
                             f"does not author {key}, so the stage uses {shown(value)}")
                raise MocapEditError(
                    f"{layer.identifier}: sublayer says {key} = {shown(says)}, but the root layer "
                    f"{root.identifier} {root_says}; a stage follows its root layer alone. Author {key} = "
                    f"{shown(says)} on the "
                    f"root layer (or make the sublayer agree with it)")


def clip_unit_notes(data: model.StageData) -> list[str]:
    """One note per clip layer that authors another ``upAxis`` or ``metersPerUnit`` than the
    stage: USD converts neither through a reference, so its agents play at another size or
    lying down, and every figure measured on them is off by as much."""
    info, notes, seen = data.info, [], set()
    for clip in data.clips.values():
        spec = clip.sample_spec
        layer = Sdf.Layer.Find(spec[0]) if spec else None
        if layer is None or layer.identifier in seen:
            continue
        seen.add(layer.identifier)
        says = []
        if layer.pseudoRoot.HasInfo("upAxis") and str(layer.pseudoRoot.GetInfo("upAxis")) != info.up_axis:
            says.append(f"upAxis {layer.pseudoRoot.GetInfo('upAxis')} (the stage: {info.up_axis})")
        if layer.pseudoRoot.HasInfo("metersPerUnit") and not np.isclose(
                float(layer.pseudoRoot.GetInfo("metersPerUnit")), info.meters_per_unit, rtol=1e-9, atol=0.0):
            says.append(f"metersPerUnit {float(layer.pseudoRoot.GetInfo('metersPerUnit')):g} "
                        f"(the stage: {info.meters_per_unit:g})")
        if says:
            notes.append(f"clip layer {layer.identifier} says {' and '.join(says)}: USD converts neither through a "
                         "reference, so the agents that play it are at another size or lie down, and so are "
                         "their edits; write the clip in the stage's units and axis (import-bvh --meters-per-unit "
                         "and --up) or reference one that is")
    return notes


def stage_info(stage: Usd.Stage) -> model.StageInfo:
    root = stage.GetRootLayer()
    start, end = shot_range(stage)
    if start is not None and end is not None and end < start:
        raise MocapEditError(f"{root.identifier}: endTimeCode {end:g} is before startTimeCode {start:g}; "
                             f"the shot plays from its start to its end: author them in that order")
    return model.StageInfo(
        up_axis=str(UsdGeom.GetStageUpAxis(stage)),
        meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(stage)),
        time_codes_per_second=float(stage.GetTimeCodesPerSecond()),
        start_time=start,
        end_time=end,
        root_layer=root.identifier,
        used_layers=sorted(layer.identifier for layer in stage.GetUsedLayers()),
        taken_animation_names=sorted(p.GetName() for p in stage.GetPrimAtPath("/MocapEdit/Animations").GetAllChildren())
        if stage.GetPrimAtPath("/MocapEdit/Animations") else [],
    )


def _targets(prim: Usd.Prim, name: str) -> list[str]:
    rel = prim.GetRelationship(name)
    if not rel:
        return []
    try:
        return [str(t) for t in rel.GetForwardedTargets()]
    except USD_ERRORS:   # some layer authors it as an attribute: USD cannot compose its targets
        raise prim_error(prim.GetPath(), f"is authored as an attribute; it is a relationship: author "
                         f"`rel {name} = </path/to/prim>`", name) from None


def _authored_type(attr: Usd.Attribute) -> Sdf.ValueTypeName | None:
    """The type the strongest spec authors (``attr.GetTypeName()`` gives the schema's)."""
    for spec in attr.GetPropertyStack(Usd.TimeCode.EarliestTime()):
        if spec.typeName:
            return spec.typeName
    return None


def _known(type_name: Sdf.ValueTypeName) -> bool:
    """Whether USD knows the type (a layer may author ``point2d x = ...``: USD reads it, with
    the type unknown and the value unregistered, and asking the type's parts then crashes)."""
    return bool(type_name) and type_name.type != Tf.Type.Unknown


_KINDS = {"int": "integer", "long": "integer", "unsigned int": "integer", "unsigned long": "integer",
          "unsigned char": "integer", "double": "real", "float": "real", "pxr_half::half": "real",
          "GfTimeCode": "real", "TfToken": "text", "string": "text"}


def _kind(type_name: Sdf.ValueTypeName) -> tuple[str, bool]:
    """What a value of this type means to the reader: text, integer, real, or a vector of
    a size and component kind (float3, double3, point3d and half3 alike), and arrayness."""
    if not _known(type_name):
        return "unknown", False
    name = type_name.scalarType.type.typeName
    name = _KINDS.get(name, name)
    if name.startswith("GfVec") and name[-1] in "dfh":
        name = name[:-1] + "r"
    return name, bool(type_name.isArray)


def _compatible(authored: Sdf.ValueTypeName, expected: Sdf.ValueTypeName) -> bool:
    a, e = _kind(authored), _kind(expected)
    return a == e or (a == ("integer", e[1]) and e[0] == "real")


def _check_finite(prim: Usd.Prim, name: str, value) -> None:
    try:
        numbers = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return
    if not np.all(np.isfinite(numbers)):
        shown = f"got {value}" if numbers.size <= 4 else "some of its values are not"
        raise prim_error(prim.GetPath(), f"must be a finite number, {shown}", name)


def _get(prim: Usd.Prim, name: str, default=None):
    """The value of a single-valued property, checked against the schema: an attribute
    authored with another type than the schema's, only as time samples, or (for numbers)
    not finite is an error naming the prim and property, never a silent misread."""
    attr = prim.GetAttribute(name)
    if not attr:
        return default
    if attr.HasAuthoredValue():
        source = attr.GetResolveInfo().GetSource()
        if source in (Usd.ResolveInfoSourceTimeSamples, Usd.ResolveInfoSourceValueClips):
            raise prim_error(prim.GetPath(), "is authored only as time samples; it takes one value: "
                             "author it without a time", name)
        expected = prim.GetPrimDefinition().GetAttributeDefinition(name)
        if isinstance(attr.Get(), Sdf.UnregisteredValue) or not _known(attr.GetTypeName()):
            schema = f"; the schema's type is {expected.GetTypeName()}" if expected else ""
            raise prim_error(prim.GetPath(), f"is authored with a type USD does not know{schema}", name)
        authored = _authored_type(attr)
        if expected and authored and not _compatible(authored, expected.GetTypeName()):
            raise prim_error(prim.GetPath(), f"is authored as {authored} {attr.Get()!r}; the schema's type "
                             f"is {expected.GetTypeName()}", name)
    value = attr.Get()
    if value is None:
        return default
    if not isinstance(value, (str, bool, int)) and _kind(attr.GetTypeName())[0] not in ("text", "bool"):
        _check_finite(prim, name, value)
    return value


def _origin(attr: Usd.Attribute):
    """Where an attribute's value comes from: the layer stack and prim path of the site that
    holds its strongest opinion (``("fallback", name)`` without one), or None when it comes from
    value clips. Attributes of many prims that reference one asset (a crowd's skeletons) share
    it, and then their values."""
    if not attr:
        return None
    info = attr.GetResolveInfo()
    source = info.GetSource()
    if source in (Usd.ResolveInfoSourceNone, Usd.ResolveInfoSourceFallback):
        return ("fallback", attr.GetName())
    if source not in (Usd.ResolveInfoSourceDefault, Usd.ResolveInfoSourceTimeSamples):
        return None
    node = info.GetNode()
    return (node.layerStack.identifier.rootLayer.identifier, str(node.path), attr.GetName())


def _ancestors(prim: Usd.Prim):
    """The prim and its ancestors up to (not including) the pseudo-root."""
    while prim and not prim.IsPseudoRoot():
        yield prim
        prim = prim.GetParent()


def _frame_range(anim: Usd.Prim, prop: str, frame_count: int, what: str) -> tuple[int, int]:
    """An inclusive (first, last) int2 range of clip frames, checked against the clip."""
    value = _get(anim, prop)
    if value is None:
        raise prim_error(anim.GetPath(), f"{what} tag has no frame range", prop)
    a, b = int(value[0]), int(value[1])
    if a > b:
        raise prim_error(anim.GetPath(), f"{what} range [{a}, {b}] is reversed: its first frame "
                         f"comes after its last; write ({b}, {a})", prop)
    if not (0 <= a <= b < frame_count):
        raise prim_error(anim.GetPath(), f"{what} range [{a}, {b}] is outside the clip's "
                         f"frames 0..{frame_count - 1}", prop)
    return a, b


#: Time codes: sample times closer than this are one frame (see StageReader._composed_times).
SAME_TIME = 1e-6


class _XformTimes:
    """Local-to-world matrices, cached per time code; static prims are read once."""

    def __init__(self, stage: Usd.Stage):
        self._stage = stage
        self._caches: dict[float | None, UsdGeom.XformCache] = {}
        self._varying: dict[str, bool] = {}
        self._own: dict[str, bool] = {}   # whether the prim's own transform ops are animated

    def cache(self, time: float | None) -> UsdGeom.XformCache:
        c = self._caches.get(time)
        if c is None:
            c = UsdGeom.XformCache(Usd.TimeCode.Default() if time is None else Usd.TimeCode(time))
            self._caches[time] = c
        return c

    def own_varying(self, prim: Usd.Prim, key: str | None = None) -> bool:
        """Whether the prim's own transform ops might be animated (asked of USD once a prim)."""
        key = str(prim.GetPath()) if key is None else key
        v = self._own.get(key)
        if v is None:
            xf = UsdGeom.Xformable(prim)
            v = self._own[key] = bool(xf and xf.TransformMightBeTimeVarying())
        return v

    def varying(self, prim: Usd.Prim) -> bool:
        key = str(prim.GetPath())
        v = self._varying.get(key)
        if v is None:
            v = self.own_varying(prim, key)
            parent = prim.GetParent()
            if not v and parent and not parent.IsPseudoRoot():
                v = self.varying(parent)
            self._varying[key] = v
        return v

    def local_to_world(self, prim: Usd.Prim, times: np.ndarray) -> np.ndarray:
        if not self.varying(prim):
            return np.array(self.cache(None).GetLocalToWorldTransform(prim))[None]
        return np.stack([np.array(self.cache(float(t)).GetLocalToWorldTransform(prim)) for t in times])

    def own_transform(self, prim: Usd.Prim, times: np.ndarray) -> np.ndarray | None:
        """(F,4,4) the prim's local transform at ``times`` when its own transform ops are
        animated, else None."""
        if not self.own_varying(prim):
            return None
        xf = UsdGeom.Xformable(prim)
        return np.stack([np.array(xf.GetLocalTransformation(Usd.TimeCode(float(t)))) for t in times])

    def inner_animated(self, agent: Usd.Prim, skel: Usd.Prim) -> bool:
        """Whether a prim between the skeleton and the agent (both excluded) has an animated
        transform."""
        p = skel.GetParent()
        while p and p != agent and not p.IsPseudoRoot() and p.GetPath().HasPrefix(agent.GetPath()):
            xf = UsdGeom.Xformable(p)
            if xf and xf.TransformMightBeTimeVarying():
                return True
            p = p.GetParent()
        return False

    def parent_to_world(self, prim: Usd.Prim, times: np.ndarray) -> np.ndarray:
        xf = UsdGeom.Xformable(prim)
        if xf and xf.GetResetXformStack():
            return np.eye(4)[None]
        parent = prim.GetParent()
        if not parent or parent.IsPseudoRoot() or not self.varying(parent):
            return np.array(self.cache(None).GetParentToWorldTransform(prim))[None]
        return np.stack([np.array(self.cache(float(t)).GetParentToWorldTransform(prim)) for t in times])


class StageReader:
    """Reads one stage. Use :func:`read_stage` unless you need the pieces."""

    def __init__(self, stage: Usd.Stage, progress=None):
        check_composition(stage)
        self.stage = stage
        self.info = stage_info(stage)
        self.progress = progress
        self.xforms = _XformTimes(stage)
        self.clips: dict[tuple, model.Clip] = {}
        self.agents: dict[str, model.Agent] = {}
        self._skeletons: dict = {}    # skeleton path, or the origin of its values -> (joints, parents, rest)
        self._anim_joints: dict = {}  # origin of a clip's joints -> its joints
        self._legs_by_name: dict = {}  # a skeleton's joints -> its legs found by name
        self._hips: dict = {}          # (joints, parents, root joint) -> the hip joint guessed by name
        self._same_times: dict[tuple, bool] = {}

    # ---- agents ---------------------------------------------------------------------

    def _target_prim(self, owner, rel: str, target: str, kind=None, what: str = "") -> Usd.Prim:
        """The prim a relationship targets; an error naming ``owner.rel`` when it does not
        exist, is inactive, or is not a ``kind`` (a schema class, described as ``what``)."""
        found = self.stage.GetPrimAtPath(target)
        why = None
        if not found:
            why = "does not exist"
        elif not found.IsActive():
            why = "is inactive (active = false)"
        elif kind is not None and not found.IsA(kind):
            why = f"is not a {what} (it is a {found.GetTypeName() or 'typeless prim'})"
        if why:
            raise prim_error(getattr(owner, "GetPath", lambda: owner)(), f"targets <{target}>, which {why}", rel)
        return found

    def _find_skeleton(self, prim: Usd.Prim) -> Usd.Prim:
        if prim.IsA(UsdSkel.Skeleton):
            return prim
        for target in _targets(prim, "skel:skeleton"):
            return self._target_prim(prim, "skel:skeleton", target, UsdSkel.Skeleton, "Skeleton")
        candidates = skeleton_candidates(prim)
        if len(candidates) == 1:
            return self.stage.GetPrimAtPath(candidates[0])
        if candidates:
            names = ", ".join(f"<{c}>" for c in candidates)
            raise prim_error(prim.GetPath(), f"agent has several skeletons ({names}) and none is bound to it: "
                             "bind the one to edit with skel:skeleton on the agent (SkelBindingAPI)",
                             "skel:skeleton")
        raise prim_error(prim.GetPath(), "agent has no skeleton: no skel:skeleton binding and no "
                         "Skeleton prim below it", "apiSchemas")

    def _find_animation(self, prim: Usd.Prim, skel: Usd.Prim) -> Usd.Prim:
        explicit = _targets(prim, "mocap:animationSource")
        if explicit:
            return self._target_prim(prim, "mocap:animationSource", explicit[0], UsdSkel.Animation,
                                     "SkelAnimation")
        # UsdSkel binds the animation on the skeleton or inherits it from an ancestor; the
        # nearest binding authored holds, even one set to nothing (it blocks those above).
        p = skel
        while p and not p.IsPseudoRoot():
            rel = p.GetRelationship("skel:animationSource")
            if rel and rel.HasAuthoredTargets():
                for target in _targets(p, "skel:animationSource"):
                    return self._target_prim(p, "skel:animationSource", target, UsdSkel.Animation, "SkelAnimation")
                raise prim_error(p.GetPath(), "agent has no animation: its binding is set to none, so UsdSkel "
                                 "plays the rest pose; bind a SkelAnimation here or set mocap:animationSource on "
                                 f"<{prim.GetPath()}>", "skel:animationSource")
            if p == prim:
                break
            p = p.GetParent()
        raise prim_error(prim.GetPath(), f"agent has no animation: neither mocap:animationSource nor "
                         f"skel:animationSource on skeleton <{skel.GetPath()}> is set",
                         "mocap:animationSource")

    def _skeleton_data(self, skel: Usd.Prim):
        key = str(skel.GetPath())
        hit = self._skeletons.get(key)
        if hit is not None:
            return hit
        # Skeletons that take their joints and rest pose from one site (a crowd referencing one
        # character) share what is read and checked of them.
        origin = tuple(_origin(skel.GetAttribute(n)) for n in ("joints", "restTransforms"))
        shared = self._skeletons.get(origin) if None not in origin else None
        if shared is not None:
            self._skeletons[key] = shared
            return shared
        joints = [str(j) for j in (_get(skel, "joints") or [])]
        if not joints:
            raise prim_error(skel.GetPath(), "skeleton has no joints", "joints")
        topo = UsdSkel.Topology(joints)
        ok, why = topo.Validate()
        if not ok:
            raise prim_error(skel.GetPath(), f"invalid joint hierarchy: {why}", "joints")
        parents = np.array(topo.GetParentIndices(), dtype=np.int64)
        rest = _get(skel, "restTransforms")
        rest = np.array(rest, dtype=np.float64) if rest is not None and len(rest) else np.tile(np.eye(4), (len(joints), 1, 1))
        if rest.shape != (len(joints), 4, 4):
            raise prim_error(skel.GetPath(), f"restTransforms has {rest.shape[0]} entries for "
                             f"{len(joints)} joints", "restTransforms")
        hit = (joints, parents, rest)
        self._skeletons[key] = hit
        if None not in origin:
            self._skeletons[origin] = hit
        return hit

    @staticmethod
    def _sampled_spec(attr: Usd.Attribute):
        for spec in attr.GetPropertyStack(Usd.TimeCode.EarliestTime()):
            if spec.layer.GetNumTimeSamplesForPath(spec.path) > 0:
                return (spec.layer.identifier, str(spec.path))
        return None

    def _composed_times(self, attrs: list, specs: tuple) -> np.ndarray:
        """The union of the attributes' composed sample times. Attributes sampled at the same
        times on one layer compose to the same times, so one of them is asked (a crowd's
        agents share a few clips: the check is cached per spec)."""
        sampled = [(a, s) for a, s in zip(attrs, specs) if s is not None]
        same = self._same_times.get(specs) if sampled else False
        if same is None:
            layer = Sdf.Layer.Find(sampled[0][1][0])
            same = bool(layer) and all(s[0] == sampled[0][1][0] for _, s in sampled) and len(
                {tuple(layer.ListTimeSamplesForPath(s[1])) for _, s in sampled}) == 1
            self._same_times[specs] = same
        if same:
            return np.asarray(sampled[0][0].GetTimeSamples(), dtype=np.float64)
        # A clip re-timed by value clips with some channels baked over it (an edits layer's legs
        # locked on a warped clip, baked on the shot's whole frames): its frames are the value
        # clip's, the source's own; the baked channels are read between their samples. (The
        # union made a 30 fps clip under a 24 fps shot 360 frames long instead of 225, and a
        # second solve put its constraints on the wrong frames.)
        clipped = [a for a in attrs if a and a.GetResolveInfo().GetSource() == Usd.ResolveInfoSourceValueClips]
        baked = [s for a, s in zip(attrs, specs) if a and a not in clipped and s is not None]
        if not (clipped and baked and all(_is_edits_layer(s[0]) for s in baked)):
            clipped = []        # a clip of the user's own: every channel's samples are frames
        times = np.unique(np.concatenate(
            [np.asarray(a.GetTimeSamples(), dtype=np.float64) for a in (clipped or attrs) if a] + [np.zeros(0)]))
        # Channels of one frame sampled at times that differ by rounding (a value clip's mapped
        # times beside samples baked at the same frames) are one frame, not two a hair apart.
        keep = np.ones(len(times), dtype=bool)
        keep[1:] = np.diff(times) > SAME_TIME
        return times[keep]

    def _clip(self, anim: Usd.Prim, all_channels: bool = True):
        """(clip key, composed stage times of the clip's frames); reads the clip on first use.

        An agent's own clip must author translations, rotations and scales (UsdSkel poses an
        animation only then); a layer clip (``all_channels=False``) may author only some."""
        _check_value_clips(anim)
        attrs = [anim.GetAttribute(n) for n in model.CHANNELS]
        specs = tuple(self._sampled_spec(a) if a else None for a in attrs)
        times = self._composed_times(attrs, specs)
        if times.size == 0:
            raise prim_error(anim.GetPath(), "clip has no samples: translations, rotations and scales "
                             "hold no time samples", "translations")
        for name, attr in zip(model.CHANNELS, attrs):
            if all_channels and (not attr or not attr.HasValue()):
                raise prim_error(anim.GetPath(), "has no value; UsdSkel poses an animation only when "
                                 "translations, rotations and scales are all authored", name)
        # Clips of many agents that reference one asset share their joints: read them once.
        origin = _origin(anim.GetAttribute("joints"))
        anim_joints = self._anim_joints.get(origin) if origin is not None else None
        if anim_joints is None:
            anim_joints = tuple(str(j) for j in (_get(anim, "joints") or []))
            if origin is not None:
                self._anim_joints[origin] = anim_joints
        if not anim_joints:
            raise prim_error(anim.GetPath(), "SkelAnimation has no joints", "joints")
        key = (anim_joints, specs, times.size)
        if key not in self.clips:
            self.clips[key] = self._read_clip(anim, key, anim_joints, times)
        return key, times

    @staticmethod
    def _read_clip(anim: Usd.Prim, key, joints, times) -> model.Clip:
        n, j = times.size, len(joints)

        def read(name, width, fill):
            attr = anim.GetAttribute(name)
            out = np.empty((n, j, width), dtype=np.float32)
            if not attr or not attr.HasAuthoredValue():
                out[:] = fill
                return out
            for i, t in enumerate(times):
                value = attr.Get(Usd.TimeCode(float(t)))
                arr = np.asarray(value, dtype=np.float32) if value is not None else None
                if arr is None or arr.shape != (j, width):
                    got = "nothing" if arr is None else f"{arr.shape[0]} values"
                    raise prim_error(anim.GetPath(), f"at time {t:g} holds {got} for {j} joints", name)
                out[i] = arr
            return out

        rotations = read("rotations", 4, (0.0, 0.0, 0.0, 1.0))
        if not np.all(np.isfinite(rotations)):
            raise prim_error(anim.GetPath(), "holds non-finite values", "rotations")
        # A zero quaternion (some exporters write one for a joint they do not animate) is no turn
        # to UsdSkel, which plays it as none: so is it here (it made every figure NaN).
        rotations[np.linalg.norm(rotations, axis=-1) < 1e-6] = (0.0, 0.0, 0.0, 1.0)
        translations = read("translations", 3, 0.0)
        if not np.all(np.isfinite(translations)):
            raise prim_error(anim.GetPath(), "holds non-finite values", "translations")
        scales = read("scales", 3, 1.0)
        if not np.all(np.isfinite(scales)):
            raise prim_error(anim.GetPath(), "holds non-finite values", "scales")
        src = key[1][0] or key[1][1]
        channels = tuple(n for n in model.CHANNELS if anim.GetAttribute(n).HasAuthoredValue())
        clip = model.Clip(key=key, source=f"{src[0]}@{src[1]}" if src else str(anim.GetPath()),
                          joints=list(joints), times=times, translations=translations,
                          rotations=rotations, scales=scales, channels=channels)
        spec = clip.sample_spec
        layer = Sdf.Layer.Find(spec[0]) if spec else None
        # A clip that value clips already re-time is not one spec's samples.
        if layer and not any(p.HasAuthoredMetadata("clips") for p in _ancestors(anim)):
            # The frames' own times in that layer, for value clips that re-time it.
            own = np.unique(np.concatenate([np.asarray(layer.ListTimeSamplesForPath(s[1]), dtype=np.float64)
                                            for s in key[1] if s is not None]))
            clip.spec_times = own if own.size == n else None
        return clip

    def _stationary(self, anim: Usd.Prim, frame_count: int, schemas=None):
        tags = []
        prefix = STATIONARY_API + ":"
        for schema in (anim.GetAppliedSchemas() if schemas is None else schemas):
            if not schema.startswith(prefix):
                continue
            name = schema[len(prefix):]
            a, b = _frame_range(anim, f"stationary:{name}:frames", frame_count, "stationary")
            tags.append((name, a, b))
        return sorted(tags, key=lambda t: (t[1], t[2], t[0]))

    def _legs(self, prim: Usd.Prim, joints: list[str], parents: np.ndarray) -> list:
        key = (tuple(joints), parents.tobytes())
        by_name = self._legs_by_name.get(key)
        if by_name is None:
            by_name = self._legs_by_name[key] = {leg.side: leg for leg in contacts.find_legs(joints, parents)}
        found = dict(by_name)
        for side in contacts.SIDES:
            prop = f"mocap:{side}LegJoints"
            names = [str(n) for n in (_get(prim, prop) or [])]
            if not names:
                continue
            indices = []
            for name in names:
                index = resolve_joint(joints, name)
                if index is None:
                    raise prim_error(prim.GetPath(), f"joint '{name}' is not in the skeleton (or its bare name "
                                     "is not unique: give its joint path)", prop)
                indices.append(int(index))
            why = contacts.chain_problem(joints, parents, indices)
            if why:
                raise prim_error(prim.GetPath(), why, prop)
            found[side] = contacts.Leg(side, *indices[:3], indices[3] if len(indices) > 3 else None)
        legs = [found[s] for s in contacts.SIDES if s in found]
        if len(legs) == 2:
            shared = {j for j in (legs[0].hip, legs[0].knee, legs[0].ankle, legs[0].toe) if j is not None} & \
                {j for j in (legs[1].hip, legs[1].knee, legs[1].ankle, legs[1].toe) if j is not None}
            if shared:
                authored = [s for s in contacts.SIDES if _get(prim, f"mocap:{s}LegJoints")]
                side = authored[-1] if authored else contacts.SIDES[-1]
                raise prim_error(prim.GetPath(), f"shares joint '{joints[min(shared)]}' with the "
                                 f"{'left' if side != 'left' else 'right'} leg; each leg is its own hip, knee "
                                 f"and ankle", f"mocap:{side}LegJoints")
        return legs

    def _foot_contacts(self, anim: Usd.Prim, joints: list[str], frame_count: int, legs: list, schemas=None):
        prefix = FOOT_CONTACT_API + ":"
        names = [s[len(prefix):] for s in (anim.GetAppliedSchemas() if schemas is None else schemas)
                 if s.startswith(prefix)]
        if not names:
            return None
        feet = {j: leg for leg in legs for j in (leg.ankle, leg.toe) if j is not None}
        out = []
        for name in names:
            prop = f"footContact:{name}:joint"
            joint_name = str(_get(anim, prop, "") or "")
            joint = resolve_joint(joints, joint_name) if joint_name else None
            if joint is None:
                raise prim_error(anim.GetPath(), f"foot joint '{joint_name}' is not in the skeleton" if joint_name
                                 else "foot contact names no joint", prop)
            if joint not in feet:
                raise prim_error(anim.GetPath(), f"joint '{joint_name}' is not the ankle or toe of a leg "
                                 "(set mocap:leftLegJoints / mocap:rightLegJoints on the agent)", prop)
            a, b = _frame_range(anim, f"footContact:{name}:frames", frame_count, "foot contact")
            out.append((name, int(feet[joint].ankle), a, b))
        return sorted(out, key=lambda c: (c[2], c[3], c[0]))

    def read_agent(self, prim: Usd.Prim) -> model.Agent:
        path = str(prim.GetPath())
        skel = self._find_skeleton(prim)
        anim = self._find_animation(prim, skel)
        # The clip's tags apply to its SkelAnimation alone; on the agent or its skeleton they
        # were silently read as nothing.
        for holder in (prim, skel.GetPrim()):
            for applied in holder.GetAppliedSchemas():
                if applied.split(":", 1)[0] in (STATIONARY_API, FOOT_CONTACT_API):
                    raise prim_error(holder.GetPath(), f"has {applied} applied, which tags frames of a clip: "
                                     f"apply it to the agent's SkelAnimation <{anim.GetPath()}>",
                                     "apiSchemas")
        joints, parents, rest = self._skeleton_data(skel)
        key, times = self._clip(anim)
        clip = self.clips[key]
        index = {j: i for i, j in enumerate(joints)}
        anim_to_skel = np.array([index.get(j, -1) for j in clip.joints], dtype=np.int64)
        if np.all(anim_to_skel < 0):
            raise prim_error(anim.GetPath(), f"animation shares no joint with skeleton <{skel.GetPath()}>",
                             "joints")

        root_name = str(_get(prim, "mocap:rootJoint", "") or "")
        if root_name:
            root_joint = resolve_joint(joints, root_name)
            if root_joint is None:
                raise prim_error(path, f"joint '{root_name}' is not in skeleton <{skel.GetPath()}> "
                                 f"(its joints start {', '.join(joints[:4])}, ...)", "mocap:rootJoint")
        else:
            root_joint = 0
        hip_name = str(_get(prim, "mocap:hipJoint", "") or "")
        if hip_name:
            hip_joint = resolve_joint(joints, hip_name)
            if hip_joint is None:
                raise prim_error(path, f"joint '{hip_name}' is not in skeleton <{skel.GetPath()}>",
                                 "mocap:hipJoint")
        else:
            skeleton = (tuple(joints), parents.tobytes(), root_joint)
            hip_joint = self._hips[skeleton] if skeleton in self._hips else \
                self._hips.setdefault(skeleton, _guess_hip(joints, parents, root_joint))

        radius = _get(prim, "mocap:collisionRadius")
        radius = self.info.metres(DEFAULT_COLLISION_RADIUS_M) if radius is None else float(radius)
        if not radius > 0:
            raise prim_error(path, f"collision radius must be positive, got {radius:g}", "mocap:collisionRadius")
        height = _get(prim, "mocap:collisionHeight")
        height = self.info.metres(DEFAULT_COLLISION_HEIGHT_M) if height is None else float(height)
        if not height > 0:
            raise prim_error(path, f"collision height must be positive, got {height:g}", "mocap:collisionHeight")

        legs = self._legs(prim, joints, parents)
        curves = _targets(prim, "mocap:pathCurve")
        order = _op_order(prim)
        anim_schemas = anim.GetAppliedSchemas()
        return model.Agent(
            path=path, skeleton_path=str(skel.GetPath()), animation_path=str(anim.GetPath()),
            clip_key=key, joints=joints, parents=parents, rest_transforms=rest,
            anim_to_skel=anim_to_skel, sample_times=times,
            skel_to_world=self.xforms.local_to_world(skel, times),
            agent_parent_to_world=self.xforms.parent_to_world(prim, times),
            xform_op_order=order,
            root_joint=int(root_joint), hip_joint=hip_joint,
            collision_radius=radius, collision_height=height,
            collide=bool(_get(prim, "mocap:collide", True)),
            path_curve=curves[0] if curves else None,
            stationary=self._stationary(anim, times.size, anim_schemas),
            legs=legs, foot_locking=bool(_get(prim, "mocap:footLocking", True)),
            foot_contacts=self._foot_contacts(anim, joints, times.size, legs, anim_schemas),
            instances=_instances(prim, skel),
            own_transform=self.xforms.own_transform(prim, times),
            skeleton_transform=None if skel == prim else self.xforms.own_transform(skel, times),
            skeleton_xform_op_order=[] if skel == prim else _op_order(skel),
            inner_transform_animated=self.xforms.inner_animated(prim, skel),
        )

    # ---- the other prims ---------------------------------------------------------------

    def _agent_target(self, prim: Usd.Prim, rel: str, required: bool = True) -> str | None:
        targets = _targets(prim, rel)
        if not targets:
            if required:
                raise prim_error(prim.GetPath(), "has no target", rel)
            return None
        if len(targets) > 1:
            raise prim_error(prim.GetPath(), f"has {len(targets)} targets; exactly one agent is expected", rel)
        target = targets[0]
        if target not in self.agents:
            raise prim_error(prim.GetPath(), f"targets <{target}>, which {self._not_an_agent(target)}", rel)
        return target

    def _not_an_agent(self, target: str) -> str:
        """Why a target path is not one of the agents read, for messages."""
        found = self.stage.GetPrimAtPath(target)
        if not found:
            return "does not exist"
        if not found.IsActive() or not found.IsLoaded():
            return "is inactive (active = false)" if not found.IsActive() else "is not loaded"
        instancer = _point_instancer(found)
        if instancer is not None:
            return (f"is a prototype of PointInstancer <{instancer.GetPath()}>: it plays at the instancer's "
                    "points, which cannot be edited one by one; make each instance an agent of its own to edit it")
        return "is not an agent (no MocapAgentAPI)"

    def _frame(self, prim: Usd.Prim, prop: str, agent: str) -> int:
        frame = int(_get(prim, prop, 0))
        count = self.agents[agent].frame_count
        if not 0 <= frame < count:
            raise prim_error(prim.GetPath(), f"frame {frame} is outside the clip of <{agent}> "
                             f"(frames 0..{count - 1})", prop)
        return frame

    def _strength(self, prim: Usd.Prim) -> tuple[bool, float]:
        strength = str(_get(prim, "strength", "hard"))
        if strength not in ("hard", "soft"):
            raise prim_error(prim.GetPath(), f"strength must be 'hard' or 'soft', got '{strength}'", "strength")
        weight = float(_get(prim, "weight", 1.0))
        if not weight >= 0 or not np.isfinite(weight):
            raise prim_error(prim.GetPath(), f"weight must be a finite non-negative number, got {weight:g}",
                             "weight")
        return strength == "hard", weight

    def read_position(self, prim):
        agent = self._agent_target(prim, "agent")
        hard, weight = self._strength(prim)
        return model.PositionConstraint(
            path=str(prim.GetPath()), agent=agent, frame=self._frame(prim, "frame", agent),
            position=np.array(_get(prim, "position", (0, 0, 0)), dtype=np.float64), hard=hard, weight=weight)

    def read_relative(self, prim):
        agent = self._agent_target(prim, "agent")
        target = self._agent_target(prim, "target")
        hard, weight = self._strength(prim)
        space = str(_get(prim, "space", "world"))
        if space not in ("world", "target"):
            raise prim_error(prim.GetPath(), f"space must be 'world' or 'target', got '{space}'", "space")
        offset = _get(prim, "offset")
        if offset is None:   # the schema gives it no fallback: (0, 0, 0) would stack the two agents
            raise prim_error(prim.GetPath(), "has no offset; author the agent's root position at frame minus "
                             "the target's at targetFrame, in stage units (it has no default)", "offset")
        return model.RelativeConstraint(
            path=str(prim.GetPath()), agent=agent, frame=self._frame(prim, "frame", agent), target=target,
            target_frame=self._frame(prim, "targetFrame", target),
            offset=np.array(offset, dtype=np.float64), space=space, hard=hard, weight=weight)

    def read_time(self, prim):
        agent = self._agent_target(prim, "agent")
        hard, weight = self._strength(prim)
        time = _get(prim, "time")
        if time is None:
            raise prim_error(prim.GetPath(), "has no time", "time")
        return model.TimeConstraint(path=str(prim.GetPath()), agent=agent,
                                    frame=self._frame(prim, "frame", agent), time=float(time), hard=hard,
                                    weight=weight)

    def read_sync(self, prim):
        agent = self._agent_target(prim, "agent")
        target = self._agent_target(prim, "target")
        hard, weight = self._strength(prim)
        return model.SyncConstraint(
            path=str(prim.GetPath()), agent=agent, frame=self._frame(prim, "frame", agent), target=target,
            target_frame=self._frame(prim, "targetFrame", target), offset=float(_get(prim, "offset", 0.0)),
            hard=hard, weight=weight)

    def read_group(self, prim):
        members = _targets(prim, "members")
        for m in members:
            if m not in self.agents:
                raise prim_error(prim.GetPath(), f"member <{m}> {self._not_an_agent(m)}", "members")
        stiffness = float(_get(prim, "stiffness", 1.0))
        if not stiffness > 0:
            raise prim_error(prim.GetPath(), f"stiffness must be positive, got {stiffness:g}", "stiffness")
        return model.AgentGroup(path=str(prim.GetPath()), members=sorted(set(members)), stiffness=stiffness)

    def read_region(self, prim):
        shape = str(_get(prim, "shape", "circle"))
        if shape not in ("circle", "box"):
            raise prim_error(prim.GetPath(), f"shape must be 'circle' or 'box', got '{shape}'", "shape")
        agents = _targets(prim, "agents")
        for a in agents:
            if a not in self.agents:
                raise prim_error(prim.GetPath(), f"targets <{a}>, which {self._not_an_agent(a)}", "agents")
        geometry = _targets(prim, "geometry")
        bounds = None
        if geometry:
            geo = self._target_prim(prim, "geometry", geometry[0], UsdGeom.Imageable, "UsdGeom prim")
            cache = UsdGeom.BBoxCache(Usd.TimeCode.Default(), [UsdGeom.Tokens.default_, UsdGeom.Tokens.render,
                                                               UsdGeom.Tokens.proxy, UsdGeom.Tokens.guide])
            box = cache.ComputeWorldBound(geo).ComputeAlignedRange()
            if box.IsEmpty():
                raise prim_error(prim.GetPath(), f"geometry <{geometry[0]}> has an empty bound", "geometry")
            bounds = np.array([box.GetMin(), box.GetMax()], dtype=np.float64)
        return model.AvoidRegion(
            path=str(prim.GetPath()), shape=shape, radius=float(_get(prim, "radius", 1.0)),
            size=np.array(_get(prim, "size", (1, 1, 1)), dtype=np.float64),
            margin=float(_get(prim, "margin", 0.0)), agents=sorted(agents),
            local_to_world=np.array(self.xforms.cache(None).GetLocalToWorldTransform(prim)),
            geometry=geometry[0] if geometry else None, geometry_bounds=bounds)

    def read_layer(self, prim):
        agents = _targets(prim, "agents")
        for a in agents:
            if a not in self.agents:
                raise prim_error(prim.GetPath(), f"targets <{a}>, which {self._not_an_agent(a)}", "agents")
        anims = _targets(prim, "animation")
        if not anims:
            raise prim_error(prim.GetPath(), "has no animation", "animation")
        if len(anims) > 1:   # the second was dropped, silently
            raise prim_error(prim.GetPath(), f"targets {len(anims)} animations ({', '.join(f'<{a}>' for a in anims)}); "
                             "a layer plays one: make a layer for each", "animation")
        anim = self._target_prim(prim, "animation", anims[0], UsdSkel.Animation, "SkelAnimation")
        try:
            key, times = self._clip(anim, all_channels=False)
        except MocapEditError as exc:
            raise prim_error(prim.GetPath(), f"animation <{anim.GetPath()}> cannot be layered: {exc}",
                             "animation") from None
        attr = prim.GetAttribute("weight")
        wt = np.asarray(attr.GetTimeSamples() if attr else [], dtype=np.float64)
        if wt.size:
            wv = np.array([attr.Get(Usd.TimeCode(float(t))) for t in wt], dtype=np.float64)
        else:
            wv = np.array([float(_get(prim, "weight", 1.0))])
        tokens = {}
        for name, allowed, default in (("mode", ("blend", "additive"), "additive"),
                                       ("wrap", ("loop", "clamp"), "loop"),
                                       ("referencePose", ("firstFrame", "restPose"), "firstFrame")):
            value = str(_get(prim, name, default))
            if value not in allowed:
                raise prim_error(prim.GetPath(), f"must be one of {', '.join(allowed)}, got '{value}'", name)
            tokens[name] = value
        return model.AnimationLayer(
            path=str(prim.GetPath()), agents=agents, animation=str(anim.GetPath()), clip_key=key,
            joint=str(_get(prim, "joint", "") or ""), mode=tokens["mode"], weight_times=wt, weight_values=wv,
            time_offset=float(_get(prim, "timeOffset", 0.0)), wrap=tokens["wrap"],
            reference_pose=tokens["referencePose"], sample_times=times)

    def read_settings(self, prim):
        s = model.SolveSettings(path=str(prim.GetPath()))
        s.collision_avoidance = bool(_get(prim, "collisionAvoidance", s.collision_avoidance))
        s.max_iterations = int(_get(prim, "maxIterations", s.max_iterations))
        s.sample_step = float(_get(prim, "sampleStep", s.sample_step))
        s.margin = float(_get(prim, "margin", s.margin))
        s.match_speed = bool(_get(prim, "matchSpeed", s.match_speed))
        s.collision_strategy = str(_get(prim, "collisionStrategy", s.collision_strategy))
        s.min_time_interval = float(_get(prim, "minTimeInterval", s.min_time_interval))
        s.max_wait = float(_get(prim, "maxWait", s.max_wait))
        s.foot_locking = bool(_get(prim, "footLocking", s.foot_locking))
        s.pivot_on_feet = bool(_get(prim, "pivotOnFeet", s.pivot_on_feet))
        problem = limits.setting_problem(s)
        if problem is not None:
            raise prim_error(prim.GetPath(), problem[1], problem[0])
        return s

    def read_curve(self, agent_path: str, curve_path: str) -> dict:
        prim = self._target_prim(agent_path, "mocap:pathCurve", curve_path)
        type_name = prim.GetTypeName()
        if type_name not in ("BasisCurves", "NurbsCurves"):
            raise prim_error(agent_path, f"targets <{curve_path}>, which is a {type_name or 'typeless prim'}, "
                             "not a curve (BasisCurves or NurbsCurves expected)", "mocap:pathCurve")
        points = np.array(_get(prim, "points") or [], dtype=np.float64).reshape(-1, 3)
        if len(points) < 2:
            raise prim_error(curve_path, "path curve needs at least two points", "points")
        counts = np.array(_get(prim, "curveVertexCounts") or [len(points)], dtype=np.int64)
        info = {"type": type_name, "points": points, "counts": counts,
                "local_to_world": np.array(self.xforms.cache(None).GetLocalToWorldTransform(prim)),
                "basis": str(_get(prim, "basis", "bezier")), "curve_type": str(_get(prim, "type", "cubic")),
                "wrap": str(_get(prim, "wrap", "nonperiodic")), "order": None, "knots": None}
        if type_name == "NurbsCurves":
            info["order"] = np.array(_get(prim, "order") or [4], dtype=np.int64)
            info["knots"] = np.array(_get(prim, "knots") or [], dtype=np.float64)
            weights = _get(prim, "pointWeights")
            info["weights"] = np.array(weights, dtype=np.float64) if weights is not None and len(weights) else None
        return info

    # ---- the whole stage -----------------------------------------------------------------

    def read(self) -> model.StageData:
        agent_prims, typed, skel_roots = [], {}, []
        for prim in self.stage.Traverse(Usd.TraverseInstanceProxies()):
            if AGENT_API in prim.GetAppliedSchemas():
                agent_prims.append(prim)
            type_name = prim.GetTypeName()
            if type_name in ("SkelRoot", "Skeleton"):
                skel_roots.append(prim.GetPath())
            if type_name.startswith("Mocap"):
                typed.setdefault(type_name, []).append(prim)
        agent_prims.sort(key=lambda p: str(p.GetPath()))
        # A PointInstancer's prototypes play at its points, which cannot be edited one by one.
        instanced = [p for p in agent_prims if _point_instancer(p) is not None]
        agent_prims = [p for p in agent_prims if _point_instancer(p) is None]
        task = self.progress.task("read agents", len(agent_prims)) if self.progress else None
        for i, prim in enumerate(agent_prims):
            agent = self.read_agent(prim)
            self.agents[agent.path] = agent
            if task:
                task.update(i + 1)
        if task:
            task.done()

        data = model.StageData(info=self.info, agents=self.agents, clips=self.clips,
                               skel_roots_without_agent=_without_agent(skel_roots, agent_prims + instanced),
                               point_instanced_agents=[str(p.GetPath()) for p in instanced])
        readers = {
            "MocapPositionConstraint": (self.read_position, data.position_constraints),
            "MocapRelativeConstraint": (self.read_relative, data.relative_constraints),
            "MocapTimeConstraint": (self.read_time, data.time_constraints),
            "MocapSyncConstraint": (self.read_sync, data.sync_constraints),
            "MocapAgentGroup": (self.read_group, data.groups),
            "MocapAvoidRegion": (self.read_region, data.avoid_regions),
            "MocapAnimationLayer": (self.read_layer, data.layers),
        }
        for type_name, prims in typed.items():
            if type_name in readers:
                fn, out = readers[type_name]
                out.extend(fn(p) for p in prims)  # stage (traversal) order, which layers rely on
        settings = typed.get("MocapSolveSettings", [])
        if len(settings) > 1:
            raise MocapEditError("more than one MocapSolveSettings prim: " +
                                 ", ".join(f"<{p.GetPath()}>" for p in settings) + "; keep one")
        if settings:
            data.settings = self.read_settings(settings[0])
        for agent in self.agents.values():
            if agent.path_curve and agent.path_curve not in data.curves:
                data.curves[agent.path_curve] = self.read_curve(agent.path, agent.path_curve)
        return data


def _point_instancer(prim: Usd.Prim) -> Usd.Prim | None:
    """The PointInstancer the prim is inside (a prototype, or below one), or None."""
    p = prim.GetParent()
    while p and not p.IsPseudoRoot():
        if p.IsA(UsdGeom.PointInstancer):
            return p
        p = p.GetParent()
    return None


def _op_order(prim: Usd.Prim) -> list[str]:
    """The prim's authored xformOpOrder (empty when it has none or is not xformable)."""
    xf = UsdGeom.Xformable(prim)
    order = xf.GetXformOpOrderAttr().Get() if xf else None
    return [str(o) for o in (order or [])]


def _instances(agent: Usd.Prim, skel: Usd.Prim) -> list[str]:
    """Paths of the instances among the agent prim, its ancestors and the prims between it and
    its skeleton (the skeleton excluded), outermost first."""
    below = skel.GetPath() != agent.GetPath() and skel.GetPath().HasPrefix(agent.GetPath())
    p, out = (skel.GetParent() if below else agent), []
    while p and not p.IsPseudoRoot():
        if p.IsInstance():
            out.append(str(p.GetPath()))
        p = p.GetParent()
    return out[::-1]


def _without_agent(skels: list[Sdf.Path], agent_prims: list[Usd.Prim]) -> list[str]:
    """The outermost of the SkelRoots and Skeletons ``skels`` that are not agents, inside one
    or holding one."""
    agents = {p.GetPath() for p in agent_prims}
    holding = {a for path in agents for a in path.GetAncestorsRange()}
    found = set(skels)
    return [str(r) for r in skels if r not in holding and
            not any(a in agents or (a != r and a in found) for a in r.GetAncestorsRange())]


def _check_value_clips(prim: Usd.Prim) -> None:
    """A value clip file that cannot be opened is an error naming the prim's ``clips``: USD
    only warns and plays the prim without it."""
    api = Usd.ClipsAPI(prim)
    clips = api.GetClips()
    if not clips:
        return
    for name in sorted(clips.keys()):
        for asset in api.ComputeClipAssetPaths(name):
            if not asset.resolvedPath:
                raise prim_error(prim.GetPath(), f"value clip set '{name}' plays @{asset.path}@, which cannot be "
                                 "opened (a missing file?)", "clips")


def _guess_hip(joints: list[str], parents: np.ndarray, root_joint: int) -> int | None:
    """The joint named for the hips other than the root, else the root's first child."""
    hip = hips_joint(joints, skip=root_joint)
    if hip is not None:
        return hip
    children = [i for i, p in enumerate(parents) if p == root_joint]
    return children[0] if children else None


def read_stage(stage: Usd.Stage, progress=None) -> model.StageData:
    """Reads every agent, clip, constraint, tag, group, region, layer and setting on a stage."""
    return StageReader(stage, progress).read()


def parent_to_world_at(stage: Usd.Stage, path: str, times) -> np.ndarray:
    """(T,4,4) the parent-to-world transform of the prim at ``path`` at stage ``times`` (one
    (1,4,4) when it does not move; identity under ``!resetXformStack!``)."""
    return _XformTimes(stage).parent_to_world(stage.GetPrimAtPath(path), np.asarray(times, dtype=np.float64))


__all__ = ["open_stage", "check_composition", "read_stage", "stage_info", "resolve_joint", "StageReader",
           "parent_to_world_at"]
