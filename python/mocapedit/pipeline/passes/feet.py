"""Foot locking, after every other edit (path, time warp, avoidance, layering).

For each edited agent with two legs (found by name or set by ``mocap:leftLegJoints`` /
``mocap:rightLegJoints``), the pose every earlier pass produced is evaluated by forward
kinematics and carried by the agent's edited ground motion. Each foot contact of the
source clip (authored with ``MocapFootContactAPI``, else detected) gets one plant: the
source foot carried by one turn and one ground shift, chosen by least squares where the
edit puts the foot, and leashed to stay within what the leg can reach from where the edit puts
the foot (at least ``LEASH_M``, with the pelvis lowered by at most ``MAX_DROP_M``) and
``LEASH_DEGREES`` of its turn (further, and further from the foot, for an agent whose feet still
slide over the bar: ``LOOSER``). The solver's foot-locking job (:mod:`mocapedit.solve.footlock`)
moves the legs of all agents at once (all of the shot's, or a run of them on a worker when
``SolveOptions.components`` is set: an agent's legs depend on no other agent's,
:func:`lock_agents`). Agents whose legs change get a pose edit that replaces their hip, knee and ankle
rotations (and the skeleton root's translation where the pelvis is lowered), so the writer
bakes their animation.

The report gets, per agent, the foot skate (as :func:`mocapedit.tools.measure.foot_skate` measures
it, stage units per second) of the source (``footSkateSource``), after the edits alone
(``footSkateUnlocked``) and as the edits layer plays it, locked (``footSkateEdited``); the
contacts locked, the largest pelvis drop and the largest IK correction (stage units).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from mocapedit.geometry import animation, contacts, ground, kinematics, trajectory
from mocapedit.solve import footlock, footplant
from mocapedit.inspect import metrics
from mocapedit.pipeline.context import SolveContext, consecutive_runs
from mocapedit.usd import writer
from mocapedit.model.errors import MocapEditError
from mocapedit.geometry.kinematics import quat_multiply
from mocapedit.solve.layering import trs_from_matrices
from mocapedit.model.data import Agent
from mocapedit.model.progress import Silent
from mocapedit.model.report import Report

#: Seconds over which a lock blends in before a contact and out after it; longer in proportion
#: where the plant lies further than ``LEASH_M`` from where the edit puts the foot at the
#: contact's end, so the leg catches up no faster than from ``LEASH_M``.
BLEND_SECONDS = 0.1
#: Metres a plant may always lie from where the edit puts the foot before it is dragged along;
#: further where the leg reaches it (:func:`footplant.reach`).
LEASH_M = 0.08
#: Metres the pelvis may be lowered for a leg to reach a plant further than ``LEASH_M``.
MAX_DROP_M = 0.08
#: Metres a plant never lies further than from where the edit puts the foot, however far the
#: leg reaches (a body dragged sideways would otherwise straddle).
MAX_LEASH_M = 0.15
#: Degrees a plant may be turned from the edited foot before it is turned along (the leg turns
#: at the hip with its planted foot up to there: ``footlock.turn_legs_toward_plants``; a hip
#: turns 40 degrees and more either way). Turned along, the foot turns about its ankle and its
#: toes slide: at 15, a walk turned round a corner by handles slid +0.5 to +1.2 cm/s over its
#: source's.
LEASH_DEGREES = 25.0
#: The looser plants an agent whose locked feet still slide over the bar tries, in turn
#: (:func:`_loosen_where_sliding`): times LEASH_DEGREES they may lag the turn (45, then 35
#: degrees), times MAX_LEASH_M they may lie from the edited foot (25 cm), and times MAX_LEASH_M
#: a foot may lie from its plant before it steps; each kept or not before the next. The last
#: steps as at MAX_LEASH_M and holds the other foot's plant as far as 25 cm while it cannot (a
#: CMU dribble dragged 1 m aside in 2.3 s: its feet, stepping at 25 cm, took one step and slid
#: +0.81 cm/s over its source's; stepping at 15 and holding at 25, three steps and +0.38).
LOOSER = ((1.8, 1.0, 1.0), (1.4, 1.0, 1.0), (1.0, 5.0 / 3.0, 5.0 / 3.0), (1.0, 5.0 / 3.0, 1.0))
#: Seconds a foot takes to step where an edit drags or turns a standing body further than the
#: leash (:func:`footplant.replant`): at least STEP_SECONDS, longer so that the foot moves no
#: faster than its source does, but no longer than STEP_LONGEST_SECONDS; and metres it lifts at
#: the top of the step.
STEP_SECONDS = 0.25
STEP_LONGEST_SECONDS = 1.5
STEP_HEIGHT_M = 0.05
#: A foot steps only through contacts where the leash would let it slide further than this
#: (metres), or turn further (degrees).
STEP_SLIDE_M = 0.05
STEP_SLIDE_DEGREES = 10.0
#: A step turns no joint of the leg faster than this many times the fastest the pose before
#: locking turns it (the issue's bar is 1.5); an agent whose steps do gets longer steps and its
#: legs solved again, up to STEP_ROUNDS times.
STEP_SPEED_RATIO = 1.35
STEP_ROUNDS = 3
#: A step moves the foot against its hip at most STEP_FOOT_SPEED_RATIO times as fast as the
#: source ever does (the bars are on the joints' turns, which STEP_SPEED_RATIO holds). A leg
#: the source holds nearly still (an idle's) steps at a calm pace at least: the foot at
#: STEP_MIN_FOOT_SPEED_M metres per second against its hip, and the hip, knee and ankle at
#: STEP_MIN_TURN_SPEEDS radians per second (a fifth to a third of a 1 m/s walk's), also where
#: the steps' joint speeds are held to STEP_SPEED_RATIO. Held to the idle's own legs (a knee
#: that turns at 0.12 rad/s), an idle dragged 1 m aside and back over 10 s could take no step
#: and slid 13.6 cm/s, its legs turning 5 times as fast as the idle's all the same.
STEP_FOOT_SPEED_RATIO = 2.0
STEP_MIN_FOOT_SPEED_M = 1.0
STEP_MIN_TURN_SPEEDS = (1.0, 2.0, 1.5)
#: A lock that still turns a leg's joint faster than STEP_SPEED_RATIO times the fastest the pose
#: before locking does (easing towards a plant that lies far from the swinging foot, most often)
#: eases in and out BLEND_LONGER times as long, up to BLEND_ROUNDS times, and keeps the longer
#: ease only where the legs turn slower with it.
BLEND_LONGER = 1.5
BLEND_ROUNDS = 2
#: Agents whose feet the edits make slide by at most this much more than the source's (metres
#: per second, the issue's quality bar) keep their legs: locking them would bake their whole
#: animation for a change no one sees.
SKATE_TOLERANCE_M = 0.005
#: Agents whose ankles all stay within this of where the edit puts them, and whose pelvis
#: drops less, keep their legs (metres): locking would move a foot by less than this over a
#: whole contact, and leaving them saves baking their animation.
STILL_M = 0.002


def _skeleton(agent: Agent, pose: animation.Pose, joints: list[int], with_rotations: bool = False):
    """(T,K,4,4) skeleton-space matrices of the given joints of a pose (or of the poses of agents of
    one skeleton, one after another) whose joint order may differ from the skeleton's (joints it
    lacks take the rest pose); ``with_rotations``: and their rotations (T,K,4), see
    :func:`kinematics.skeleton_space`."""
    column = {name: k for k, name in enumerate(pose.joints)}
    columns = np.array([column.get(name, -1) for name in agent.joints], dtype=np.int64)
    return kinematics.skeleton_space(agent.parents, columns, agent.rest_transforms, pose.translations,
                                     pose.rotations, pose.scales, joints, with_rotations)


@dataclass
class _Posed:
    """An agent's pose after the earlier passes at its output frames and its pose columns by
    joint name, and its forward kinematics: skeleton-space positions (T,8,3) and rotations
    (T,8,4) of both legs' hips, knees, ankles and the hips' parents (``legs``: columns 0-1, 2-3,
    4-5, 6-7; a hip without parent repeats the hip, and ``parented`` (2,) says which have one),
    each leg's knee hinge in the knee's frame (2,3) and the feet's positions (T,F,3)."""
    pose: animation.Pose
    columns: dict
    pos: np.ndarray
    rot: np.ndarray
    parented: np.ndarray
    hinge: np.ndarray
    feet: np.ndarray


