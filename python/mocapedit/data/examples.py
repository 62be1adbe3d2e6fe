"""Author example crowd stages: clip layers, agents, constraints and tags.

A clip layer holds one skeleton and its animation::

    def Skeleton "Skel" (apiSchemas = ["SkelBindingAPI"])   # joints, rest/bind transforms
        rel skel:animationSource = </Skel/Anim>
        def SkelAnimation "Anim"                            # samples at time codes 0..F-1

A crowd stage has one SkelRoot per agent under ``/World/Crowd``, placed by a
translate and a rotation about the up axis, with ``MocapAgentAPI`` applied. Its
``Skel`` child references the shared clip layer, optionally with a layer offset
so the agent starts playing at another shot time. Clips are written once
however many agents play them, and everything is authored through the Sdf API
inside ``Sdf.ChangeBlock``: a stage of a thousand agents builds in well under a
second once its clips exist.

Lengths are in the stage's units, angles in degrees, times in time codes.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence, Union

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from mocapedit.data.walker import Clip, rest_local_matrices, rest_world_transforms
from mocapedit.usd import clip_layer, sdf
from mocapedit.usd.clip_layer import tag_stationary

__all__ = [
    "CLIP_SKELETON_PATH",
    "CLIP_ANIMATION_PATH",
    "AgentSpec",
    "write_clip_layer",
    "build_crowd_stage",
    "define_mocap_prim",
    "add_position_constraint",
    "add_time_constraint",
    "add_sync_constraint",
    "add_relative_constraint",
    "add_group",
    "add_path_curve",
    "tag_stationary",
    "dense_crowd_paths",
]

CLIP_SKELETON_PATH = clip_layer.SKELETON_PATH
CLIP_ANIMATION_PATH = clip_layer.ANIMATION_PATH
AGENT_API = "MocapAgentAPI"

PathLike = Union[str, os.PathLike]


def _matrices(m: np.ndarray) -> Vt.Matrix4dArray:
    # walker's matrices use column vectors; Gf's use row vectors.
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(m, -1, -2)))


def write_clip_layer(clip: Clip, path: PathLike,
                     stationary: Mapping[str, Sequence[int]] | None = None) -> Sdf.Layer:
    """Write a clip as a layer holding a Skeleton and its SkelAnimation.

    Args:
        clip: the clip (F frames, J joints).
        path: file to write; ``.usda`` for text, ``.usdc`` for crate.
        stationary: optional ``{name: (first, last)}`` inclusive frame ranges,
            each tagged on the animation with ``MocapStationaryAPI:<name>``.

    Returns:
        The saved layer. Samples are at time codes 0..F-1; the layer's
        timeCodesPerSecond and framesPerSecond are the clip's fps, and its
        upAxis and metersPerUnit are the clip's.
    """
    frames = clip.num_frames
    if frames < 1:
        raise ValueError(f"clip {clip.name!r} has no samples")
    with Sdf.ChangeBlock():
        layer = clip_layer.new_layer(path)
        layer.defaultPrim = CLIP_SKELETON_PATH.name
        sdf.set_stage_metadata(layer, clip.up_axis, clip.meters_per_unit)
        sdf.set_time_metadata(layer, clip.fps, 0.0, float(frames - 1))

        joints = Vt.TokenArray(list(clip.joints))
        skel = Sdf.PrimSpec(layer, CLIP_SKELETON_PATH.name, Sdf.SpecifierDef, "Skeleton")
        sdf.prepend_api(skel, "SkelBindingAPI")
        sdf.attr(skel, "joints", Sdf.ValueTypeNames.TokenArray, joints, uniform=True)
        sdf.attr(skel, "bindTransforms", Sdf.ValueTypeNames.Matrix4dArray,
                 _matrices(rest_world_transforms(clip)), uniform=True)
        sdf.attr(skel, "restTransforms", Sdf.ValueTypeNames.Matrix4dArray,
                 _matrices(rest_local_matrices(clip)), uniform=True)
        rel = Sdf.RelationshipSpec(skel, "skel:animationSource", custom=False)
        rel.targetPathList.explicitItems = [CLIP_ANIMATION_PATH]

        anim = Sdf.PrimSpec(skel, CLIP_ANIMATION_PATH.name, Sdf.SpecifierDef, "SkelAnimation")
        sdf.attr(anim, "joints", Sdf.ValueTypeNames.TokenArray, joints, uniform=True)
        t_attr = sdf.attr(anim, "translations", Sdf.ValueTypeNames.Float3Array).path
        r_attr = sdf.attr(anim, "rotations", Sdf.ValueTypeNames.QuatfArray).path
        s_attr = sdf.attr(anim, "scales", Sdf.ValueTypeNames.Half3Array).path
        translations = np.ascontiguousarray(clip.translations, dtype=np.float32)
        rotations = np.ascontiguousarray(clip.rotations, dtype=np.float32)
        ones = Vt.Vec3hArray.FromNumpy(np.ones((clip.num_joints, 3), dtype=np.float16))
        for f in range(frames):
            layer.SetTimeSample(t_attr, float(f), Vt.Vec3fArray.FromNumpy(translations[f]))
            layer.SetTimeSample(r_attr, float(f), Vt.QuatfArray.FromNumpy(rotations[f]))
            layer.SetTimeSample(s_attr, float(f), ones)
        for name, frames_range in sorted((stationary or {}).items()):
            tag_stationary(anim, name, frames_range)
    layer.Save()
    return layer


@dataclass
class AgentSpec:
    """One agent of a crowd stage.

    Attributes:
        name: prim name under the crowd scope, e.g. ``agent_0003``.
        clip: the clip it plays; clips are written once per distinct name.
        position: translation of the agent's SkelRoot, stage units.
        yaw: rotation about the stage up axis, degrees (counter-clockwise
            seen from above).
        time_offset: shot time code at which the clip's frame 0 plays (the
            reference's layer offset).
    """

    name: str
    clip: Clip
    position: Sequence[float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    time_offset: float = 0.0


def _relative_asset_path(target: Path, anchor_dir: Path) -> str:
    rel = os.path.relpath(target.resolve(), anchor_dir.resolve()).replace(os.sep, "/")
    return rel if rel.startswith("../") else "./" + rel


def build_crowd_stage(path: PathLike, agents: Iterable[AgentSpec], up_axis: str = "Y",
                      meters_per_unit: float = 1.0, fps: float = 24.0,
                      clips_dir: PathLike | None = None, clip_format: str = "usda",
                      crowd_path: str = "/World/Crowd",
                      stationary: Mapping[str, Mapping[str, Sequence[int]]] | None = None,
                      ) -> Usd.Stage:
    """Write a shot stage of agents that reference shared clip layers.

    Args:
        path: the stage's root layer file.
        agents: the agents, in prim order; names must be unique.
        up_axis, meters_per_unit, fps: stage metadata. Every clip must have
            been made with the same up axis, units and fps.
        clips_dir: folder for the clip layers (default: ``clips`` beside the
            stage); each clip is written once, as ``<clip name>.<clip_format>``.
        clip_format: ``"usda"`` or ``"usdc"``.
        crowd_path: the scope that holds the agents.
        stationary: optional ``{clip name: {range name: (first, last)}}``
            stationary tags to author on those clips' animations.

    Returns:
        The stage, opened on the saved root layer. Its start and end time codes
        cover every agent's clip as offset.
    """
    if up_axis not in ("Y", "Z"):
        raise ValueError(f"up_axis must be 'Y' or 'Z', got {up_axis!r}")
    if clip_format not in ("usda", "usdc"):
        raise ValueError(f"clip_format must be 'usda' or 'usdc', got {clip_format!r}")
    agents = list(agents)
    path = Path(path)
    clips_dir = Path(clips_dir) if clips_dir is not None else path.parent / "clips"

    clips: dict[str, Clip] = {}
    names: set[str] = set()
    for agent in agents:
        if agent.name in names:
            raise ValueError(f"agent name {agent.name!r} is used twice")
        names.add(agent.name)
        clip = agent.clip
        known = clips.setdefault(clip.name, clip)
        if known is not clip:
            raise ValueError(f"two different clips are named {clip.name!r}")
        if (clip.up_axis, clip.meters_per_unit, clip.fps) != (up_axis, meters_per_unit, fps):
            raise ValueError(
                f"clip {clip.name!r} is {clip.up_axis}-up, {clip.meters_per_unit} m per unit at "
                f"{clip.fps} fps; the stage is {up_axis}-up, {meters_per_unit} m per unit at "
                f"{fps} fps")
    unknown = set(stationary or {}) - set(clips)
    if unknown:
        raise ValueError(f"stationary tags for clips no agent plays: {sorted(unknown)}")

    assets = {}
    for name, clip in clips.items():
        clip_file = clips_dir / f"{name}.{clip_format}"
        write_clip_layer(clip, clip_file, (stationary or {}).get(name))
        assets[name] = _relative_asset_path(clip_file, path.parent)

    start = min([0.0] + [float(a.time_offset) for a in agents])
    end = max([0.0] + [float(a.time_offset) + a.clip.num_frames - 1 for a in agents])
    rotate_op = "xformOp:rotate" + up_axis
    crowd = Sdf.Path(crowd_path)
    if not crowd.IsAbsolutePath() or not crowd.IsPrimPath() or crowd.pathElementCount < 1:
        raise ValueError(f"crowd_path must be an absolute prim path, got {crowd_path!r}")

    with Sdf.ChangeBlock():
        layer = clip_layer.new_layer(path)
        sdf.set_stage_metadata(layer, up_axis, meters_per_unit)
        sdf.set_time_metadata(layer, fps, start, end)
        layer.defaultPrim = crowd.GetPrefixes()[0].name
        parent = layer.pseudoRoot
        for prefix in crowd.GetPrefixes():
            parent = Sdf.PrimSpec(parent, prefix.name, Sdf.SpecifierDef, "Xform")
        op_order = Vt.TokenArray(["xformOp:translate", rotate_op])
        for agent in agents:
            root = Sdf.PrimSpec(parent, agent.name, Sdf.SpecifierDef, "SkelRoot")
            sdf.prepend_api(root, AGENT_API)
            sdf.attr(root, "xformOp:translate", Sdf.ValueTypeNames.Double3,
                     Gf.Vec3d(*(float(v) for v in agent.position)))
            sdf.attr(root, rotate_op, Sdf.ValueTypeNames.Float, float(agent.yaw))
            sdf.attr(root, "xformOpOrder", Sdf.ValueTypeNames.TokenArray, op_order, uniform=True)
            skel = Sdf.PrimSpec(root, CLIP_SKELETON_PATH.name, Sdf.SpecifierDef, "Skeleton")
            offset = Sdf.LayerOffset(float(agent.time_offset), 1.0)
            skel.referenceList.Prepend(
                Sdf.Reference(assets[agent.clip.name], CLIP_SKELETON_PATH, offset))
    layer.Save()
    return Usd.Stage.Open(layer)


# --- constraints and tags --------------------------------------------------

def define_mocap_prim(stage: Usd.Stage, path: str | Sdf.Path, type_name: str,
                      attributes: Mapping[str, tuple[Sdf.ValueTypeName, object]] | None = None,
                      relationships: Mapping[str, Sequence[str | Sdf.Path]] | None = None,
                      ) -> Usd.Prim:
    """Define a prim of a mocapEdit type and author its properties.

    Works with or without the schema registered. Attributes are given as
    ``{name: (value type, value)}`` and authored uniform unless the
    registered schema says otherwise; relationships as ``{name: [targets]}``.
    """
    prim = stage.DefinePrim(Sdf.Path(str(path)), type_name)
    for name, (type_name_, value) in (attributes or {}).items():
        clip_layer.set_property(prim, name, type_name_, value)
    for name, targets in (relationships or {}).items():
        rel = prim.GetRelationship(name) or prim.CreateRelationship(name, False)
        rel.SetTargets([Sdf.Path(str(t)) for t in targets])
    return prim


def _strength(strength: str, weight: float) -> dict:
    if strength not in ("hard", "soft"):
        raise ValueError(f"strength must be 'hard' or 'soft', got {strength!r}")
    return {"strength": (Sdf.ValueTypeNames.Token, strength), "weight": (Sdf.ValueTypeNames.Double, float(weight))}


def add_position_constraint(stage: Usd.Stage, path: str | Sdf.Path, agent_path: str | Sdf.Path,
                            frame: int, position: Sequence[float], strength: str = "hard",
                            weight: float = 1.0) -> Usd.Prim:
    """Define a MocapPositionConstraint: the agent's root is at `position`
    (world space, stage units) at `frame` of its clip."""
    vt = Sdf.ValueTypeNames
    return define_mocap_prim(
        stage, path, "MocapPositionConstraint",
        attributes={
            "frame": (vt.Int, int(frame)),
            "position": (vt.Point3d, Gf.Vec3d(*(float(v) for v in position))),
            **_strength(strength, weight),
        },
        relationships={"agent": [agent_path]})


def add_time_constraint(stage: Usd.Stage, path: str | Sdf.Path, agent_path: str | Sdf.Path,
                        frame: int, time: float, strength: str = "hard", weight: float = 1.0) -> Usd.Prim:
    """Define a MocapTimeConstraint: the agent's `frame` plays at shot time code `time`."""
    vt = Sdf.ValueTypeNames
    return define_mocap_prim(
        stage, path, "MocapTimeConstraint",
        attributes={"frame": (vt.Int, int(frame)), "time": (vt.Double, float(time)),
                    **_strength(strength, weight)},
        relationships={"agent": [agent_path]})


