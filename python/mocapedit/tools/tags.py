"""Stationary tags: find the clips of a stage, measure their root motion, author the tags.

``detect(stage)`` proposes stationary ranges for every clip played on a stage, using
:mod:`mocapedit.geometry.stationary` for the numbers, and ``build_layer`` writes them as
``MocapStationaryAPI`` instances (``stationary:<name>:frames``, int2, inclusive) in a new
layer of ``over``s on the SkelAnimation prims: sub-layer it over the input to review
the tags, or keep it beside the clip.

A clip is found through the agents of the stage (prims with ``MocapAgentAPI``: their
root joint, or hip joint when the root carries no motion, as the solve reads them).
On a shot stage each agent's composed SkelAnimation prim is tagged, so the tags layer
sub-layered over the shot tags every agent; to tag a clip once for every shot that uses
it, run the command on the clip layer itself.
A clip layer with no agent (``mocapedit import-bvh`` without ``--agent``) is read the
same way through each Skeleton that binds an animation, as if it were an agent: that
view is made in the stage's session layer, in memory, and never saved.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from pxr import Gf, Sdf, Usd, UsdSkel

from mocapedit.usd import clip_layer, edits_format, reader, sdf, writer
from mocapedit.geometry import stationary, trajectory
from mocapedit.model.errors import MocapEditError

@dataclass
class ClipTags:
    animation: str                                  # SkelAnimation prim path on the stage
    agent: str                                      # the agent (or skeleton) it was measured on
    joint: str                                      # the joint whose motion was measured
    frames: int
    existing: list[tuple[str, int, int]]            # tags already on the clip
    ranges: list[stationary.StationaryRange] = field(default_factory=list)
    names: list[str] = field(default_factory=list)  # instance name of each range


def _view_skeletons_as_agents(stage: Usd.Stage, root_joint: str | None) -> None:
    """Applies MocapAgentAPI, in the session layer, to skeletons that no agent plays."""
    played = set()
    skeletons = []
    for prim in stage.Traverse():
        if reader.AGENT_API in prim.GetAppliedSchemas():
            played.add(str(prim.GetPath()))
            for child in Usd.PrimRange(prim):
                played.add(str(child.GetPath()))
        elif prim.IsA(UsdSkel.Skeleton):
            skeletons.append(prim)
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        for skel in skeletons:
            if str(skel.GetPath()) in played:
                continue
            binding = UsdSkel.BindingAPI(skel)
            if not binding.GetAnimationSourceRel() or not binding.GetAnimationSourceRel().GetTargets():
                continue
            skel.AddAppliedSchema(reader.AGENT_API)
            if root_joint:
                skel.CreateAttribute("mocap:rootJoint", Sdf.ValueTypeNames.Token, False,
                                     Sdf.VariabilityUniform).Set(root_joint)


def detect(stage: Usd.Stage, settings: stationary.DetectSettings | None = None,
           root_joint: str | None = None, animation: str | None = None, prefix: str = "auto"
           ) -> tuple[list[ClipTags], object]:
    """Proposes stationary ranges for each clip on the stage.

    Args:
      stage: the input; only its session layer is touched (in memory).
      settings: thresholds (:class:`~mocapedit.geometry.stationary.DetectSettings`).
      root_joint: measure this joint (name or joint path) instead of each agent's root.
      animation: only the clip at this SkelAnimation path.
      prefix: instance names are ``<prefix>1``, ``<prefix>2``, ... skipping names in use.

    Returns:
      (one ClipTags per clip, in path order; the stage info).
    """
    settings = settings or stationary.DetectSettings()
    try:
        settings.validate()
    except ValueError as exc:
        raise MocapEditError(str(exc)) from None
    if not Sdf.Path.IsValidIdentifier(prefix + "1"):
        raise MocapEditError(f"tag name prefix '{prefix}' is not a valid identifier")
    data, measured = clips_to_measure(stage, root_joint, animation)
    info = data.info
    out: dict[str, ClipTags] = {}
    chains: dict = {}   # skeleton-space chains of clips that several agents play, composed once
    for path, agent in measured:
        if root_joint:
            index = reader.resolve_joint(agent.joints, root_joint)
            if index is None:
                raise MocapEditError(f"--root-joint '{root_joint}' is not a joint of <{agent.skeleton_path}> "
                                     f"(its joints start {', '.join(agent.joints[:3])}, ...)")
            agent.root_joint = index
        clip = data.clip_of(agent)
        traj = trajectory.extract(agent, clip, info.up_axis, info.meters_per_unit, chains)
        world = trajectory.joint_world(agent, clip, traj.joint)
        heading = stationary.facing(world, info.up_axis)
        seconds = agent.sample_times / info.time_codes_per_second
        ranges = stationary.detect(seconds, traj.ground * info.meters_per_unit, heading, settings)
        # A range a tag on the clip already covers is not proposed again (a run over a tagged stage).
        ranges = [r for r in ranges if not any(a <= r.first and r.last <= b for _, a, b in agent.stationary)]
        taken = {name for name, _, _ in agent.stationary}
        names, k = [], 0
        for _ in ranges:
            k += 1
            while f"{prefix}{k}" in taken:
                k += 1
            names.append(f"{prefix}{k}")
        out[agent.animation_path] = ClipTags(
            animation=agent.animation_path, agent=path, joint=agent.joints[traj.joint],
            frames=agent.frame_count, existing=list(agent.stationary), ranges=ranges, names=names)
    return [out[k] for k in sorted(out)], info


def clips_to_measure(stage: Usd.Stage, root_joint: str | None = None, animation: str | None = None):
    """(the stage's data, [(agent path, agent)] one agent per clip to measure, in path order).

    Skeletons that no agent plays are read as agents (see the module doc); ``animation``
    keeps only that clip. Raises a MocapEditError when there is nothing to measure.
    """
    _view_skeletons_as_agents(stage, root_joint)
    data = reader.read_stage(stage)
    if animation is not None and not any(a.animation_path == animation for a in data.agents.values()):
        raise MocapEditError(f"<{animation}> is not a SkelAnimation played by an agent or bound to a "
                             "skeleton on this stage")
    measured, seen = [], set()
    for path in sorted(data.agents):
        agent = data.agents[path]
        if agent.animation_path in seen or (animation is not None and agent.animation_path != animation):
            continue
        seen.add(agent.animation_path)
        measured.append((path, agent))
    if not measured:
        raise MocapEditError(f"{data.info.root_layer}: no clip to measure: no agent (MocapAgentAPI) and no "
                             "Skeleton bound to a SkelAnimation")
    return data, measured


def review_layer(info, documentation: str) -> Sdf.Layer:
    """A new anonymous layer with the input's time, up axis and units, to review tags in."""
    layer = Sdf.Layer.CreateAnonymous(".usda")
    writer.set_input_metadata(layer, info)
    layer.documentation = documentation
    return layer


def build_layer(clips: list[ClipTags], info, settings: stationary.DetectSettings) -> Sdf.Layer:
    """A layer of ``over``s tagging each proposed range with MocapStationaryAPI."""
    layer = review_layer(info, "Stationary ranges proposed by mocapedit detect-stationary, for review: "
                               "place over the clip (sublayer above it).")
    report = {}
    with Sdf.ChangeBlock():
        for clip in clips:
            if not clip.ranges:
                continue
            spec = sdf.over_chain(layer, Sdf.Path(clip.animation))
            for name, r in zip(clip.names, clip.ranges):
                clip_layer.tag_stationary(spec, name, (r.first, r.last))
                report[f"{clip.animation}.{name}"] = {
                    "frames": Gf.Vec2i(r.first, r.last), "seconds": round(r.duration, 4),
                    "maxSpeed": round(r.max_speed, 4), "maxTurn": round(r.max_turn, 3)}
                if r.bridged:
                    report[f"{clip.animation}.{name}"].update({
                        "bridgedFrames": r.bridged, "bridgedMaxSpeed": round(r.bridged_max_speed, 4),
                        "bridgedMaxTurn": round(r.bridged_max_turn, 3)})
    edits_format.write(layer, {
        "detectStationary": {"maxSpeed": settings.max_speed, "maxTurn": settings.max_turn,
                             "minDuration": settings.min_duration, "window": settings.window,
                             "maxGap": settings.max_gap,
                             "units": "maxSpeed m/s, maxTurn deg/s, minDuration window maxGap s"},
        "ranges": report})
    return layer


__all__ = ["ClipTags", "detect", "build_layer"]