def _foot_joints(agent: Agent, cache: dict) -> list[int]:
    """The joints :func:`mocapedit.tools.measure.foot_skate` measures (named like feet); agents of
    one skeleton share them."""
    key = ("feet", tuple(agent.joints))
    if key not in cache:
        cache[key] = metrics.default_foot_joints(agent.joints)
    return cache[key]


def _posed_legs(ctx, path: str, frames: np.ndarray, times: np.ndarray, shared: dict) -> _Posed:
    """The pose after the earlier passes and its forward kinematics. Agents that play one clip
    at the same frames without pose edits share them."""
    agent = ctx.data.agents[path]
    edits = ctx.pose_edits.get(path, [])
    legs = [j for key in ("hip", "knee", "ankle") for leg in agent.legs for j in [getattr(leg, key)]]
    parents = [int(agent.parents[leg.hip]) for leg in agent.legs]
    feet = _foot_joints(agent, shared)
    key = None if edits else (agent.clip_key, tuple(agent.joints), agent.rest_transforms.tobytes(),
                              tuple(legs), frames.tobytes())
    hit = shared.get(key) if key is not None else None
    if hit is None:
        pose = animation.sample_pose(ctx.data.clip_of(agent), frames)
        for edit in edits:
            pose = edit.apply(pose, times, frames)
        rows = legs + [p if p >= 0 else hip for p, hip in zip(parents, legs[:2])]
        matrices, rot = _skeleton(agent, pose, rows + feet, with_rotations=True)
        # Rotations as trs_from_matrices gives them (float32).
        pos, rot = matrices[:, :8, 3, :3], rot[:, :8].astype(np.float32).astype(np.float64)
        hinge = footlock.knee_hinge(pos[:, 0:2], pos[:, 2:4], pos[:, 4:6], rot[:, 2:4])
        feet_pos = matrices[:, 8:, 3, :3] if feet else None
        hit = _Posed(pose, {name: k for k, name in enumerate(pose.joints)}, pos, rot,
                     np.array([p >= 0 for p in parents]), hinge, feet_pos)
        if key is not None:
            shared[key] = hit
    return hit


def _top(agent: Agent, joint: int) -> int:
    while int(agent.parents[joint]) >= 0:
        joint = int(agent.parents[joint])
    return joint


