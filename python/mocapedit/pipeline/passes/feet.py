"""Foot locking, after every other edit (path, time warp, avoidance, layering).

For each edited agent with two legs (found by name or set by ``mocap:leftLegJoints`` /
``mocap:rightLegJoints``), the pose every earlier pass produced is evaluated by forward
kinematics and carried by the agent's edited ground motion. Each foot contact of the
source clip (authored with ``MocapFootContactAPI``, else detected) gets one plant: the
source foot carried by one turn and one ground shift, chosen by least squares where the
edit puts the foot, and leashed to stay within what the leg can reach from where the edit puts
the foot (at least ``LEASH_M``, with the pelvis lowered by at most ``MAX_DROP_M``) and
``LEASH_DEGREES`` of its turn. The solver's foot-locking job (:mod:`mocapedit.solve.footlock`)
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
from mocapedit.solve.layering import quat_multiply, trs_from_matrices
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
#: Degrees a plant may be turned from the edited foot before it is turned along.
LEASH_DEGREES = 15.0
#: Seconds a foot takes to step where an edit drags or turns a standing body further than the
#: leash (:func:`footplant.replant`): at least STEP_SECONDS, longer so that the foot moves no
#: faster than its source does, but no longer than STEP_LONGEST_SECONDS; and metres it lifts at
#: the top of the step.
STEP_SECONDS = 0.3
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
#: Agents whose feet the edits make slide by at most this much more than the source's (metres
#: per second, the issue's quality bar) keep their legs: locking them would bake their whole
#: animation for a change no one sees.
SKATE_TOLERANCE_M = 0.005
#: Agents whose ankles all stay within this of where the edit puts them, and whose pelvis
#: drops less, keep their legs (metres): locking would move a foot by less than this over a
#: whole contact, and leaving them saves baking their animation.
STILL_M = 0.002


def _skel_space(agent: Agent, pose: animation.Pose, joints: list[int], base: "_Chains | None" = None,
                changed: frozenset = frozenset()) -> "_Chains":
    """(T,4,4) joint-local and skeleton-space matrices of the given joints and their ancestors,
    from a pose whose joint order may differ from the skeleton's (joints it lacks take the rest
    pose). ``base``: the matrices of a pose that differs from this one only in the joints
    ``changed``; the other joints take theirs from it."""
    column = {name: k for k, name in enumerate(pose.joints)}
    count = pose.translations.shape[0]
    chain: list[int] = []
    seen: set[int] = set()
    for j in joints:
        up: list[int] = []
        while j >= 0 and j not in seen:
            seen.add(j)
            up.append(j)
            j = int(agent.parents[j])
        chain.extend(reversed(up))           # parents before children
    local: dict[int, np.ndarray] = {}
    todo = []
    for j in chain:
        if base is not None and j not in changed and j in base.local:
            local[j] = base.local[j]
        elif agent.joints[j] not in column:
            local[j] = np.broadcast_to(agent.rest_transforms[j], (count, 4, 4))
        else:
            todo.append(j)
    if todo:
        # All joints' local matrices in one call, one contiguous (T,4,4) block each.
        cols = [column[agent.joints[j]] for j in todo]
        blocks = kinematics.compose_trs(*(np.swapaxes(a[:, cols], 0, 1)
                                          for a in (pose.translations, pose.rotations, pose.scales)))
        local.update(zip(todo, blocks))
    skel: dict[int, np.ndarray] = {}
    moved: set[int] = set()
    for j in chain:
        p = int(agent.parents[j])
        if base is None or j in changed or p in moved or j not in base.skel:
            moved.add(j)
            skel[j] = local[j] if p < 0 else local[j] @ skel[p]
        else:
            skel[j] = base.skel[j]
    return _Chains(local, skel)


@dataclass
class _Chains:
    """Joint-local and skeleton-space (T,4,4) matrices of some joints of one pose, by joint."""
    local: dict
    skel: dict


@dataclass
class _Posed:
    """An agent's pose after the earlier passes at its output frames, and its forward kinematics:
    the leg joints, the hips' parents and the feet (``chains``); skeleton-space positions (T,K,3)
    and rotations (T,K,4) of the K leg joints and hips' parents (``needed``, in that order), and
    each leg's knee hinge in the knee's frame (2,3)."""
    pose: animation.Pose
    chains: _Chains
    needed: list
    pos: np.ndarray
    rot: np.ndarray
    hinge: np.ndarray


def _posed_legs(ctx, path: str, frames: np.ndarray, times: np.ndarray, shared: dict) -> _Posed:
    """The pose after the earlier passes and its forward kinematics. Agents that play one clip
    at the same frames without pose edits share them."""
    agent = ctx.data.agents[path]
    edits = ctx.pose_edits.get(path, [])
    needed = sorted({j for leg in agent.legs for j in (leg.hip, leg.knee, leg.ankle, int(agent.parents[leg.hip]))
                     if j >= 0})
    feet = metrics.default_foot_joints(agent.joints)
    key = None if edits else (agent.clip_key, tuple(agent.joints), agent.rest_transforms.tobytes(),
                              tuple(needed), frames.tobytes())
    hit = shared.get(key) if key is not None else None
    if hit is None:
        pose = animation.sample_pose(ctx.data.clip_of(agent), frames)
        for edit in edits:
            pose = edit.apply(pose, times, frames)
        chains = _skel_space(agent, pose, needed + feet)
        matrices = np.stack([chains.skel[j] for j in needed], axis=1)
        pos, rot = matrices[..., 3, :3], trs_from_matrices(matrices)[1].astype(np.float64)
        column = {j: i for i, j in enumerate(needed)}
        hinge = np.stack([footlock.knee_hinge(*(pos[:, column[j]] for j in (leg.hip, leg.knee, leg.ankle)),
                                              rot[:, column[leg.knee]]) for leg in agent.legs])
        hit = _Posed(pose, chains, needed, pos, rot, hinge)
        if key is not None:
            shared[key] = hit
    return hit


def _top(agent: Agent, joint: int) -> int:
    while int(agent.parents[joint]) >= 0:
        joint = int(agent.parents[joint])
    return joint


class _AgentLock:
    """One agent's side of the jobs: what it needs, and what it gets back."""

    def __init__(self, ctx: SolveContext, path: str, source_contacts: list, shared: dict):
        data = ctx.data
        info = data.info
        self.path = path
        agent = self.agent = data.agents[path]
        self.legs = agent.legs
        # Locked legs are a pose edit, and a pose edit bakes the animation: lock on its frames.
        self.times, self.frames = ctx.output_frames(path, baked=True)
        self.root = _top(agent, self.legs[0].hip)
        posed = self.posed = _posed_legs(ctx, path, self.frames, self.times, shared)
        self.pose = posed.pose
        self.columns = {name: k for k, name in enumerate(self.pose.joints)}
        # Contacts on these frames.
        self.contacts = []
        for ranges in source_contacts:
            ranges = np.array(ranges, dtype=np.float64).reshape(-1, 2)
            inside = (self.frames >= ranges[:, :1] - 1e-9) & (self.frames <= ranges[:, 1:] + 1e-9)
            self.contacts.append(ranges[inside.any(axis=1)])
        self.locked = sum(len(c) for c in self.contacts)
        if not self.locked:
            return
        to_world = agent.skel_to_world
        if to_world.shape[0] > 1:
            to_world = animation.interp_frames(to_world, self.frames)
        self.to_world = to_world
        count = len(self.times)
        up_vector = np.zeros(3)
        up_vector[ground.up_index(info.up_axis)] = 1.0
        # The edited ground motion (identity without a path edit): a turn about up, then a shift.
        edited = ctx.paths.get(path)
        if edited is None:
            motion = np.broadcast_to(np.eye(4), (count, 4, 4))
            turn = np.zeros(count)
        else:
            traj = ctx.trajectories[path]
            src_h = animation.interp_frames(traj.heading, self.frames)
            new_h = animation.interp_frames(edited.heading, self.frames)
            motion = trajectory.ground_motion(
                animation.interp_frames(traj.ground, self.frames), src_h,
                animation.interp_frames(edited.ground, self.frames), new_h, info.up_axis)
            turn = new_h - src_h
        self.motion = motion
        turn_q = footplant.yaw_quat(turn, up_vector)
        world_q = trs_from_matrices(to_world)[1].astype(np.float64)        # (1 or T, 4)
        # World, before the ground motion (the posed source) and as edited; (T,K,...) by needed joint.
        source = np.einsum("tki,tij->tkj", posed.pos, to_world[:, :3, :3]) + to_world[:, None, 3, :3]
        pos = np.einsum("tki,tij->tkj", source, motion[:, :3, :3]) + motion[:, None, 3, :3]
        source_rot = quat_multiply(world_q[:, None], posed.rot)
        rot = quat_multiply(turn_q[:, None], source_rot)
        column = {j: i for i, j in enumerate(posed.needed)}

        def per_leg(key):
            return [column[getattr(leg, key)] for leg in self.legs]

        hip, knee, ankle = per_leg("hip"), per_leg("knee"), per_leg("ankle")
        self.hip, self.knee, self.ankle = pos[:, hip], pos[:, knee], pos[:, ankle]
        self.hip_rot, self.knee_rot, self.ankle_rot = rot[:, hip], rot[:, knee], rot[:, ankle]
        parent_rot = []
        for leg in self.legs:
            p = int(agent.parents[leg.hip])
            parent_rot.append(rot[:, column[p]] if p >= 0
                              else quat_multiply(turn_q, np.broadcast_to(world_q, turn_q.shape)))
        self.parent_rot = np.stack(parent_rot, axis=1)
        self.hinge = footlock.world_hinge(self.knee_rot, posed.hinge)

        # Plants: per contact, the source foot carried by one turn and one ground translation.
        fps = info.time_codes_per_second
        step = np.median(np.diff(agent.sample_times)) if agent.frame_count > 1 else 1.0
        self.blend = max(2.0, BLEND_SECONDS * fps / max(step, 1e-9))
        self.blend_frames = int(np.ceil(self.blend))
        self.agent_fps = fps
        stationary = self.keep = np.zeros(count, dtype=bool)
        for _, first, last in agent.stationary:
            stationary |= (self.frames >= first - 1e-9) & (self.frames <= last + 1e-9)
        self.plant_inputs = dict(
            frames=self.frames, seconds=self.times / fps, stationary=stationary, turn=turn, hip=self.hip,
            knee=self.knee, ankle=self.ankle, ankle_rot=self.ankle_rot, source_hip=source[:, hip],
            source_ankle=source[:, ankle], source_hip_rot=source_rot[:, hip], source_knee_rot=source_rot[:, knee],
            source_ankle_rot=source_rot[:, ankle])

    def planned(self, out: footplant.PlantOutputs, a: int, lo: int, hi: int) -> None:
        """Takes the plants of agent ``a`` of a plant job, its poses lo:hi."""
        self.target, self.target_rot = out.target[lo:hi], out.target_rot[lo:hi]
        self.weight, self.stepping, self.steps = out.weight[lo:hi], out.stepping[lo:hi], int(out.steps[a])

    def step_speed(self, out: footlock.LegOutputs, lo: int, hi: int) -> np.ndarray:
        """(legs,) the largest angular speed of a leg's hip, knee or ankle around its steps, against
        the largest the joint turns at in the pose before locking (1 when it steps no faster)."""
        seconds = self.times / self.agent_fps
        out_ratio = np.ones(len(self.legs))
        if not self.steps or len(seconds) < 2:
            return out_ratio

        near = self.stepping.copy()
        for shift_by in (1, 2):
            near[shift_by:] |= self.stepping[:-shift_by]
            near[:-shift_by] |= self.stepping[shift_by:]
        for k, leg in enumerate(self.legs):
            if not near[:, k].any():
                continue
            around = near[1:, k] | near[:-1, k]
            for j, new in ((leg.hip, out.hip_local), (leg.knee, out.knee_local), (leg.ankle, out.ankle_local)):
                source = footplant.turn_speed(self.pose.rotations[:, self.columns[self.agent.joints[j]]], seconds).max()
                locked = footplant.turn_speed(new[lo:hi, k], seconds)[around].max()
                out_ratio[k] = max(out_ratio[k], locked / max(source, 1e-9))
        return out_ratio

    def inputs(self) -> dict:
        return {"hip": self.hip, "knee": self.knee, "ankle": self.ankle, "parent_rot": self.parent_rot,
                "hip_rot": self.hip_rot, "knee_rot": self.knee_rot, "ankle_rot": self.ankle_rot,
                "target": self.target, "target_rot": self.target_rot, "weight": self.weight, "hinge": self.hinge, "keep": self.keep}

    def writable(self) -> str | None:
        """Why the legs cannot be baked into this agent's pose, or None."""
        for leg in self.legs:
            for j in (leg.hip, leg.knee, leg.ankle):
                if self.agent.joints[j] not in self.columns:
                    return f"leg joint '{self.agent.joints[j]}' is not animated by the clip"
        return None

    def apply(self, out: footlock.LegOutputs, lo: int, hi: int, up: np.ndarray,
              meters_per_unit: float) -> "LockedLegs | None":
        """The locked legs, or None when locking leaves them as they are."""
        columns = [self.columns[self.agent.joints[j]] for leg in self.legs for j in (leg.hip, leg.knee, leg.ankle)]
        rotations = np.stack([new[lo:hi, k] for k in range(len(self.legs))
                              for new in (out.hip_local, out.knee_local, out.ankle_local)], axis=1)
        drop = out.drop[lo:hi]
        root, shift = None, None
        if np.any(drop > 0):
            root = self.columns.get(self.agent.joints[self.root])
            if root is None:
                raise MocapEditError(
                    f"<{self.path}>: the pelvis must be lowered but the skeleton root "
                    f"'{self.agent.joints[self.root]}' is not animated by the clip")
            # World offset -drop * up, in the root's parent space (the skeleton's).
            inv = np.linalg.inv(self.to_world[:, :3, :3])
            shift = (-drop[:, None] * up) @ inv if inv.ndim == 2 else np.einsum("ti,tij->tj", -drop[:, None] * up, inv)
        # The correction of a planted foot: a stepping foot is in the air, moving to its next plant.
        correction = np.where(self.stepping, 0.0, np.linalg.norm(out.reached[lo:hi] - self.ankle, axis=-1))
        self.max_correction = float(correction.max(initial=0.0))
        self.max_drop = float(drop.max(initial=0.0))
        self.reached = out.reached[lo:hi]
        still = STILL_M / meters_per_unit
        if self.max_correction <= still and self.max_drop <= still:
            return None
        return LockedLegs(self.path, list(self.pose.joints), np.array(columns, dtype=np.int64),
                          rotations.astype(np.float32),
                          None if root is None else drop.astype(np.float64), root,
                          None if shift is None else np.asarray(shift, dtype=np.float64))