def add_sync_constraint(stage: Usd.Stage, path: str | Sdf.Path, agent_path: str | Sdf.Path, frame: int,
                        target_path: str | Sdf.Path, target_frame: int, offset: float = 0.0,
                        strength: str = "hard", weight: float = 1.0) -> Usd.Prim:
    """Define a MocapSyncConstraint: the agent's `frame` plays `offset` time codes after
    the target's `target_frame`."""
    vt = Sdf.ValueTypeNames
    return define_mocap_prim(
        stage, path, "MocapSyncConstraint",
        attributes={"frame": (vt.Int, int(frame)), "targetFrame": (vt.Int, int(target_frame)),
                    "offset": (vt.Double, float(offset)), **_strength(strength, weight)},
        relationships={"agent": [agent_path], "target": [target_path]})


def add_relative_constraint(stage: Usd.Stage, path: str | Sdf.Path, agent_path: str | Sdf.Path, frame: int,
                            target_path: str | Sdf.Path, target_frame: int, offset: Sequence[float],
                            space: str = "world", strength: str = "hard", weight: float = 1.0) -> Usd.Prim:
    """Define a MocapRelativeConstraint: the agent's root at `frame` is the target's root at
    `target_frame` plus `offset` (stage units; world axes, or the target's heading frame when
    `space` is "target")."""
    if space not in ("world", "target"):
        raise ValueError(f"space must be 'world' or 'target', got {space!r}")
    vt = Sdf.ValueTypeNames
    return define_mocap_prim(
        stage, path, "MocapRelativeConstraint",
        attributes={"frame": (vt.Int, int(frame)), "targetFrame": (vt.Int, int(target_frame)),
                    "offset": (vt.Vector3d, Gf.Vec3d(*(float(v) for v in offset))),
                    "space": (vt.Token, space), **_strength(strength, weight)},
        relationships={"agent": [agent_path], "target": [target_path]})