class _AgentLock:
    """One agent's side of the jobs: what it needs, and (through its :class:`_Run`) what it gets back."""

    def __init__(self, ctx: SolveContext, path: str, source_contacts: list, shared: dict):
        info = ctx.data.info
        self.path = path
        agent = self.agent = ctx.data.agents[path]
        self.legs = agent.legs
        # (source, unlocked) feet in the world, (T,F,3) each, once measured (:meth:`_Run.skates`).
        self.feet_world: tuple | None = None
        self._pose_speed: np.ndarray | None = None
        # Locked legs are a pose edit, and a pose edit bakes the animation: lock on its frames.
        self.times, self.frames = ctx.output_frames(path, baked=True)
        self.root = _top(agent, self.legs[0].hip)
        posed = self.posed = _posed_legs(ctx, path, self.frames, self.times, shared)
        self.pose, self.columns = posed.pose, posed.columns
        # The contacts on these frames.
        self.contacts = []
        for ranges in source_contacts:
            ranges = np.array(ranges, dtype=np.float64).reshape(-1, 2)
            inside = (self.frames >= ranges[:, :1] - 1e-9) & (self.frames <= ranges[:, 1:] + 1e-9)
            self.contacts.append(ranges[inside.any(axis=1)])
        self.locked = sum(len(c) for c in self.contacts)
        if not self.locked or self.writable():
            return
        to_world = agent.skel_to_world
        if to_world.shape[0] > 1:
            to_world = animation.interp_frames(to_world, self.frames)
        self.to_world = to_world
        # The edit's ground motion (none without a path edit): source and edited ground and heading.
        edited = ctx.paths.get(path)
        self.ground = None
        if edited is not None:
            traj = ctx.trajectories[path]
            parts = (traj.ground, traj.heading, edited.ground, edited.heading)
            if all(np.asarray(v).dtype == np.float64 for v in parts):
                # Interpolated as the columns of one array: the same values, one call.
                columns = np.column_stack(parts)
                at = animation.interp_frames(columns, self.frames)
                self.ground = (at[:, 0:2], at[:, 2], at[:, 3:5], at[:, 5])
            else:
                self.ground = tuple(animation.interp_frames(values, self.frames) for values in parts)
        fps = self.agent_fps = info.time_codes_per_second
        key = ("step", agent.sample_times.tobytes())
        if key not in shared:
            shared[key] = np.median(np.diff(agent.sample_times)) if agent.frame_count > 1 else 1.0
        self.blend = max(2.0, BLEND_SECONDS * fps / max(shared[key], 1e-9))
        self.blend_frames = int(np.ceil(self.blend))
        self.keep = np.zeros(len(self.times), dtype=bool)
        for _, first, last in agent.stationary:
            self.keep |= (self.frames >= first - 1e-9) & (self.frames <= last + 1e-9)

    def writable(self) -> str | None:
        """Why the legs cannot be baked into this agent's pose, or None."""
        for leg in self.legs:
            for j in (leg.hip, leg.knee, leg.ankle):
                if self.agent.joints[j] not in self.columns:
                    return f"leg joint '{self.agent.joints[j]}' is not animated by the clip"
        return None

    def pose_speed(self) -> np.ndarray:
        """(legs, 3) the largest angular speed of each leg's hip, knee and ankle in the pose before
        locking (radians per second), at least STEP_MIN_TURN_SPEEDS; measured once."""
        if self._pose_speed is None:
            seconds = self.times / self.agent_fps
            columns = [self.columns[self.agent.joints[j]] for leg in self.legs for j in (leg.hip, leg.knee, leg.ankle)]
            fastest = footplant.turn_speed(self.pose.rotations[:, columns], seconds).max(axis=0, initial=0.0)
            self._pose_speed = np.maximum(fastest.reshape(len(self.legs), 3), STEP_MIN_TURN_SPEEDS)
        return self._pose_speed

    def ease_over(self, blend: float) -> None:
        """Ease the locks in and out over ``blend`` frames (and the pelvis drop as long)."""
        self.blend = blend
        self.blend_frames = int(np.ceil(blend))

    def step_speed(self, run: "_Run", a: int) -> np.ndarray:
        """(legs,) the largest angular speed of a leg's hip, knee or ankle around its steps, against
        the largest the joint turns at in the pose before locking (1 when it steps no faster)."""
        seconds = self.times / self.agent_fps
        out_ratio = np.ones(len(self.legs))
        if not run.steps[a] or len(seconds) < 2:
            return out_ratio
        lo, hi = run.span(a)
        stepping = run.stepping[lo:hi]
        near = stepping.copy()
        for shift_by in (1, 2):
            near[shift_by:] |= stepping[:-shift_by]
            near[:-shift_by] |= stepping[shift_by:]
        out = run.legs
        for k, leg in enumerate(self.legs):
            if not near[:, k].any():
                continue
            around = near[1:, k] | near[:-1, k]
            for i, new in enumerate((out.hip_local, out.knee_local, out.ankle_local)):
                locked = footplant.turn_speed(new[lo:hi, k], seconds)[around].max()
                out_ratio[k] = max(out_ratio[k], locked / max(self.pose_speed()[k, i], 1e-9))
        return out_ratio