def _source(ctx, agent: Agent, cache: dict) -> tuple[list[list[tuple[int, int]]], float]:
    """(per leg, the inclusive frame ranges of its foot contacts on the source clip; the source
    foot skate over them, stage units per second). Agents that play one clip share them."""
    place = agent.skel_to_world
    # A static placement's translation and turn about up change neither the contacts nor the
    # skate: what matters is how it maps the skeleton to height (its up column) and its scale.
    up = ground.up_index(ctx.data.info.up_axis)
    placement = (np.round(place[0, :3, up], 12).tobytes(), round(float(np.linalg.norm(place[0, 0, :3])), 12)) \
        if place.shape[0] == 1 else place.tobytes()
    key = (agent.clip_key, tuple(agent.joints), tuple(leg.joints for leg in agent.legs),
           tuple(agent.foot_contacts or ()), placement)
    hit = cache.get(key)
    if hit is None:
        info = ctx.data.info
        clip = ctx.data.clip_of(agent)
        if agent.foot_contacts is not None:
            found = [[(a, b) for _, ankle, a, b in agent.foot_contacts if ankle == leg.ankle] for leg in agent.legs]
        else:
            found = contacts.detect_agent(agent, clip, info)
        hit = cache[key] = found
    return hit


def _report_skate(ctx, lock: "_AgentLock", legs: "LockedLegs | None", chains: dict) -> tuple[float, float, float] | None:
    """(source, after the edits, after locking) foot skate of a locked agent, stage units per
    second, as :func:`mocapedit.tools.measure.foot_skate` measures it on the input and on the composed
    stage: joints named like feet, over the frames where the source's feet are planted.

    A retimed agent is measured against its source as its timing plays it: the clip's poses at
    the same clip times, per second of the shot. Against the source at its own samples, a time
    warp alone would count as sliding what the source does between its samples (where a warp
    falls) and its heel-toe roll played faster. None for a skeleton without such joints."""
    agent, info = lock.agent, ctx.data.info
    feet = metrics.default_foot_joints(agent.joints)
    if not feet:
        return None
    units = (info.up_axis, info.meters_per_unit, info.time_codes_per_second)
    count = len(lock.times)
    to_world = np.broadcast_to(lock.to_world, (count, 4, 4))
    place = to_world @ lock.motion

    def world(skel, placement):
        return np.stack([np.einsum("ti,tij->tj", skel[f][:, 3, :3], placement[:, :3, :3]) + placement[:, 3, :3]
                         for f in feet], axis=1)

    posed = lock.posed.chains
    same = count == agent.frame_count and np.allclose(lock.times, agent.sample_times)
    if same:
        clip = ctx.data.clip_of(agent)
        source = np.stack([trajectory.joint_world(agent, clip, f, chains)[:, 3, :3] for f in feet], axis=1)
    elif not ctx.pose_edits.get(lock.path):
        # The pose locking starts from is the source's at these frames.
        source = world(posed.skel, to_world)
    else:
        source = world(_skel_space(agent, animation.sample_pose(ctx.data.clip_of(agent), lock.frames), feet).skel,
                       to_world)
    before = metrics.foot_skate_of_positions(source, lock.times, *units)

    def skate(skel):
        feet_world = world(skel, place)
        contact = metrics.on_ground(before.contact, source, feet_world, info.up_axis, info.meters_per_unit)
        return metrics.foot_skate_of_positions(feet_world, lock.times, *units, contact=contact).mean

    unlocked = skate(posed.skel)
    if legs is None:
        return before.mean, unlocked, unlocked
    locked = legs.apply(lock.pose)
    base, changed = None, frozenset()
    if lock.pose.translations.dtype == np.float32 and lock.pose.rotations.dtype == np.float32:
        # Only the legs' joints (and the root, where lowered) differ from the pose before locking.
        columns = set(legs.columns.tolist()) | ({legs.root} if legs.root_shift is not None else set())
        base = posed
        changed = frozenset(j for j, name in enumerate(agent.joints) if lock.columns.get(name) in columns)
    return before.mean, unlocked, skate(_skel_space(agent, locked, feet, base, changed).skel)


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
    cache: dict = {}
    shared: dict = {}
    chains: dict = {}
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
            lock = _AgentLock(ctx, path, _source(ctx, agent, cache), shared)
            why = lock.writable()
            if why:
                result.note = f"foot locking skipped: {why}"
            elif lock.locked:
                locks.append((lock, result))
        if len(locks) >= LOCK_RUN:
            _lock_run(ctx, locks, chains)
            locks = []
    if locks:
        _lock_run(ctx, locks, chains)
    return out


