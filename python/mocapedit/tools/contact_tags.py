"""Foot contact tags: detect the contacts of each clip of a stage and author them for review.

``detect(stage)`` finds each clip's contacts as the solve would (:mod:`mocapedit.geometry.contacts`
on the legs of the agent that plays it) and ``build_layer`` writes them as
``MocapFootContactAPI`` instances (``footContact:<name>:joint``, ``footContact:<name>:frames``)
in a new layer of ``over``s on the SkelAnimation prims. A clip with authored contacts uses
exactly those in the solve, so the layer, once reviewed and sub-layered, replaces detection.
Clips are found as :mod:`mocapedit.tools.tags` finds them (agents, else skeletons bound to a clip).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from pxr import Gf, Sdf, Usd

from mocapedit.geometry import contacts
from mocapedit.tools import tags
from mocapedit.usd import edits_format, sdf
from mocapedit.model.errors import MocapEditError

API = "MocapFootContactAPI"


@dataclass
class ClipContacts:
    animation: str                                   # SkelAnimation prim path on the stage
    agent: str                                       # the agent (or skeleton) it was measured on
    frames: int
    legs: list[contacts.Leg]
    joint_names: list[str]                           # the skeleton's joints
    ranges: list[list[tuple[int, int]]] = field(default_factory=list)  # per leg
    names: list[list[str]] = field(default_factory=list)               # instance name of each range
    note: str | None = None                          # why a leg has none (contacts.raised_note)


def detect(stage: Usd.Stage, settings: contacts.DetectSettings | None = None, animation: str | None = None,
           prefix: str | None = None) -> tuple[list[ClipContacts], object, list[str]]:
    """Detects the foot contacts of each clip on the stage (only its session layer is touched);
    returns (the clips' contacts, the stage's info, the agents left out for having no legs).

    Instance names are ``<side><k>`` (``left1``, ``right1``, ...), or ``<prefix><side><k>``.
    """
    settings = settings or contacts.DetectSettings()
    try:
        settings.validate()
    except ValueError as exc:
        raise MocapEditError(str(exc)) from None
    if prefix and not Sdf.Path.IsValidIdentifier(prefix + "left1"):
        raise MocapEditError(f"contact name prefix '{prefix}' is not a valid identifier")
    data, measured = tags.clips_to_measure(stage, None, animation)
    out = []
    legless = [(path, agent) for path, agent in measured if not agent.legs]
    if legless and len(legless) == len(measured):
        path, agent = legless[0]
        raise MocapEditError(f"<{path}>: no legs found by name in skeleton <{agent.skeleton_path}>; set "
                             "mocap:leftLegJoints and mocap:rightLegJoints")
    skipped = [path for path, _ in legless]
    for path, agent in measured:
        if not agent.legs:
            continue
        clip = data.clip_of(agent)
        raised = contacts.raised_legs(agent, clip, data.info)
        found = contacts.detect_agent(agent, clip, data.info, settings, raised)
        names = [[f"{prefix or ''}{leg.side}{k + 1}" for k in range(len(r))] for leg, r in zip(agent.legs, found)]
        out.append(ClipContacts(animation=agent.animation_path, agent=path, frames=agent.frame_count,
                                legs=list(agent.legs), joint_names=list(agent.joints), ranges=found, names=names,
                                note=contacts.raised_note(agent, raised)))
    return sorted(out, key=lambda c: c.animation), data.info, skipped


def build_layer(clips: list[ClipContacts], info, settings: contacts.DetectSettings) -> Sdf.Layer:
    """A layer of ``over``s holding each detected contact as a MocapFootContactAPI instance."""
    layer = tags.review_layer(info, "Foot contacts detected by mocapedit detect-contacts, for review: place over "
                                    "the clip (sublayer above it). A clip with contacts uses exactly these when solving.")
    with Sdf.ChangeBlock():
        for clip in clips:
            if not any(clip.ranges):
                continue
            spec = sdf.over_chain(layer, Sdf.Path(clip.animation))
            applied = []
            for leg, ranges, names in zip(clip.legs, clip.ranges, clip.names):
                joint = clip.joint_names[leg.toe if leg.toe is not None else leg.ankle]
                for name, (first, last) in zip(names, ranges):
                    applied.append(f"{API}:{name}")
                    for prop, type_name, value in (("joint", Sdf.ValueTypeNames.Token, joint),
                                                   ("frames", Sdf.ValueTypeNames.Int2, Gf.Vec2i(first, last))):
                        sdf.attr(spec, f"footContact:{name}:{prop}", type_name, value, uniform=True)
            spec.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=applied))
    edits_format.write(layer, {
        "detectContacts": {"height": settings.height, "releaseHeight": settings.release_height,
                           "speed": settings.speed, "releaseSpeed": settings.release_speed,
                           "minDuration": settings.min_duration, "maxGap": settings.max_gap,
                           "units": "heights m above the joint's lowest, speeds m/s, durations s"}})
    return layer


__all__ = ["ClipContacts", "detect", "build_layer"]