class _Run:
    """A run of agents for the jobs, their output frames one after another (#N poses): the legs
    before and after the edits' ground motion, the plants and the locked legs, as flat arrays,
    agent ``a`` owning poses ``offsets[a]:offsets[a + 1]``. Each pose is computed alone, so an
    agent's results do not depend on the others in its run."""

    def __init__(self, ctx: SolveContext, locks: list[_AgentLock], legs: bool = True):
        """``legs`` False: only what :meth:`skates` measures before locking (no legs placed)."""
        info = ctx.data.info
        self.ctx, self.locks = ctx, locks
        self.offsets = np.cumsum([0] + [len(lock.times) for lock in locks]).astype(np.int64)
        self.up = np.zeros(3)
        self.up[ground.up_index(info.up_axis)] = 1.0

        def flat(values) -> np.ndarray:
            return np.concatenate([np.broadcast_to(v, (len(lock.times),) + np.shape(v)[1:])
                                   for lock, v in zip(locks, values)])

        # Each agent's placement and its rotation (agents placed once, in one call).
        world_q: list = [None] * len(locks)
        static = [a for a, lock in enumerate(locks) if lock.to_world.shape[0] == 1]
        if static:
            quats = trs_from_matrices(np.concatenate([locks[a].to_world for a in static]))[1].astype(np.float64)
            for a, q in zip(static, quats):
                world_q[a] = q[None]
        for a, lock in enumerate(locks):
            if world_q[a] is None:
                world_q[a] = trs_from_matrices(lock.to_world)[1].astype(np.float64)
        self.to_world = flat([lock.to_world for lock in locks])
        world_q = flat(world_q)
        # The edits' ground motion: a turn about up, then a shift (the identity without a path edit).
        self.motion = np.broadcast_to(np.eye(4), (len(self.to_world), 4, 4)).copy()
        self.turn = np.zeros(len(self.to_world))
        moved = [a for a, lock in enumerate(locks) if lock.ground is not None]
        if moved:
            at = np.concatenate([np.arange(*self.span(a)) for a in moved])
            src_uv, src_h, new_uv, new_h = (np.concatenate([locks[a].ground[i] for a in moved]) for i in range(4))
            self.motion[at] = trajectory.ground_motion(src_uv, src_h, new_uv, new_h, info.up_axis)
            self.turn[at] = new_h - src_h
        self.times = np.concatenate([lock.times for lock in locks])
        if not legs:
            return
        # The legs in the world, before the ground motion (the posed source) and as edited.
        source, pos, source_rot, rot = footplant.place(
            self.to_world, world_q, self.motion, self.turn, self.up, flat([lock.posed.pos[:, :6] for lock in locks]),
            flat([lock.posed.rot for lock in locks]))
        self.hip, self.knee, self.ankle = pos[:, 0:2], pos[:, 2:4], pos[:, 4:6]
        self.hip_rot, self.knee_rot, self.ankle_rot = rot[:, 0:2], rot[:, 2:4], rot[:, 4:6]
        parented = flat([lock.posed.parented[None] for lock in locks])
        self.parent_rot = np.where(parented[..., None], rot[:, 6:8],
                                   quat_multiply(footplant.yaw_quat(self.turn, self.up), world_q)[:, None])
        self.hinge = footlock.world_hinge(self.knee_rot, flat([lock.posed.hinge[None] for lock in locks]))
        self.source = dict(source_hip=source[:, 0:2], source_ankle=source[:, 4:6], source_hip_rot=source_rot[:, 0:2],
                           source_knee_rot=source_rot[:, 2:4], source_ankle_rot=source_rot[:, 4:6])
        self.frames = np.concatenate([lock.frames for lock in locks])
        self.keep = np.concatenate([lock.keep for lock in locks])
        self.stretch = np.ones((len(locks), 2))
        self.turn_leash = np.ones(len(locks))
        self.reach_leash = np.ones(len(locks))
        self.step_leash = np.ones(len(locks))

    def span(self, a: int) -> tuple[int, int]:
        return int(self.offsets[a]), int(self.offsets[a + 1])

    _PLAN = ("target", "target_rot", "weight", "stepping")
    _LEGS = ("hip_local", "knee_local", "ankle_local", "drop", "reached")

    def agent_state(self, a: int) -> tuple:
        """A copy of agent ``a``'s plants and locked legs, for :meth:`set_agent_state`."""
        lo, hi = self.span(a)
        return ([getattr(self, k)[lo:hi].copy() for k in self._PLAN],
                [getattr(self.legs, k)[lo:hi].copy() for k in self._LEGS], int(self.steps[a]))

    def set_agent_state(self, a: int, state: tuple) -> None:
        lo, hi = self.span(a)
        plan, legs, self.steps[a] = state
        for k, v in zip(self._PLAN, plan):
            getattr(self, k)[lo:hi] = v
        for k, v in zip(self._LEGS, legs):
            getattr(self.legs, k)[lo:hi] = v

    def leg_speed(self, agents: list[int] | None = None) -> np.ndarray:
        """(A,) per agent (of ``agents``, 1 for the others; all: None), the largest angular speed
        of a leg's hip, knee or ankle after locking, against the largest that joint turns at in
        the pose before locking (1: no faster)."""
        chosen = list(range(len(self.locks))) if agents is None else list(agents)
        out = np.ones(len(self.locks))
        offsets = self._offsets(agents)
        if offsets[-1] < 2 or not chosen:
            return out
        seconds = self._pick(self.times, agents) / self.ctx.data.info.time_codes_per_second
        starts, between = offsets[:-1], offsets[1:-1] - 1   # pairs that span two agents
        # (N, joint, leg, 4): each leg's hip, knee and ankle, all turn speeds at once.
        new = np.stack([self._pick(v, agents) for v in (self.legs.hip_local, self.legs.knee_local,
                                                        self.legs.ankle_local)], axis=1)
        speed = footplant.turn_speed(new, seconds)
        speed[between] = 0.0
        most = np.maximum.reduceat(np.concatenate([speed, np.zeros((1,) + speed.shape[1:])]), starts, axis=0)
        pose = np.full((len(chosen), 3, new.shape[2]), np.inf)
        for n, a in enumerate(chosen):
            legs = self.locks[a].pose_speed()
            pose[n, :, :len(legs)] = legs.T
        out[chosen] = np.maximum(1.0, (most / np.maximum(pose, 1e-9)).max(axis=(1, 2)))
        return out

    def _pick(self, values: np.ndarray, agents: list[int] | None) -> np.ndarray:
        """The poses of these agents (all: None), one after another."""
        if agents is None:
            return values
        return np.concatenate([values[slice(*self.span(a))] for a in agents])

    def _offsets(self, agents: list[int] | None) -> np.ndarray:
        if agents is None:
            return self.offsets
        return np.cumsum([0] + [len(self.locks[a].times) for a in agents]).astype(np.int64)

    def plan(self, agents: list[int] | None = None) -> None:
        """The plants of these agents' feet (all: None), each leg's steps ``stretch`` times as long
        as they would be: the solver's plant job on all of them at once."""
        info = self.ctx.data.info
        chosen = range(len(self.locks)) if agents is None else agents
        contacts = [c for a in chosen for c in self.locks[a].contacts]
        inputs = footplant.PlantInputs(
            offsets=self._offsets(agents), contact_offsets=np.cumsum([0] + [len(c) for c in contacts]).astype(np.int64),
            contacts=np.concatenate(contacts).reshape(-1, 2), blend=np.array([self.locks[a].blend for a in chosen]),
            stretch=self.stretch[list(chosen)], turn_leash=self.turn_leash[list(chosen)],
            reach_leash=self.reach_leash[list(chosen)], step_leash=self.step_leash[list(chosen)], up=self.up,
            meters_per_unit=info.meters_per_unit,
            leash_m=LEASH_M, max_leash_m=MAX_LEASH_M, max_drop_m=MAX_DROP_M, leash_degrees=LEASH_DEGREES,
            soft_reach=footlock.SOFT_REACH, step_slide_m=STEP_SLIDE_M, step_slide_degrees=STEP_SLIDE_DEGREES,
            step_seconds=STEP_SECONDS, step_longest_seconds=STEP_LONGEST_SECONDS, step_height_m=STEP_HEIGHT_M,
            step_foot_speed_ratio=STEP_FOOT_SPEED_RATIO, step_min_foot_speed_m=STEP_MIN_FOOT_SPEED_M,
            step_min_turn_speed=STEP_MIN_TURN_SPEEDS[2], step_min_knee_speed=STEP_MIN_TURN_SPEEDS[1],
            frames=self._pick(self.frames, agents), seconds=self._pick(self.times, agents) / info.time_codes_per_second,
            stationary=self._pick(self.keep, agents), turn=self._pick(self.turn, agents),
            hip=self._pick(self.hip, agents), knee=self._pick(self.knee, agents), ankle=self._pick(self.ankle, agents),
            ankle_rot=self._pick(self.ankle_rot, agents),
            **{k: self._pick(v, agents) for k, v in self.source.items()})
        out = footplant.plan_feet(inputs)
        if agents is None:
            self.target, self.target_rot, self.weight, self.stepping, self.steps = (
                out.target, out.target_rot, out.weight, out.stepping, out.steps)
        else:
            for i, a in enumerate(agents):
                lo, hi = self.span(a)
                at = slice(int(inputs.offsets[i]), int(inputs.offsets[i + 1]))
                self.target[lo:hi], self.target_rot[lo:hi] = out.target[at], out.target_rot[at]
                self.weight[lo:hi], self.stepping[lo:hi], self.steps[a] = out.weight[at], out.stepping[at], out.steps[i]
        for a in chosen:
            self._stop_at_cuts(a)
            self._ease_within_leash(a)

    def _ease_within_leash(self, a: int) -> None:
        """While agent ``a``'s feet ease into or out of a contact, the lock pulls each foot no
        further than ``MAX_LEASH_M`` from where the edit puts it: a body dragged fast (a standing
        agent pushed by avoidance) swings its foot far from the next plant, and easing towards
        it from there had the pelvis sink 60 cm for the leg to reach."""
        lo, hi = self.span(a)
        weight = self.weight[lo:hi]
        easing = (weight > 0.0) & (weight < 1.0)
        if not easing.any():
            return
        far = np.linalg.norm(self.target[lo:hi] - self.ankle[lo:hi], axis=-1)
        most = MAX_LEASH_M / self.ctx.data.info.meters_per_unit
        limit = np.where(far > most, most / np.maximum(far, 1e-300), 1.0)
        self.weight[lo:hi] = np.where(easing, np.minimum(weight, limit), weight)

    def _stop_at_cuts(self, a: int) -> None:
        """No leg of agent ``a`` is locked in a take (a run of poses between cuts) where it has no
        contact: the ease into a take's first contact would otherwise reach back over the cut to
        a rest pose metres away, and the pelvis drop to make the leg reach it eases out over the
        take's first poses."""
        lo, hi = self.span(a)
        lock, info = self.locks[a], self.ctx.data.info
        seconds = self.times[lo:hi] / info.time_codes_per_second
        for k, ranges in enumerate(lock.contacts):
            pieces = contacts.takes(seconds, self.source["source_ankle"][lo:hi, k], info.up_axis, info.meters_per_unit)
            if len(pieces) < 2:
                continue
            for first, end in pieces:
                frames = lock.frames[first:end]
                if not np.any((ranges[:, 0] <= frames[-1] + 1e-9) & (ranges[:, 1] >= frames[0] - 1e-9)):
                    self.weight[lo + first:lo + end, k] = 0.0

    def solve(self, agents: list[int] | None = None) -> None:
        """The solver's IK job on these agents' legs (all: None) at once."""
        picked = {k: self._pick(getattr(self, k), agents) for k in (
            "hip", "knee", "ankle", "parent_rot", "hip_rot", "knee_rot", "ankle_rot", "target", "target_rot",
            "weight", "hinge", "keep")}
        # The leg turns at the hip with its planted foot, not at the ankle.
        picked = footlock.turn_legs_toward_plants(picked, self.up)
        inputs = footlock.LegInputs(
            offsets=self._offsets(agents), up=self.up,
            smooth=np.array([self.locks[a].blend_frames for a in (range(len(self.locks)) if agents is None else agents)],
                            dtype=np.int64),
            **picked)
        out = footlock.lock_feet(inputs)
        if agents is None:
            self.legs = out
            return
        for i, a in enumerate(agents):
            lo, hi = self.span(a)
            at = slice(int(inputs.offsets[i]), int(inputs.offsets[i + 1]))
            for k in ("hip_local", "knee_local", "ankle_local", "drop", "reached"):
                getattr(self.legs, k)[lo:hi] = getattr(out, k)[at]

    def locked_legs(self, a: int, meters_per_unit: float) -> "LockedLegs | None":
        """Agent ``a``'s locked legs, or None when locking leaves them as they are; sets its largest
        pelvis drop and foot correction."""
        lock, out = self.locks[a], self.legs
        lo, hi = self.span(a)
        drop = out.drop[lo:hi]
        # The correction of a planted foot: a stepping foot is in the air, moving to its next plant.
        correction = np.where(self.stepping[lo:hi], 0.0, np.linalg.norm(out.reached[lo:hi] - self.ankle[lo:hi], axis=-1))
        lock.max_correction = float(correction.max(initial=0.0))
        lock.max_drop = float(drop.max(initial=0.0))
        still = STILL_M / meters_per_unit
        if lock.max_correction <= still and lock.max_drop <= still:
            return None
        columns = [lock.columns[lock.agent.joints[j]] for leg in lock.legs for j in (leg.hip, leg.knee, leg.ankle)]
        rotations = np.stack([new[lo:hi, k] for k in range(len(lock.legs))
                              for new in (out.hip_local, out.knee_local, out.ankle_local)], axis=1)
        root, shift = None, None
        if np.any(drop > 0):
            root = lock.columns.get(lock.agent.joints[lock.root])
            if root is None:
                raise MocapEditError(
                    f"<{lock.path}>: the pelvis must be lowered but the skeleton root "
                    f"'{lock.agent.joints[lock.root]}' is not animated by the clip")
            # World offset -drop * up, in the root's parent space (the skeleton's).
            shift = np.einsum("ti,tij->tj", -drop[:, None] * self.up, np.linalg.inv(lock.to_world[:, :3, :3]))
        return LockedLegs(lock.path, list(lock.pose.joints), np.array(columns, dtype=np.int64),
                          rotations.astype(np.float32),
                          None if root is None else drop.astype(np.float64), root,
                          None if shift is None else np.asarray(shift, dtype=np.float64))

    def skates(self, legs: list, agents: list[int] | None = None) -> list:
        """Per agent, (source, after the edits, after locking) foot skate, stage units per second,
        as :func:`mocapedit.tools.measure.foot_skate` measures it on the input and on the composed
        stage: joints named like feet, over the frames where the source's feet are planted; None
        for a skeleton without such joints (and for agents not in ``agents``, when given).
        ``legs``: each agent's :class:`LockedLegs` or None.

        A retimed agent is measured against its source as its timing plays it: the clip's poses
        at the same clip times, per second of the shot. Against the source at its own samples, a
        time warp alone would count as sliding what the source does between its samples (where a
        warp falls) and its heel-toe roll played faster."""
        ctx, info = self.ctx, self.ctx.data.info
        units = (info.up_axis, info.meters_per_unit, info.time_codes_per_second)
        place = self.to_world @ self.motion
        # The feet's skeleton-space positions: of the source and before locking where the agent
        # has not had them carried into the world yet (an earlier measure keeps them on the
        # agent), and after locking where its legs change; by agent.
        count = len(self.locks)
        chosen = range(count) if agents is None else agents
        source, unlocked, locked = [None] * count, [None] * count, [None] * count
        groups: dict = {}
        for a in chosen:
            lock = self.locks[a]
            feet = lock.posed.feet
            if feet is None:
                continue
            if lock.feet_world is None:
                unlocked[a] = feet
                if ctx.pose_edits.get(lock.path):
                    source[a] = _feet_of(lock.agent, animation.sample_pose(ctx.data.clip_of(lock.agent), lock.frames))
                else:
                    # The pose locking starts from is the source's at these frames.
                    source[a] = feet
            if legs[a] is not None:
                agent = lock.agent
                key = (tuple(agent.joints), tuple(lock.pose.joints), agent.parents.tobytes(),
                       agent.rest_transforms.tobytes())
                groups.setdefault(key, []).append(a)
        # The locked poses, agents of one skeleton at once.
        for members in groups.values():
            poses = [legs[a].apply(self.locks[a].pose) for a in members]
            stacked = animation.Pose(joints=list(poses[0].joints),
                                     translations=np.concatenate([p.translations for p in poses]),
                                     rotations=np.concatenate([p.rotations for p in poses]),
                                     scales=np.concatenate([p.scales for p in poses]))
            feet = _feet_of(self.locks[members[0]].agent, stacked)
            start = 0
            for a in members:
                frames = len(self.locks[a].times)
                locked[a] = feet[start:start + frames]
                start += frames
        # In the world, agents with as many feet at once.
        for parts in (((source, self.to_world), (unlocked, place)), ((locked, place),)):
            by_count: dict = {}
            for a in range(count):
                if parts[0][0][a] is not None:
                    by_count.setdefault(parts[0][0][a].shape[1], []).append(a)
            for members in by_count.values():
                at = np.concatenate([np.arange(*self.span(a)) for a in members])
                moved = [kinematics.transform_points(np.concatenate([feet[a] for a in members]), m[at, None])
                         for feet, m in parts]
                start = 0
                for a in members:
                    frames = len(self.locks[a].times)
                    if len(parts) == 2:
                        self.locks[a].feet_world = tuple(w[start:start + frames] for w in moved)
                    else:
                        locked[a] = moved[0][start:start + frames]
                    start += frames
        # (source, unlocked, locked) world feet of each agent with feet.
        worlds = [None if lock.feet_world is None else
                  (*lock.feet_world, lock.feet_world[1] if locked[a] is None else locked[a])
                  for a, lock in enumerate(self.locks)]
        # Measured at once for agents with as many frames and feet (each on its own).
        out: list = [None] * len(self.locks)
        by_shape: dict = {}
        for a in chosen:
            if worlds[a] is not None:
                by_shape.setdefault(worlds[a][0].shape, []).append(a)
        for members in by_shape.values():
            source_world, free_world, locked_world = (np.stack([worlds[a][k] for a in members]) for k in range(3))
            times = np.stack([self.locks[a].times for a in members])
            # Over the samples that play in the shot (the figures are of what is seen).
            shot = np.stack([metrics.in_shot(t, info.start_time, info.end_time) for t in times])
            planted = metrics.foot_skate_of_positions(source_world, times, *units).contact & shot[:, :, None]
            before = metrics.foot_skate_of_positions(source_world, times, *units, contact=planted)

            def skate(feet_world):
                contact = metrics.on_ground(planted, source_world, feet_world, info.up_axis,
                                            info.meters_per_unit)
                return np.atleast_1d(metrics.foot_skate_of_positions(feet_world, times, *units, contact=contact).mean)

            free, source = skate(free_world), np.atleast_1d(before.mean)
            locked = skate(locked_world) if any(legs[a] is not None for a in members) else free
            for i, a in enumerate(members):
                out[a] = (float(source[i]), float(free[i]), float(free[i] if legs[a] is None else locked[i]))
        return out

    def plants(self, a: int) -> tuple[np.ndarray, np.ndarray]:
        """Where agent ``a``'s locked feet are planted: the ankle at the first fully locked frame of
        each contact and where each step lands, blue for left feet and orange for right.
        (points, colors)."""
        lo, hi = self.span(a)
        points, colors = [], []
        for k, leg in enumerate(self.locks[a].legs):
            full = self.weight[lo:hi, k] >= 1.0
            starts = np.flatnonzero(full & ~np.concatenate([[False], full[:-1]]))
            stepping = self.stepping[lo:hi, k]
            landed = np.flatnonzero(~stepping & np.concatenate([[False], stepping[:-1]]))
            at = np.union1d(starts, landed)
            points.append(self.target[lo:hi][at, k])
            colors.append(np.tile(PLANT_COLORS[0 if leg.side == "left" else 1], (len(at), 1)))
        return np.concatenate(points), np.concatenate(colors)