def _lock_run(ctx: SolveContext, locks: list, chains: dict) -> None:
    """Runs the plant and IK jobs on some agents' legs and fills in their results."""
    info = ctx.data.info
    up = np.zeros(3)
    up[ground.up_index(info.up_axis)] = 1.0
    stretch = [np.ones(2) for _ in locks]
    _plan(ctx, [lock for lock, _ in locks], stretch)
    solved = _solve_legs([lock for lock, _ in locks], up)
    # A step that turns a leg's joint too fast against the pose is made longer, and the agent's
    # legs solved again.
    for _ in range(STEP_ROUNDS):
        again = []
        for a, ((lock, _), (legs, lo, hi)) in enumerate(zip(locks, solved)):
            ratio = lock.step_speed(legs, lo, hi) / STEP_SPEED_RATIO
            if np.any(ratio > 1.0 + 1e-6):
                stretch[a] = stretch[a] * np.maximum(ratio * 1.05, 1.0)
                again.append(a)
        if not again:
            break
        _plan(ctx, [locks[a][0] for a in again], [stretch[a] for a in again])
        for a, done in zip(again, _solve_legs([locks[a][0] for a in again], up)):
            solved[a] = done
    tolerance = SKATE_TOLERANCE_M / info.meters_per_unit
    for (lock, result), (legs, lo, hi) in zip(locks, solved):
        locked_legs = lock.apply(legs, lo, hi, up, info.meters_per_unit)
        skate = _report_skate(ctx, lock, locked_legs, chains)
        if locked_legs is not None and skate is not None and skate[1] <= skate[0] + tolerance:
            # The edit left the feet as planted as the source's: keep the legs, bake nothing.
            locked_legs, skate = None, (skate[0], skate[1], skate[1])
            result.kept = True
        result.contacts, result.skate, result.legs = lock.locked, skate, locked_legs
        result.steps = lock.steps if locked_legs is not None else 0
        result.max_drop, result.max_correction = lock.max_drop, lock.max_correction
        result.plants = _plants(lock)


