"""Writes an imported BVH clip as a UsdSkel layer; drives :mod:`mocapedit.formats.bvh` chunk by chunk.

The layer has the layout of :mod:`mocapedit.usd.clip_layer`, as generated clips have, so an
imported clip is referenced into an agent exactly like a generated one::

    def Skeleton "Skel"                     # the default prim: joints, restTransforms,
        (SkelBindingAPI)                    # bindTransforms, skel:animationSource -> <Anim>
        def SkelAnimation "Anim"            # joints; translations and rotations sampled at
                                            # time codes 0..F-1; scales (constant ones)

With ``agent=True`` the default prim is instead a ready agent that ``mocapedit solve`` and
usdview take as it is (``<Clip>`` is the file name made a valid identifier)::

    def SkelRoot "<Clip>" (MocapAgentAPI)   # mocap:rootJoint, mocap:hipJoint if given
        def Skeleton "Skel"
            def SkelAnimation "Anim"

The layer sets ``metersPerUnit``, ``upAxis``, ``timeCodesPerSecond``, ``framesPerSecond``
and the time range, and records its source in ``customLayerData``; the BVH joint names
are kept in the Skeleton's ``customData["bvhJointNames"]``.

Samples are authored through Sdf inside one change block per chunk, from numpy with
``Vt.*Array.FromNumpy``; a clip that is streamed in is authored as it streams. The layer
is saved through a temporary file and a rename; on any error nothing is written.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np
from pxr import Sdf, Vt

from mocapedit.formats import bvh
from mocapedit.usd import clip_layer, edits_format, outputs, sdf, writer
from mocapedit.model.errors import MocapEditError
from mocapedit.model.progress import Progress, Silent

#: Names of the Skeleton and SkelAnimation prims, as in every clip layer.
SKELETON = clip_layer.SKELETON_PATH.name
ANIMATION = clip_layer.ANIMATION_PATH.name


@dataclass
class ImportSettings:
    """How a BVH file becomes a clip layer (the ``import-bvh`` options)."""
    scale: float = 1.0                 # stage units per BVH length unit
    meters_per_unit: float = 0.01      # metersPerUnit of the written layer
    up_axis: str = "Y"                 # upAxis of the written layer ("Y" or "Z")
    fps: float | None = None           # None: from the file's Frame Time
    position_mode: str = "auto"        # "auto" | "absolute" | "relative" (see bvh.position_modes)
    end_sites: bool = False            # also import End Sites as joints
    agent: bool = False                # author a SkelRoot with MocapAgentAPI
    root_joint: str | None = None      # mocap:rootJoint of the agent (BVH name, token or path)
    hip_joint: str | None = None       # mocap:hipJoint of the agent
    name: str | None = None            # default prim name; None: "Skel", or the file name for an agent
    chunk_frames: int = bvh.CHUNK_FRAMES


@dataclass
class ImportResult:
    source: str
    output: str | None
    layer: Sdf.Layer
    prim: str                          # the default prim's path
    skeleton: str                      # the Skeleton prim's path
    animation: str                     # the SkelAnimation prim's path
    frames: int
    fps: float
    joints: int
    height_m: float                    # height of the pose of frame 0 (lowest to highest joint), metres
    position_modes: dict[str, str] = field(default_factory=dict)  # joints with position channels


def clip_name(path: str) -> str:
    """A valid prim name from a file name (``131_01 walk.bvh`` -> ``_131_01_walk``)."""
    stem = os.path.splitext(os.path.basename(path))[0]
    name = re.sub(r"[^A-Za-z0-9_]", "_", stem) or "clip"
    return "_" + name if name[0].isdigit() else name


class ClipLayerBuilder:
    """Authors the clip layer: the skeleton once, then the samples chunk after chunk."""

    def __init__(self, name: str, pose: bvh.SkeletonPose, settings: ImportSettings, fps: float,
                 provenance: dict, root_joint: str | None, hip_joint: str | None):
        self.layer = Sdf.Layer.CreateAnonymous(".usda")
        self.root = Sdf.Path.absoluteRootPath.AppendChild(name)
        self.skel_path = self.root.AppendChild(SKELETON) if settings.agent else self.root
        self.anim_path = self.skel_path.AppendChild(ANIMATION)
        self.frames = 0
        layer = self.layer
        sdf.set_time_metadata(layer, fps, start=0)
        layer.defaultPrim = name
        sdf.set_stage_metadata(layer, settings.up_axis, settings.meters_per_unit)
        layer.documentation = f"Motion capture imported from {provenance['source']} by mocapedit import-bvh."
        edits_format.write(layer, {"bvh": provenance})
        joints = Vt.TokenArray(pose.joints)
        with Sdf.ChangeBlock():
            if settings.agent:
                top = Sdf.PrimSpec(layer.pseudoRoot, name, Sdf.SpecifierDef, "SkelRoot")
                top.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["MocapAgentAPI"]))
                if root_joint:
                    sdf.attr(top, "mocap:rootJoint", Sdf.ValueTypeNames.Token, root_joint, uniform=True)
                if hip_joint:
                    sdf.attr(top, "mocap:hipJoint", Sdf.ValueTypeNames.Token, hip_joint, uniform=True)
                skel = Sdf.PrimSpec(top, SKELETON, Sdf.SpecifierDef, "Skeleton")
            else:
                skel = Sdf.PrimSpec(layer.pseudoRoot, name, Sdf.SpecifierDef, "Skeleton")
            skel.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["SkelBindingAPI"]))
            skel.customData = {"bvhJointNames": Vt.StringArray(pose.names)}
            sdf.attr(skel, "joints", Sdf.ValueTypeNames.TokenArray, joints, uniform=True)
            sdf.attr(skel, "restTransforms", Sdf.ValueTypeNames.Matrix4dArray,
                  Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(pose.rest_transforms)), uniform=True)
            sdf.attr(skel, "bindTransforms", Sdf.ValueTypeNames.Matrix4dArray,
                  Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(pose.bind_transforms)), uniform=True)
            rel = Sdf.RelationshipSpec(skel, "skel:animationSource", custom=False)
            rel.targetPathList.explicitItems = [self.anim_path]
            anim = Sdf.PrimSpec(skel, ANIMATION, Sdf.SpecifierDef, "SkelAnimation")
            sdf.attr(anim, "joints", Sdf.ValueTypeNames.TokenArray, joints, uniform=True)
            # BVH has no scale channels: one constant value serves every time.
            sdf.attr(anim, "scales", Sdf.ValueTypeNames.Half3Array,
                  Vt.Vec3hArray.FromNumpy(np.ones((len(pose.joints), 3), np.float16)))
            self._translations = sdf.attr(anim, "translations", Sdf.ValueTypeNames.Float3Array).path
            self._rotations = sdf.attr(anim, "rotations", Sdf.ValueTypeNames.QuatfArray).path

    def add(self, translations: np.ndarray, rotations: np.ndarray) -> None:
        """Authors the next frames: (n,J,3) translations and (n,J,4) (x,y,z,w) rotations."""
        t = np.ascontiguousarray(translations, dtype=np.float32)
        r = np.ascontiguousarray(rotations, dtype=np.float32)
        layer, start = self.layer, self.frames
        with Sdf.ChangeBlock():
            for i in range(t.shape[0]):
                time = float(start + i)
                layer.SetTimeSample(self._translations, time, Vt.Vec3fArray.FromNumpy(t[i]))
                layer.SetTimeSample(self._rotations, time, Vt.QuatfArray.FromNumpy(r[i]))
        self.frames += t.shape[0]

    def finish(self) -> Sdf.Layer:
        self.layer.endTimeCode = max(self.frames - 1, 0)
        return self.layer


def _joint_path(skeleton: bvh.BvhSkeleton, pose: bvh.SkeletonPose, name: str | None, what: str) -> str | None:
    if not name:
        return None
    index = skeleton.find(name)
    if index is None:
        raise MocapEditError(f"{skeleton.path}: {what} '{name}' is not a joint of this file (its joints start "
                             f"{', '.join(skeleton.names[:4])}{', ...' if skeleton.joint_count > 4 else ''})")
    return pose.joints[index]


def build_clip(source: str, settings: ImportSettings | None = None, progress: Progress | None = None
               ) -> ImportResult:
    """Reads a BVH file (streamed in chunks) into a clip layer held in memory.

    Raises:
      MocapEditError: the file is malformed (the message names the file and line), has no
        frames, or names a root or hip joint it does not have.
    """
    settings = settings or ImportSettings()
    progress = progress or Silent()
    source = str(source)
    if not os.path.isfile(source):
        raise MocapEditError(f"{source}: no such file")
    skeleton = bvh.read_header(source)
    if skeleton.frame_count == 0:
        raise MocapEditError(f"{source}:{skeleton.frames_line}: 'Frames: 0': the clip has no frames")
    fps = float(settings.fps) if settings.fps else skeleton.fps
    if not (np.isfinite(fps) and fps > 0):
        raise MocapEditError(f"{source}: frame rate must be positive, got {fps}")
    name = settings.name or (clip_name(source) if settings.agent else SKELETON)
    if not Sdf.Path.IsValidIdentifier(name):
        raise MocapEditError(f"prim name '{name}' is not a valid USD identifier")
    task = progress.task(f"import {os.path.basename(source)}", skeleton.frame_count, unit="frames")

    builder = converter = None
    for values in bvh.iter_frames(source, settings.chunk_frames):
        if converter is None:
            # The first chunk decides how position channels combine with OFFSETs.
            modes = bvh.position_modes(skeleton, values, settings.position_mode)
            converter = bvh.Converter(skeleton, scale=settings.scale, up_axis=settings.up_axis,
                                      modes=modes, end_sites=settings.end_sites)
            pose = converter.pose
            root_joint = _joint_path(skeleton, pose, settings.root_joint, "root joint")
            hip_joint = _joint_path(skeleton, pose, settings.hip_joint, "hip joint")
            provenance = {"source": os.path.basename(source), "frameTime": skeleton.frame_time,
                          "scale": float(settings.scale)}
            with_positions = {skeleton.names[j]: modes[j] for j, labels in enumerate(skeleton.channels)
                              if any(lab.lower().endswith("position") for lab in labels)}
            if with_positions:
                provenance["positionChannels"] = with_positions
            builder = ClipLayerBuilder(name, pose, settings, fps, provenance, root_joint, hip_joint)
        translations, rotations = converter(values)
        if builder.frames == 0:  # the character as it stands in frame 0, not its rest pose
            height = pose.height(translations[0], rotations[0], settings.up_axis) * settings.meters_per_unit
        builder.add(translations, rotations)
        task.update(builder.frames)
    layer = builder.finish()
    task.done(f"{converter.joint_count} joints, {fps:g} fps")
    return ImportResult(source=source, output=None, layer=layer, prim=str(builder.root),
                        skeleton=str(builder.skel_path), animation=str(builder.anim_path), frames=builder.frames,
                        fps=fps, joints=converter.joint_count, height_m=height, position_modes=with_positions)


def import_bvh(source: str, output: str, settings: ImportSettings | None = None,
               progress: Progress | None = None) -> ImportResult:
    """Imports one BVH file and saves the clip layer atomically (``.usda`` or ``.usdc``)."""
    outputs.check_outputs([outputs.Output(str(output), "-o", stem=".clip")], [source])
    result = build_clip(source, settings, progress)
    writer.save_layer(result.layer, str(output))
    result.output = str(output)
    return result


def import_many(sources: list[str], out_dir: str, settings: ImportSettings | None = None,
                progress: Progress | None = None, ext: str = ".usda", keep_going: bool = False
                ) -> tuple[list[ImportResult], list[tuple[str, str]]]:
    """Imports several files into ``out_dir/<stem><ext>``.

    All or nothing by default: every layer goes to a temporary file first, and the files
    are renamed into place only when every import succeeded. With ``keep_going`` each good
    file is written and the failures are returned as (source, message).
    """
    progress = progress or Silent()
    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise MocapEditError(f"-o {out_dir}: several clips are written into a folder, but this is a file; "
                             "give a folder, or one .usda/.usdc file for one .bvh")
    targets = [os.path.join(out_dir, os.path.splitext(os.path.basename(s))[0] + ext) for s in sources]
    seen: dict[str, str] = {}
    for s, t in zip(sources, targets):
        if t in seen:
            raise MocapEditError(f"{s}: would be written to {t} like {seen[t]}; rename one of them")
        seen[t] = s
    outputs.check_outputs([outputs.Output(t, f"output for {s}") for s, t in zip(sources, targets)], sources)
    done: list[ImportResult] = []
    failed: list[tuple[str, str]] = []
    files = progress.task("import files", len(sources), unit="files")
    with outputs.Writes() as staged:
        for i, (src, dst) in enumerate(zip(sources, targets)):
            try:
                result = build_clip(src, settings, progress)
            except MocapEditError as exc:
                if not keep_going:
                    raise
                failed.append((src, str(exc)))
                continue
            if keep_going:
                writer.save_layer(result.layer, dst)
            else:
                staged.add(dst, writer.export_layer(result.layer))
            result.output = dst
            result.layer = None  # the layers of a batch are not kept in memory
            done.append(result)
            files.update(i + 1)
    files.done()
    return done, failed


__all__ = ["ImportSettings", "ImportResult", "ClipLayerBuilder", "build_clip", "import_bvh", "import_many",
           "clip_name"]
