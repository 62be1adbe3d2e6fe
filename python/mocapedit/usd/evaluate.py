"""Evaluate a composed stage by UsdSkel forward kinematics: stage in, numpy arrays out.

An edited stage is judged by what plain UsdSkel plays: these functions compute joint world
positions and matrices of agents on the composed stage, and hand the arrays to the measures of
:mod:`mocapedit.inspect.metrics` (foot skate, plausibility). Positions are world space in stage
units; times are time codes (default: the animation's authored joint-transform samples as
composed).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, NamedTuple, Sequence, Union

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdSkel

from mocapedit.model.names import default_facing_joint, default_foot_joints

__all__ = ["StageUnits", "stage_units", "skeleton_candidates", "sample_times", "joint_world_positions", "agent_root_positions",
           "joint_world_matrices", "joint_transforms", "FootSamples", "foot_positions"]

PathLike = Union[str, Sdf.Path]


class StageUnits(NamedTuple):
    """What a stage's numbers mean: its up axis ("Y" or "Z"), metres per unit, time codes per second."""
    up_axis: str
    meters_per_unit: float
    time_codes_per_second: float


def stage_units(stage: Usd.Stage) -> StageUnits:
    """The stage's :class:`StageUnits`."""
    return StageUnits(UsdGeom.GetStageUpAxis(stage), UsdGeom.GetStageMetersPerUnit(stage),
                      stage.GetTimeCodesPerSecond())


def shot_range(stage: Usd.Stage) -> tuple[float | None, float | None]:
    """The stage's start and end time codes where its root layer authors them (None where not)."""
    root = stage.GetRootLayer()
    return (float(stage.GetStartTimeCode()) if root.HasStartTimeCode() else None,
            float(stage.GetEndTimeCode()) if root.HasEndTimeCode() else None)


class _Skel:
    """A skeleton of an agent, resolved once: its query, joints and composed sample times."""

    def __init__(self, stage: Usd.Stage, path: PathLike, cache: UsdSkel.Cache | None = None):
        prim = stage.GetPrimAtPath(Sdf.Path(str(path)))
        if not prim or not prim.IsValid():
            raise ValueError(f"{path}: no prim at this path")
        skel = _find_skeleton(prim)
        self.path = str(path)
        self.skeleton = skel
        cache = cache or UsdSkel.Cache()
        # Populate so animation sources bound (and inherited) under the SkelRoot resolve.
        roots = []
        for p in (prim, skel.GetPrim()):
            root = UsdSkel.Root(p) if p.IsA(UsdSkel.Root) else UsdSkel.Root.Find(p)
            if root and root.GetPath() not in [r.GetPath() for r in roots]:
                roots.append(root)
        for root in roots:
            cache.Populate(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))
        self.query = cache.GetSkelQuery(skel)
        if not self.query:
            raise ValueError(f"{skel.GetPath()}: skeleton is not valid "
                             "(check its joints and rest pose)")
        self.joints = [str(j) for j in self.query.GetJointOrder()]
        anim = self.query.GetAnimQuery()
        samples = anim.GetJointTransformTimeSamples() if anim else []
        self.sample_times = _distinct_times(samples)

    def joint_index(self, joint) -> int:
        if isinstance(joint, (int, np.integer)):
            if not 0 <= int(joint) < len(self.joints):
                raise ValueError(f"{self.skeleton.GetPath()}: joint index {joint} out of range "
                                 f"0..{len(self.joints) - 1}")
            return int(joint)
        name = str(joint)
        if name in self.joints:
            return self.joints.index(name)
        hits = [k for k, j in enumerate(self.joints) if j.rsplit("/", 1)[-1] == name]
        if len(hits) != 1:
            why = "no joint" if not hits else "several joints"
            raise ValueError(f"{self.skeleton.GetPath()}: {why} named {name!r}")
        return hits[0]

    def default_times(self) -> np.ndarray:
        if len(self.sample_times) == 0:
            raise ValueError(f"{self.path}: the animation of {self.skeleton.GetPath()} has no time "
                             "samples; pass times explicitly")
        return self.sample_times

    def world_translations(self, xform_cache: UsdGeom.XformCache) -> np.ndarray:
        return self.world_matrices(xform_cache)[:, 3, :3]  # row-vector: translation is the last row

    def world_matrices(self, xform_cache: UsdGeom.XformCache) -> np.ndarray:
        prim = self.skeleton.GetPrim()
        if prim.IsInstanceProxy():
            # The query is the prototype's skeleton, which sits at the prototype's origin: the
            # instance's own transform is the proxy's.
            skel = np.asarray(self.query.ComputeJointSkelTransforms(xform_cache.GetTime()))
            return skel @ np.asarray(xform_cache.GetLocalToWorldTransform(prim))
        return np.asarray(self.query.ComputeJointWorldTransforms(xform_cache))