def add_group(stage: Usd.Stage, path: str | Sdf.Path, members: Sequence[str | Sdf.Path],
              stiffness: float = 1.0) -> Usd.Prim:
    """Define a MocapAgentGroup of `members` that keeps its formation (`stiffness` weights it)."""
    return define_mocap_prim(stage, path, "MocapAgentGroup",
                             attributes={"stiffness": (Sdf.ValueTypeNames.Double, float(stiffness))},
                             relationships={"members": list(members)})


def add_path_curve(stage: Usd.Stage, path: str | Sdf.Path, points: Sequence[Sequence[float]],
                   agents: Sequence[str | Sdf.Path] = (), basis: str = "catmullRom",
                   curve_type: str = "cubic", wrap: str = "pinned") -> Usd.Prim:
    """Define a BasisCurves path curve (world-space points, stage units) and point each
    agent's ``mocap:pathCurve`` at it."""
    curve = UsdGeom.BasisCurves.Define(stage, Sdf.Path(str(path)))
    pts = [Gf.Vec3f(*(float(v) for v in p)) for p in points]
    curve.CreatePointsAttr(Vt.Vec3fArray(pts))
    curve.CreateCurveVertexCountsAttr(Vt.IntArray([len(pts)]))
    curve.CreateTypeAttr(curve_type)
    curve.CreateBasisAttr(basis)
    curve.CreateWrapAttr(wrap)
    curve.CreatePurposeAttr(UsdGeom.Tokens.guide)
    for agent in agents:
        prim = stage.GetPrimAtPath(Sdf.Path(str(agent)))
        rel = prim.GetRelationship("mocap:pathCurve") or prim.CreateRelationship("mocap:pathCurve", False)
        rel.SetTargets([curve.GetPath()])
    return curve.GetPrim()