def _plan(ctx: SolveContext, locks: list[_AgentLock], stretch: list[np.ndarray]) -> None:
    """The plants of these agents' feet, each leg's steps ``stretch`` times as long as they would
    be: the solver's plant job on all of them at once."""
    info = ctx.data.info
    up = np.zeros(3)
    up[ground.up_index(info.up_axis)] = 1.0
    offsets = np.cumsum([0] + [len(lock.times) for lock in locks]).astype(np.int64)
    contacts = [c for lock in locks for c in lock.contacts]
    inputs = footplant.PlantInputs(
        offsets=offsets, contact_offsets=np.cumsum([0] + [len(c) for c in contacts]).astype(np.int64),
        contacts=np.concatenate(contacts).reshape(-1, 2), blend=np.array([lock.blend for lock in locks]),
        stretch=np.array(stretch, dtype=np.float64).reshape(-1, 2), up=up, meters_per_unit=info.meters_per_unit,
        leash_m=LEASH_M, max_leash_m=MAX_LEASH_M, max_drop_m=MAX_DROP_M, leash_degrees=LEASH_DEGREES,
        soft_reach=footlock.SOFT_REACH, step_slide_m=STEP_SLIDE_M, step_slide_degrees=STEP_SLIDE_DEGREES,
        step_seconds=STEP_SECONDS, step_longest_seconds=STEP_LONGEST_SECONDS, step_height_m=STEP_HEIGHT_M,
        **{k: np.concatenate([lock.plant_inputs[k] for lock in locks]) for k in locks[0].plant_inputs})
    out = footplant.plan_feet_numpy(inputs)
    for a, lock in enumerate(locks):
        lock.planned(out, a, int(offsets[a]), int(offsets[a + 1]))