def skeleton_candidates(prim: Usd.Prim) -> list[Sdf.Path]:
    """The skeletons an agent prim may play, by the strongest evidence there is: the prim itself
    if it is a Skeleton; else the skeleton bound on it (``skel:skeleton``); else the skeletons its
    geometry below binds (UsdSkel skins each mesh by its own binding); else the skeleton it
    inherits from an ancestor's binding; else the Skeleton prims below it (through instances).
    One path when the choice is clear, several when it is not (a prop's skeleton beside the
    body's), none when there is no skeleton."""
    if prim.IsA(UsdSkel.Skeleton):
        return [prim.GetPath()]
    stage = prim.GetStage()

    def skeletons(rel) -> list[Sdf.Path]:
        return [t for t in (rel.GetForwardedTargets() if rel else []) if stage.GetPrimAtPath(t).IsA(UsdSkel.Skeleton)]

    own = skeletons(prim.GetRelationship("skel:skeleton"))
    if own:
        return own[:1]
    bound, found = [], []
    for p in Usd.PrimRange(prim, Usd.TraverseInstanceProxies()):
        if p.IsA(UsdSkel.Skeleton):
            found.append(p.GetPath())
        if p != prim:
            bound.extend(t for t in skeletons(p.GetRelationship("skel:skeleton")) if t not in bound)
    if bound:
        return bound
    inherited = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    return [inherited.GetPath()] if inherited else found


def _find_skeleton(prim: Usd.Prim) -> UsdSkel.Skeleton:
    candidates = skeleton_candidates(prim)
    if not candidates:
        raise ValueError(f"{prim.GetPath()}: no Skeleton at or below this prim")
    if len(candidates) > 1:
        names = ", ".join(str(c) for c in candidates)
        raise ValueError(f"{prim.GetPath()}: several skeletons ({names}); name the Skeleton prim")
    return UsdSkel.Skeleton.Get(prim.GetStage(), candidates[0])


def _times(times) -> np.ndarray:
    out = []
    for t in times:
        if isinstance(t, Usd.TimeCode):
            if t.IsDefault():
                raise ValueError("the default time code has no place among sample times")
            t = t.GetValue()
        out.append(float(t))
    return np.asarray(out, dtype=np.float64)


#: Time codes: two samples closer than this are one. A value clip maps its samples to shot
#: times by arithmetic that rounds (-8.999999999999998 for -9), so an animation whose
#: translations play through a clip and whose rotations are baked on the shot frames composes
#: both, and FK between the two saw a body turn at 1e10 degrees per second.
SAME_TIME = 1e-6


def _distinct_times(samples) -> np.ndarray:
    """(T,) increasing time codes, the first of any run closer than SAME_TIME kept."""
    times = np.asarray(sorted(samples), dtype=np.float64)
    if len(times) < 2:
        return times
    return times[np.r_[True, np.diff(times) > SAME_TIME]]


def sample_times(stage: Usd.Stage, agent_path: PathLike) -> np.ndarray:
    """(T,) the time codes of the agent's joint-transform samples as composed, increasing."""
    return _Skel(stage, agent_path).sample_times


def joint_world_positions(stage: Usd.Stage, skel_or_root_path: PathLike,
                          times: Iterable | None = None) -> np.ndarray:
    """World positions of every joint by UsdSkel forward kinematics: ``(T, J, 3)`` stage units.

    ``skel_or_root_path`` names a Skeleton, or a SkelRoot / agent prim from which the skeleton is
    found (its ``skel:skeleton`` binding, else the one skeleton below it). ``times`` are time codes
    (default: the animation's authored joint-transform samples as composed). Joints are in the
    skeleton's joint order.
    """
    skel = _Skel(stage, skel_or_root_path)
    t = skel.default_times() if times is None else _times(times)
    out = np.empty((len(t), len(skel.joints), 3))
    xfc = UsdGeom.XformCache()
    for k, tc in enumerate(t):
        xfc.SetTime(Usd.TimeCode(tc))
        out[k] = skel.world_translations(xfc)
    return out


def agent_root_positions(stage: Usd.Stage, agent_path, times: Iterable,
                         root_joint: Union[int, str] = 0) -> np.ndarray:
    """World position of one joint (default: the skeleton's root) for one or many agents.

    ``agent_path``: one path -> ``(T, 3)``; a sequence of paths -> ``(A, T, 3)``, all evaluated
    through one UsdSkel cache and one transform cache per time. ``root_joint``: index into the
    joint order, a full joint path or a unique joint name.
    """
    single = isinstance(agent_path, (str, Sdf.Path))
    paths = [agent_path] if single else list(agent_path)
    t = _times(times)
    cache = UsdSkel.Cache()
    skels = [_Skel(stage, p, cache) for p in paths]
    index = [s.joint_index(root_joint) for s in skels]
    out = np.empty((len(skels), len(t), 3))
    xfc = UsdGeom.XformCache()
    for k, tc in enumerate(t):
        xfc.SetTime(Usd.TimeCode(tc))
        for a, (s, j) in enumerate(zip(skels, index)):
            out[a, k] = s.world_translations(xfc)[j]
    return out[0] if single else out