def dense_crowd_paths(agents: int, frames: int = 240, fps: float = 24.0, density: float = 0.25,
                      seed: int = 1) -> list[np.ndarray]:
    """Ground paths (metres) of a dense crowd crossing at random: ``agents`` walkers start at
    random places in a square holding ``density`` agents per square metre and walk straight
    at 1.4 m/s (+-20 %) in random directions, with a 3 cm lateral sway at one step per
    second. Returns #A arrays of (frames, 2), one position per frame."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(agents / density)
    start = rng.uniform(0.0, side, (agents, 2))
    heading = rng.uniform(0.0, 2 * np.pi, agents)
    speed = 1.4 * rng.uniform(0.8, 1.2, agents) / fps
    t = np.arange(frames, dtype=np.float64)
    d = np.stack([np.cos(heading), np.sin(heading)], 1)
    across = np.stack([-d[:, 1], d[:, 0]], 1)
    sway = 0.03 * np.sin(2 * np.pi * t[None, :] / fps + rng.uniform(0, 2 * np.pi, (agents, 1)))
    paths = start[:, None] + t[None, :, None] * (speed[:, None] * d)[:, None] + sway[..., None] * across[:, None]
    return list(paths)


def leg_inputs(rng: np.random.Generator, agents: int, poses: int, reach: float, smooth: Sequence[int],
               weights: np.ndarray):
    """Inputs of the foot-locking job (:class:`mocapedit.solve.footlock.LegInputs`) for #agents x
    #poses walking-like pairs of legs, Y-up, in metres: hips 0.9 m up and 0.2 m apart, thigh
    0.45 m, shin 0.42 m, knees bent 3 to 35 degrees forwards, random world rotations; each
    target is its ankle moved by a normal offset of ``reach`` metres per axis. ``weights``
    (#agents * #poses, 2) and ``smooth`` (#agents,) are passed through."""
    from mocapedit.solve.footlock import LegInputs
    n = agents * poses
    hip = np.zeros((n, 2, 3))
    hip[:, 0, 0], hip[:, 1, 0] = 0.1, -0.1
    hip[:, :, 1] = 0.9 + 0.02 * rng.standard_normal((n, 1))
    bend = rng.uniform(0.05, 0.6, (n, 2))
    thigh, shin = 0.45, 0.42
    knee = hip + np.stack([np.zeros_like(bend), -thigh * np.cos(bend), thigh * np.sin(bend)], -1)
    ankle = knee + np.stack([np.zeros_like(bend), -shin * np.cos(bend), -shin * np.sin(bend)], -1)

    def quats(scale):
        q = np.concatenate([scale * rng.standard_normal((n, 2, 3)), np.ones((n, 2, 1))], -1)
        return q / np.linalg.norm(q, axis=-1, keepdims=True)

    return LegInputs(
        offsets=np.arange(0, n + 1, poses, dtype=np.int64), smooth=np.asarray(smooth, dtype=np.int64),
        up=np.array([0.0, 1.0, 0.0]), hip=hip, knee=knee, ankle=ankle, parent_rot=quats(0.2), hip_rot=quats(0.3),
        knee_rot=quats(0.3), ankle_rot=quats(0.3), target=ankle + reach * rng.standard_normal((n, 2, 3)),
        target_rot=quats(0.4), weight=np.asarray(weights, dtype=np.float64),
        hinge=np.cross(knee - hip, ankle - hip))