def _feet_of(agent: Agent, pose: animation.Pose) -> np.ndarray:
    """(T,F,3) skeleton-space positions of the feet of a pose (or of the poses of agents of one
    skeleton, one after another)."""
    return _skeleton(agent, pose, metrics.default_foot_joints(agent.joints))[..., 3, :3]



@dataclass
class AgentLocking:
    """What foot locking decided for one edited agent (see :func:`lock_agents`)."""
    path: str
    note: str | None = None               # why it was skipped
    contacts: int = 0                      # contacts locked (0: not locked)
    steps: int = 0                         # steps a standing foot takes
    skate: tuple | None = None             # (source, unlocked, edited) foot skate
    max_drop: float = 0.0
    max_correction: float = 0.0
    legs: "LockedLegs | None" = None       # the pose edit, when the legs change
    kept: bool = False                     # locked, but the legs kept (as planted as the source's)
    plants: tuple | None = None            # (points, colors) of its plant guides


#: Agents whose legs one run of the IK job moves: their legs' arrays are alive together, so a
#: crowd's memory stays bounded (results do not depend on it).
LOCK_RUN = 256


def lock_agents(ctx: SolveContext) -> list[AgentLocking]:
    """Locks the feet of every edited agent of ``ctx`` (its :meth:`touched`), in order. The result
    of one agent depends on nothing else, so a shot's agents can be locked in runs elsewhere
    (``SolveOptions.components``) and merged in order."""
    data = ctx.data
    shared: dict = {}
    out: list[AgentLocking] = []
    locks: list[tuple[_AgentLock, AgentLocking]] = []
    for path in ctx.touched():
        agent = data.agents[path]
        result = AgentLocking(path)
        out.append(result)
        if not agent.foot_locking:
            result.note = "foot locking off (mocap:footLocking = false)"
        elif len(agent.legs) != 2:
            result.note = "foot locking skipped: legs not found by name; set mocap:leftLegJoints and mocap:rightLegJoints"
        else:
            lock = _AgentLock(ctx, path, ctx.source_contacts(path), shared)
            why = lock.writable()
            if why:
                result.note = f"foot locking skipped: {why}"
            elif lock.locked:
                locks.append((lock, result))
            if not why and ctx.contacts_note(path):
                result.note = f"foot locking: {ctx.contacts_note(path)}"
        if len(locks) >= LOCK_RUN:
            _lock_run(ctx, locks)
            # Posed legs are shared by the agents of a run only: a crowd's retimed agents each
            # have their own, and kept for the whole shot they held 240 KB an agent.
            locks, shared = [], {}
    if locks:
        _lock_run(ctx, locks)
    return out