def joint_world_matrices(stage: Usd.Stage, agent_path: PathLike, times: Iterable | None = None,
                         joint: Union[int, str, None] = None) -> tuple[np.ndarray, np.ndarray]:
    """World matrices of one joint by UsdSkel FK: ``(times (T,), matrices (T, 4, 4))``.

    ``joint``: index, full path or unique name (default :func:`~mocapedit.model.names.default_facing_joint`). ``times``:
    time codes (default: the animation's authored samples as composed). Matrices are USD's
    row-vector convention: row k is the joint's local axis k in world space, row 3 its position.
    """
    skel = _Skel(stage, agent_path)
    t = skel.default_times() if times is None else _times(times)
    j = default_facing_joint(skel.joints) if joint is None else skel.joint_index(joint)
    out = np.empty((len(t), 4, 4))
    xfc = UsdGeom.XformCache()
    for k, tc in enumerate(t):
        xfc.SetTime(Usd.TimeCode(tc))
        out[k] = skel.world_matrices(xfc)[j]
    return t, out


def played_frames(stage: Usd.Stage, agent_path: PathLike, times: Iterable) -> np.ndarray | None:
    """(T,) the (fractional) frame of its source clip the agent plays at each of ``times``, when
    its animation re-times the clip by a USD value clip (what an edits layer writes for time edits
    and locked legs); None when the animation plays its own samples. Frame k is the clip's k-th
    authored sample, as the source stage numbers them."""
    skel = _Skel(stage, agent_path)
    anim_query = skel.query.GetAnimQuery()
    if not anim_query:
        return None
    anim = anim_query.GetPrim()
    api = Usd.ClipsAPI(anim)
    clips = api.GetClips().get("default")
    if not clips or "times" not in clips or "primPath" not in clips:
        return None
    assets = api.ComputeClipAssetPaths("default")
    layer = Sdf.Layer.FindOrOpen(assets[0].resolvedPath) if len(assets) == 1 else None
    if layer is None:
        return None
    spec = Sdf.Path(clips["primPath"])
    own = np.unique(np.concatenate([np.asarray(layer.ListTimeSamplesForPath(spec.AppendProperty(c)), dtype=np.float64)
                                    for c in ("translations", "rotations", "scales")]))
    if own.size == 0:
        return None
    pairs = np.asarray(clips["times"], dtype=np.float64).reshape(-1, 2)
    clip_times = np.interp(_times(times), pairs[:, 0], pairs[:, 1])
    return np.interp(clip_times, own, np.arange(own.size, dtype=np.float64))


@dataclass(frozen=True)
class FootSamples:
    """World positions of an agent's feet by UsdSkel FK (:func:`foot_positions`).

    ``times`` (T,) increasing time codes; ``positions`` (T, F, 3) stage units; ``joints`` the F
    foot joints' paths; ``in_clip`` (T,) whether each time lies within the clip's samples."""

    times: np.ndarray
    positions: np.ndarray
    joints: tuple[str, ...]
    in_clip: np.ndarray


def foot_positions(stage: Usd.Stage, agent_path: PathLike, times: Iterable | None = None,
                   foot_joints: Sequence[Union[int, str]] | None = None) -> FootSamples:
    """Foot joints' world positions on the composed stage, as foot skate measures them.

    ``times``: time codes (default: the animation's authored samples as composed), sorted and
    made unique. ``foot_joints``: joint indices, full joint paths or unique joint names (default:
    :func:`~mocapedit.model.names.default_foot_joints`, joints named like a foot, toe or ankle,
    but not an end site).
    """
    skel = _Skel(stage, agent_path)
    t = np.unique(skel.default_times() if times is None else _times(times))
    if foot_joints is None:
        feet = default_foot_joints(skel.joints)
        if not feet:
            raise ValueError(f"{skel.skeleton.GetPath()}: no joint is named like a foot, toe or "
                             "ankle; pass foot_joints")
    else:
        feet = [skel.joint_index(j) for j in foot_joints]
    pos = np.empty((len(t), len(feet), 3))
    xfc = UsdGeom.XformCache()
    for k, tc in enumerate(t):
        xfc.SetTime(Usd.TimeCode(tc))
        pos[k] = skel.world_translations(xfc)[feet]
    if len(skel.sample_times):
        first, last = skel.sample_times[0], skel.sample_times[-1]
        in_clip = (t >= first - 1e-9) & (t <= last + 1e-9)
    else:
        in_clip = np.ones(len(t), dtype=bool)
    return FootSamples(t, pos, tuple(skel.joints[f] for f in feet), in_clip)


def joint_transforms(stage: Usd.Stage, agent_path: PathLike, times: Iterable
                     ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Every joint's world and local matrices by UsdSkel: ``(world (T, J, 4, 4), local (T, J, 4, 4),
    joint paths (J))`` at time codes ``times``, row-vector convention (row 3 the translation)."""
    skel = _Skel(stage, agent_path)
    world, local = [], []
    xfc = UsdGeom.XformCache()
    for t in _times(times):
        xfc.SetTime(Usd.TimeCode(t))
        world.append(skel.world_matrices(xfc))
        local.append(np.asarray(skel.query.ComputeJointLocalTransforms(Usd.TimeCode(t))))
    return np.array(world), np.array(local), skel.joints
