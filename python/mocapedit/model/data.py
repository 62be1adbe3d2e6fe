"""Plain data passed between the reader, the solves and the writer.

Everything here is numpy arrays, strings and numbers: no USD objects, so the solve
modules can be tested without a stage and the reader and writer do no linear algebra.
Frames are 0-based indices into a clip's authored samples; times are stage time codes;
positions are world space in stage units (see :mod:`mocapedit.geometry.kinematics` for the
quaternion and matrix conventions).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class StageInfo:
    up_axis: str                      # "Y" or "Z"
    meters_per_unit: float
    time_codes_per_second: float
    start_time: float | None
    end_time: float | None
    root_layer: str                   # identifier of the input's root layer
    used_layers: list[str]            # identifiers of every layer the input uses
    # Names of the prims under /MocapEdit/Animations the input already has (an earlier
    # solve's edits layer in it): a new layer's animations take other names.
    taken_animation_names: list[str] = field(default_factory=list)

    def metres(self, value_in_metres: float) -> float:
        """A length given in metres, in stage units."""
        return value_in_metres / self.meters_per_unit

    def shot_span(self, first: float, last: float) -> tuple[float, float]:
        """The shot times that play: the stage's start and end time codes where it authors
        them, else ``first`` and ``last`` (the extent of the agents' clips). What a clip plays
        before the shot starts or after it ends is never seen. Outside its clip an agent holds
        its first or last pose, as UsdSkel holds samples, so a range wider than the clips
        still counts there."""
        lo = float(first) if self.start_time is None else float(self.start_time)
        hi = float(last) if self.end_time is None else float(self.end_time)
        return lo, max(hi, lo)


CHANNELS = ("translations", "rotations", "scales")


@dataclass
class Clip:
    """One SkelAnimation's authored samples, read once however many agents play it."""
    key: tuple                        # identity of the authored data (layer, spec path, ...)
    source: str                       # "<layer>@<spec path>", for messages and reports
    joints: list[str]                 # the animation's own joint order
    times: np.ndarray                 # (F,) sample times in the clip layer's own time
    translations: np.ndarray          # (F,Ja,3) float32, joint-local
    rotations: np.ndarray             # (F,Ja,4) float32 (x,y,z,w), joint-local
    scales: np.ndarray                # (F,Ja,3) float32
    # The channels the clip authors; the others hold the identity (an agent's own clip
    # authors all three, a layer clip may author only some).
    channels: tuple[str, ...] = CHANNELS
    # (F,) the frames' times in the layer of :attr:`sample_spec` (before any layer offset of
    # the arcs that bring the clip in); None when there is no such single spec.
    spec_times: np.ndarray | None = None

    @property
    def frame_count(self) -> int:
        return int(self.times.shape[0])

    @property
    def sample_spec(self) -> tuple[str, str] | None:
        """(layer identifier, prim path) of the one spec whose time samples make the whole
        clip, or None when translations, rotations and scales are sampled on different specs
        (or inside a variant), which cannot be re-timed as one value clip."""
        specs = {(s[0], s[1].rsplit(".", 1)[0]) for s in self.key[1] if s is not None} \
            if len(self.key) > 1 else set()
        if len(specs) != 1:
            return None
        layer, prim_path = next(iter(specs))
        return None if "{" in prim_path else (layer, prim_path)


@dataclass
class Agent:
    """An editable character: a prim with MocapAgentAPI and the clip it plays."""
    path: str
    skeleton_path: str
    animation_path: str               # composed SkelAnimation prim
    clip_key: tuple
    joints: list[str]                 # skeleton joint order
    parents: np.ndarray               # (J,) parent index, -1 for a root
    rest_transforms: np.ndarray       # (J,4,4) joint-local rest pose
    anim_to_skel: np.ndarray          # (Ja,) skeleton joint index of each animation joint, -1 if absent
    sample_times: np.ndarray          # (F,) stage time of each clip frame
    skel_to_world: np.ndarray         # (1,4,4) or (F,4,4): skeleton prim local-to-world
    agent_parent_to_world: np.ndarray  # (1,4,4) or (F,4,4): parent of the agent prim, identity if it resets the stack
    xform_op_order: list[str]         # the agent prim's authored xformOpOrder
    root_joint: int
    hip_joint: int | None
    collision_radius: float           # stage units
    collision_height: float           # stage units
    collide: bool
    path_curve: str | None
    stationary: list[tuple[str, int, int]] = field(default_factory=list)  # (name, first, last)
    legs: list = field(default_factory=list)           # contacts.Leg per leg found or authored
    foot_locking: bool = True                          # mocap:footLocking
    # Authored MocapFootContactAPI instances of the clip as (name, skeleton joint, first, last);
    # None when the clip has none (contacts are then detected).
    foot_contacts: list[tuple[str, int, int, int]] | None = None
    # Instances (instanceable prims that share a prototype) among the agent prim, its
    # ancestors and the prims between it and its skeleton, outermost first: an opinion
    # authored below an instance is ignored, so the writer makes those it authors under
    # not instanceable in the edits layer.
    instances: list[str] = field(default_factory=list)
    # (F,4,4) the agent prim's own local transform at each clip frame when its transform ops
    # are animated (ground motion carried by the prim, as crowd tools export), else None. A
    # re-timed agent's edit op then replaces those ops: they play at shot time, its clip at
    # the re-timed source time.
    own_transform: np.ndarray | None = None
    # The same for the skeleton prim's own transform ops (the skeleton below the agent), and
    # the skeleton's authored xformOpOrder.
    skeleton_transform: np.ndarray | None = None
    skeleton_xform_op_order: list[str] = field(default_factory=list)
    # A prim between the agent and its skeleton (both excluded) has an animated transform,
    # which a re-timed clip does not carry.
    inner_transform_animated: bool = False

    @property
    def frame_count(self) -> int:
        return int(self.sample_times.shape[0])


@dataclass
class PositionConstraint:
    path: str
    agent: str
    frame: int
    position: np.ndarray              # (3,) world
    hard: bool
    weight: float


@dataclass
class RelativeConstraint:
    path: str
    agent: str
    frame: int
    target: str
    target_frame: int
    offset: np.ndarray                # (3,)
    space: str                        # "world" | "target"
    hard: bool
    weight: float


@dataclass
class TimeConstraint:
    path: str
    agent: str
    frame: int
    time: float
    hard: bool
    weight: float


@dataclass
class SyncConstraint:
    path: str
    agent: str
    frame: int
    target: str
    target_frame: int
    offset: float
    hard: bool
    weight: float


@dataclass
class AgentGroup:
    path: str
    members: list[str]
    stiffness: float


@dataclass
class AvoidRegion:
    path: str
    shape: str                        # "circle" | "box"
    radius: float
    size: np.ndarray                  # (3,)
    margin: float
    agents: list[str]                 # empty = all
    local_to_world: np.ndarray        # (4,4)
    geometry: str | None
    geometry_bounds: np.ndarray | None  # (2,3) world-space min/max of the geometry, if any


@dataclass
class AnimationLayer:
    path: str
    agents: list[str]
    animation: str                    # composed SkelAnimation prim path
    clip_key: tuple | None
    joint: str
    mode: str                         # "blend" | "additive"
    weight_times: np.ndarray          # (K,) stage times of weight samples; empty = constant
    weight_values: np.ndarray         # (K,) or (1,) weights
    time_offset: float
    wrap: str                         # "loop" | "clamp"
    reference_pose: str               # "firstFrame" | "restPose"
    sample_times: np.ndarray | None = None  # (F,) stage time of each layer clip frame, as composed


@dataclass
class SolveSettings:
    path: str | None = None
    collision_avoidance: bool = False
    max_iterations: int = 10
    sample_step: float = 1.0
    margin: float = 0.0
    match_speed: bool = False
    collision_strategy: str = "relinearize"
    min_time_interval: float = 0.1
    max_wait: float = 3.0             # seconds collision avoidance may delay one agent
    foot_locking: bool = True
    pivot_on_feet: bool = True


@dataclass
class StageData:
    info: StageInfo
    agents: dict[str, Agent]          # by prim path, sorted
    clips: dict[tuple, Clip]
    position_constraints: list[PositionConstraint] = field(default_factory=list)
    relative_constraints: list[RelativeConstraint] = field(default_factory=list)
    time_constraints: list[TimeConstraint] = field(default_factory=list)
    sync_constraints: list[SyncConstraint] = field(default_factory=list)
    groups: list[AgentGroup] = field(default_factory=list)
    avoid_regions: list[AvoidRegion] = field(default_factory=list)
    layers: list[AnimationLayer] = field(default_factory=list)
    settings: SolveSettings = field(default_factory=SolveSettings)
    # Path curve prim -> {"type": "BasisCurves"|"NurbsCurves", "points": (K,3) local,
    # "local_to_world": (4,4), "counts": (C,), "basis": str, "curve_type": str, "wrap": str,
    # "order": (C,) or None, "knots": (M,) or None, "weights": (K,) or None (NurbsCurves pointWeights)}
    curves: dict[str, dict] = field(default_factory=dict)
    # Outermost SkelRoot and Skeleton prims that no agent is, holds or is held by (no
    # MocapAgentAPI): left as they are.
    skel_roots_without_agent: list[str] = field(default_factory=list)
    #: agents inside a PointInstancer (its prototypes): they play at its points, not edited
    point_instanced_agents: list[str] = field(default_factory=list)

    def clip_of(self, agent: Agent) -> Clip:
        return self.clips[agent.clip_key]