def _lock_run(ctx: SolveContext, locks: list) -> None:
    """Runs the plant and IK jobs on some agents' legs and fills in their results."""
    info = ctx.data.info
    tolerance = SKATE_TOLERANCE_M / info.meters_per_unit
    # Agents whose edits leave their feet as planted as the source's keep their legs: measured
    # first, so that no plant or IK is solved for them (nothing of it would be applied).
    before = _Run(ctx, [lock for lock, _ in locks], legs=False).skates([None] * len(locks))
    needed = []
    for (lock, result), skate in zip(locks, before):
        if skate is not None and skate[1] <= skate[0] + tolerance:
            result.contacts, result.skate, result.kept = lock.locked, skate, True
        else:
            needed.append((lock, result))
    locks = needed
    if not locks:
        return
    run = _Run(ctx, [lock for lock, _ in locks])
    run.plan()
    run.solve()
    # A step that turns a leg's joint too fast against the pose is made longer, and the agent's
    # legs solved again.
    for _ in range(STEP_ROUNDS):
        again = []
        for a, (lock, _) in enumerate(locks):
            ratio = lock.step_speed(run, a) / STEP_SPEED_RATIO
            if np.any(ratio > 1.0 + 1e-6):
                run.stretch[a] = run.stretch[a] * np.maximum(ratio * 1.05, 1.0)
                again.append(a)
        if not again:
            break
        run.plan(again)
        run.solve(again)
    _ease_longer_where_fast(run)
    legs = [run.locked_legs(a, info.meters_per_unit) for a in range(len(locks))]
    skates = _loosen_where_sliding(run, legs, run.skates(legs))
    for a, ((lock, result), locked_legs, skate) in enumerate(zip(locks, legs, skates)):
        result.contacts, result.skate, result.legs = lock.locked, skate, locked_legs
        result.steps = int(run.steps[a]) if locked_legs is not None else 0
        result.max_drop, result.max_correction = lock.max_drop, lock.max_correction
        result.plants = run.plants(a)