def _solve_legs(locks: list[_AgentLock], up: np.ndarray) -> list[tuple[footlock.LegOutputs, int, int]]:
    """The solver's job on these agents' legs at once: per agent, (the outputs, its first and
    last + 1 pose in them)."""
    offsets = np.cumsum([0] + [len(lock.times) for lock in locks])
    parts = [lock.inputs() for lock in locks]
    inputs = footlock.LegInputs(
        offsets=offsets.astype(np.int64), smooth=np.array([lock.blend_frames for lock in locks], dtype=np.int64),
        up=up, **{k: np.concatenate([p[k] for p in parts]) for k in parts[0]})
    legs = footlock.lock_feet(inputs)
    return [(legs, int(lo), int(hi)) for lo, hi in zip(offsets[:-1], offsets[1:])]


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
        _plant_guides(ctx, [r.plants for r in locked if r.path in ctx.pose_edits])
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


def _plants(lock: _AgentLock) -> tuple[np.ndarray, np.ndarray]:
    """Where the agent's locked feet are planted: the ankle at the first fully locked frame of
    each contact and where each step lands, blue for left feet and orange for right.
    (points, colors)."""
    points, colors = [], []
    for k, leg in enumerate(lock.legs):
        full = lock.weight[:, k] >= 1.0
        starts = np.flatnonzero(full & ~np.concatenate([[False], full[:-1]]))
        stepping = lock.stepping[:, k]
        landed = np.flatnonzero(~stepping & np.concatenate([[False], stepping[:-1]]))
        at = np.union1d(starts, landed)
        points.append(lock.target[at, k])
        colors.append(np.tile(PLANT_COLORS[0 if leg.side == "left" else 1], (len(at), 1)))
    return np.concatenate(points), np.concatenate(colors)


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
        rotations = pose.rotations.copy()
        rotations[:, self.columns] = self.rotations
        translations = pose.translations
        if self.root_shift is not None:
            translations = translations.copy()
            translations[:, self.root] += self.root_shift
        return animation.Pose(joints=list(pose.joints), translations=translations.astype(np.float32),
                              rotations=rotations.astype(np.float32), scales=pose.scales)

    def aligned(self) -> "LockedLegs":
        """A copy whose arrays are C-contiguous and aligned (arrays that crossed the network
        may not be, and USD's array conversion rejects those)."""
        def fix(a):
            return None if a is None else np.require(a, requirements=("C", "A"))
        return dataclasses.replace(self, columns=fix(self.columns), rotations=fix(self.rotations),
                                   drop=fix(self.drop), root_shift=fix(self.root_shift))