def _ease_longer_where_fast(run: _Run) -> None:
    """Agents whose locked legs turn a joint faster than STEP_SPEED_RATIO times the pose before
    locking ease their locks in and out over longer (BLEND_LONGER times, up to BLEND_ROUNDS
    times), each keeping the longer ease only where its legs turn slower with it."""
    ratio = run.leg_speed()
    tried: set[int] = set()
    for _ in range(BLEND_ROUNDS):
        fast = [a for a in range(len(run.locks)) if ratio[a] > STEP_SPEED_RATIO + 1e-6 and a not in tried]
        if not fast:
            return
        kept = {a: (run.agent_state(a), run.locks[a].blend) for a in fast}
        for a in fast:
            run.locks[a].ease_over(run.locks[a].blend * BLEND_LONGER)
        run.plan(fast)
        run.solve(fast)
        now = run.leg_speed(fast)
        for a in fast:
            if now[a] >= ratio[a] - 1e-9:
                state, blend = kept[a]
                run.set_agent_state(a, state)
                run.locks[a].ease_over(blend)
                now[a] = ratio[a]
                tried.add(a)
        ratio = ratio.copy()
        ratio[fast] = now[fast]


def _loosen_where_sliding(run: _Run, legs: list, skates: list) -> list:
    """Agents whose locked feet still slide more than SKATE_TOLERANCE_M over their source's are
    locked again with looser plants, a step at a time (LOOSER): their plants lag the body's turn
    further (an edit that turns the body hard while a foot is planted: past LEASH_DEGREES the
    plant turns along, about the ankle, and the toes slide), then may lie further from where the
    edit puts the foot, as far as the leg reaches (a body carried while it stands on one foot:
    past MAX_LEASH_M the foot is dragged along), then may lie that far only while the foot
    cannot step, stepping as at MAX_LEASH_M (a body dragged faster than one foot at a time
    steps). Each keeps a step where its feet slide less and
    its legs turn no faster than STEP_SPEED_RATIO times the pose before locking (or than they
    did), and the steps after it try from there. Updates ``legs`` and returns the skates
    (:meth:`_Run.skates`)."""
    mpu = run.ctx.data.info.meters_per_unit
    tolerance = SKATE_TOLERANCE_M / mpu
    skates = list(skates)

    def sliding() -> list[int]:
        return [a for a, (leg, skate) in enumerate(zip(legs, skates))
                if leg is not None and skate is not None and skate[2] > skate[0] + tolerance]

    over = sliding()
    if not over:
        return skates
    speed = run.leg_speed(over)

    def leashes(a: int) -> tuple[float, float, float]:
        return float(run.turn_leash[a]), float(run.reach_leash[a]), float(run.step_leash[a])

    for turn, reach, step in LOOSER:
        trial = {a: (max(turn, run.turn_leash[a]), max(reach, run.reach_leash[a]), step) for a in sliding()}
        over = [a for a, t in trial.items() if t != leashes(a)]
        if not over:
            continue
        kept = {a: (run.agent_state(a), leashes(a)) for a in over}
        for a in over:
            run.turn_leash[a], run.reach_leash[a], run.step_leash[a] = trial[a]
        run.plan(over)
        run.solve(over)
        now = run.leg_speed(over)
        trial = [None] * len(legs)
        for a in over:
            trial[a] = run.locked_legs(a, mpu)
        again = run.skates(trial, over)
        for a in over:
            if (trial[a] is not None and again[a] is not None and again[a][2] < skates[a][2]
                    and now[a] <= max(speed[a], STEP_SPEED_RATIO) + 1e-9):
                legs[a], skates[a] = trial[a], again[a]
            else:
                state, (run.turn_leash[a], run.reach_leash[a], run.step_leash[a]) = kept[a]
                run.set_agent_state(a, state)
                legs[a] = run.locked_legs(a, mpu)
    return skates


def lock_part(part: dict) -> list[AgentLocking]:
    """:func:`lock_agents` on a part of a shot made by :func:`_part` (a Dask task of a split shot)."""
    return lock_agents(SolveContext(**part, report=Report(), progress=Silent()))


def _part(ctx: SolveContext, paths: list[str]) -> dict:
    """The fields of ``ctx`` that foot locking reads for these agents (to lock them elsewhere)."""
    data = ctx.data
    agents = {p: data.agents[p] for p in paths}
    clips = {a.clip_key: data.clips[a.clip_key] for a in agents.values()}
    part = dataclasses.replace(data, agents=agents, clips=clips, position_constraints=[], relative_constraints=[],
                               time_constraints=[], sync_constraints=[], groups=[], avoid_regions=[], curves={})

    def mine(values: dict) -> dict:
        return {p: values[p] for p in paths if p in values}

    return dict(data=part, options=dataclasses.replace(ctx.options, components=None),
                trajectories=mine(ctx.trajectories), paths=mine(ctx.paths), time_maps=mine(ctx.time_maps),
                pose_edits=mine(ctx.pose_edits), out_times=mine(ctx.out_times))


def _lock_elsewhere(ctx: SolveContext) -> list[AgentLocking]:
    pool = ctx.options.components
    touched = ctx.touched()
    runs = consecutive_runs([ctx.data.agents[p].frame_count for p in touched], pool.chunks)
    out: list[AgentLocking] = []
    for part in pool.map(lock_part, [_part(ctx, touched[run]) for run in runs]):
        out.extend(part)
    for r in out:
        if r.legs is not None:
            # Arrays that crossed the network may sit unaligned in their message, which USD's
            # array conversion rejects: the writer gets aligned copies.
            r.legs = r.legs.aligned()
    return out


def run(ctx: SolveContext) -> None:
    if not ctx.data.settings.foot_locking:
        return
    touched = ctx.touched()
    task = ctx.progress.task("foot locking", len(touched))
    results = _lock_elsewhere(ctx) if ctx.options.components is not None and touched else lock_agents(ctx)
    task.update(len(touched))
    task.done()
    locked = [r for r in results if r.contacts]
    for r in results:
        entry = ctx.report.agent(r.path)
        if r.note:
            entry.add_notes(r.note)
    if not locked:
        return
    skates = []
    for r in locked:
        entry = ctx.report.agent(r.path)
        if r.skate is not None and np.isfinite(r.skate).all():
            # footSkateEdited is what the edits layer plays; footSkateUnlocked, the edits alone.
            entry.foot_skate_source, entry.foot_skate_unlocked, entry.foot_skate_edited = r.skate
            skates.append(r.skate)
        entry.foot_contacts_locked = r.contacts
        if r.steps:
            entry.foot_steps = r.steps
        entry.max_pelvis_drop = r.max_drop
        entry.max_foot_correction = r.max_correction
        if r.legs is not None:
            ctx.pose_edits.setdefault(r.path, []).append(r.legs)
    if ctx.options.guides:
        _plant_guides(ctx, [r.plants for r in locked if r.plants is not None and r.path in ctx.pose_edits])
    stats = ctx.report.stats
    stats.foot_locked_agents = sum(r.legs is not None for r in locked)
    stats.foot_locking_not_needed = sum(r.kept for r in locked)
    stats.foot_contacts_locked = sum(r.contacts for r in locked)
    if any(r.steps for r in locked):
        stats.foot_steps = sum(r.steps for r in locked)
    # The shot's figures: mean skate over the agents with contacts, the largest corrections.
    if skates:
        stats.foot_skate_source, stats.foot_skate_unlocked, stats.foot_skate_edited = (
            float(np.mean(values)) for values in np.transpose(skates))
    stats.max_pelvis_drop = max(r.max_drop for r in locked)
    stats.max_foot_correction = max(r.max_correction for r in locked)


#: Guide colours of the left and right feet's plants.
PLANT_COLORS = np.array([[0.2, 0.5, 1.0], [1.0, 0.55, 0.1]])


def _plant_guides(ctx, plants: list) -> None:
    """One guide of the plants of the locked agents."""
    if plants:
        ctx.guides.append(writer.GuidePoints(
            name="FootPlants", points=np.concatenate([p for p, _ in plants]),
            colors=np.concatenate([c for _, c in plants]), width=ctx.data.info.metres(0.06),
            doc="Where foot locking plants each contact of the locked agents: left feet blue, right orange."))


@dataclass
class LockedLegs:
    """The pose edit of foot locking: new local rotations of the legs' hip, knee and ankle joints
    and, where the pelvis is lowered, the skeleton root lowered with it. Only what changes is
    kept (an agent's whole pose is many times larger)."""
    path: str
    joints: list[str]                   # the joints of the pose it was computed for
    columns: np.ndarray                 # (K,) columns of that pose whose rotations it replaces
    rotations: np.ndarray               # (T,K,4) float32 local rotations (x, y, z, w)
    drop: np.ndarray | None = None      # (T,) how far the whole body is lowered along up, stage units
    root: int | None = None             # column of the skeleton root, when lowered
    root_shift: np.ndarray | None = None  # (T,3) the lowering as the root's local translation

    #: The pose channels it changes when the lowering is carried by the agent's transform
    #: instead (:attr:`drop`): the writer then bakes only these over the re-timed source.
    CHANNELS = ("rotations",)

    def apply(self, pose: animation.Pose, out_times: np.ndarray | None = None,
              src_frames: np.ndarray | None = None) -> animation.Pose:
        """``pose`` (the pose the legs were locked on) with the locked legs and lowered root."""
        if list(pose.joints) != self.joints or pose.rotations.shape[0] != self.rotations.shape[0]:
            raise MocapEditError(f"<{self.path}>: foot locking was computed for another pose")
        # One copy of each channel that changes (the pose's channels are float32 already: a
        # second conversion copied a crowd's poses once more).
        rotations = pose.rotations.astype(np.float32)
        rotations[:, self.columns] = self.rotations
        translations = pose.translations
        if self.root_shift is not None:
            translations = translations.copy()
            translations[:, self.root] += self.root_shift
        return animation.Pose(joints=list(pose.joints), translations=translations.astype(np.float32, copy=False),
                              rotations=rotations, scales=pose.scales)

    def aligned(self) -> "LockedLegs":
        """A copy whose arrays are C-contiguous and aligned (arrays that crossed the network
        may not be, and USD's array conversion rejects those)."""
        def fix(a):
            return None if a is None else np.require(a, requirements=("C", "A"))
        return dataclasses.replace(self, columns=fix(self.columns), rotations=fix(self.rotations),
                                   drop=fix(self.drop), root_shift=fix(self.root_shift))
