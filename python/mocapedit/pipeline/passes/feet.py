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
#: further where the leg reaches it (:func:`_reach`).
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


def _skel_space(agent: Agent, pose: animation.Pose, joints: list[int]) -> dict[int, np.ndarray]:
    """(T,4,4) skeleton-space matrices of the given joints and their ancestors, from a pose
    whose joint order may differ from the skeleton's (joints it lacks take the rest pose)."""
    column = {name: k for k, name in enumerate(pose.joints)}
    count = pose.translations.shape[0]
    out: dict[int, np.ndarray] = {}

    def world(j: int) -> np.ndarray:
        if j not in out:
            k = column.get(agent.joints[j])
            if k is None:
                local = np.broadcast_to(agent.rest_transforms[j], (count, 4, 4))
            else:
                local = kinematics.compose_trs(pose.translations[:, k], pose.rotations[:, k], pose.scales[:, k])
            p = int(agent.parents[j])
            out[j] = local if p < 0 else local @ world(p)
        return out[j]

    for j in joints:
        world(j)
    return out


def _yaw_quat(angle: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(T,4) quaternions turning by ``angle`` (radians, counter-clockwise) about the unit ``up``."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)[:, None]
    return np.concatenate([np.sin(half) * up, np.cos(half)], axis=1)


def _posed_legs(ctx, path: str, frames: np.ndarray, times: np.ndarray, shared: dict):
    """(pose after the earlier passes, skeleton-space positions (T,3) and rotations (T,4) of the
    leg joints and the hips' parents). Agents that play one clip at the same frames without
    pose edits share them."""
    agent = ctx.data.agents[path]
    edits = ctx.pose_edits.get(path, [])
    needed = sorted({j for leg in agent.legs for j in (leg.hip, leg.knee, leg.ankle, int(agent.parents[leg.hip]))
                     if j >= 0})
    key = None if edits else (agent.clip_key, tuple(agent.joints), agent.rest_transforms.tobytes(),
                              tuple(needed), frames.tobytes())
    hit = shared.get(key) if key is not None else None
    if hit is None:
        pose = animation.sample_pose(ctx.data.clip_of(agent), frames)
        for edit in edits:
            pose = edit.apply(pose, times, frames)
        skel = _skel_space(agent, pose, needed)
        hit = (pose, {j: skel[j][:, 3, :3] for j in needed},
               {j: trs_from_matrices(skel[j])[1].astype(np.float64) for j in needed})
        if key is not None:
            shared[key] = hit
    return hit


def _top(agent: Agent, joint: int) -> int:
    while int(agent.parents[joint]) >= 0:
        joint = int(agent.parents[joint])
    return joint


def _reach(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, up: np.ndarray, drop: float) -> np.ndarray:
    """(T,) how far (stage units, over the ground) an ankle may move from ``ankle`` in any
    direction and still lie within the leg's soft reach from ``hip`` lowered by ``drop``: the
    leg's soft length over the ground at that height, less the ankle's ground distance from the
    hip. (T,3) world positions of one leg."""
    length = np.linalg.norm(knee - hip, axis=-1) + np.linalg.norm(ankle - knee, axis=-1)
    apart = hip - ankle
    height = np.maximum(apart @ up - drop, 0.0)
    over = np.linalg.norm(apart - np.outer(apart @ up, up), axis=-1)
    return np.sqrt(np.maximum((footlock.SOFT_REACH * length) ** 2 - height ** 2, 0.0)) - over


_CONJUGATE = np.array([-1.0, -1.0, -1.0, 1.0])


def _turn_speed(q: np.ndarray, seconds: np.ndarray) -> np.ndarray:
    """(T-1,) how fast (T,4) rotations turn between samples ``seconds`` apart, radians per second."""
    q = np.asarray(q, dtype=np.float64)
    dot = np.abs(np.sum(q[1:] * q[:-1], axis=-1)) / np.maximum(
        np.linalg.norm(q[1:], axis=-1) * np.linalg.norm(q[:-1], axis=-1), 1e-300)
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0)) / np.maximum(np.diff(seconds), 1e-300)


def _ramp(frames: np.ndarray, first, last, blend, blend_out=None) -> np.ndarray:
    """1 inside [first, last], easing to 0 over ``blend`` frames before and ``blend_out`` (default
    ``blend``) after (smoothstep)."""
    blend_out = blend if blend_out is None else blend_out
    x = np.clip(1.0 - np.maximum(first - frames, 0.0) / blend - np.maximum(frames - last, 0.0) / blend_out, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass
class _Contacts:
    """The contacts of one foot, one row each (C) over the W frames ``at`` its ramp reaches."""
    ranges: np.ndarray      # (C,2) source frames, inclusive
    at: np.ndarray          # (C,W) output frames
    valid: np.ndarray       # (C,W) frames the ramp reaches
    inside: np.ndarray      # (C,W) frames inside the contact
    rigid: np.ndarray       # (C,W) ... and inside a stationary range
    turn: np.ndarray        # (C,W) the edit's turn of the body (radians)
    yaw: np.ndarray         # (C,W) the plant's turn
    foot: np.ndarray        # (C,W,3) the posed source ankle
    pivot: np.ndarray       # (C,3) its mean over the contact, which the plant turns about
    base: np.ndarray        # (C,3) where the pivot goes
    radius: np.ndarray      # (C,W) the leash
    up_axis: str
    offset: np.ndarray | None = None   # (C,W,3) the edited ankle against the carried source foot
    shift: np.ndarray | None = None    # (C,W,3) the plant's ground shift
    lift: np.ndarray | None = None     # (C,W) how far a stepping foot is up (0 to 1 of STEP_HEIGHT_M)

    @property
    def carried(self) -> np.ndarray:
        """(C,W,3) the source foot turned by the plant's turn about the pivot, pivot at ``base``."""
        spin = kinematics.yaw_matrix(self.yaw, self.up_axis)[..., :3, :3]
        return np.einsum("cti,ctij->ctj", self.foot - self.pivot[:, None], spin) + self.base[:, None]

    def sliding(self, distance: float, angle: float) -> np.ndarray:
        """(C,) contacts whose leashed plant slides further than ``distance`` or turns further
        than ``angle`` (radians) inside them."""
        both = self.inside[:, 1:] & self.inside[:, :-1]
        slide = np.where(both, np.linalg.norm(np.diff(self.shift, axis=1), axis=-1), 0.0).sum(axis=1)
        turn = np.where(both, np.abs(np.diff(self.yaw, axis=1)), 0.0).sum(axis=1)
        return (slide > distance) | (turn > angle)


class _AgentLock:
    """One agent's side of the job: what it needs, and what it gets back."""

    def __init__(self, ctx: SolveContext, path: str, source_contacts: list, shared: dict):
        data = ctx.data
        info = data.info
        self.path = path
        agent = self.agent = data.agents[path]
        self.legs = agent.legs
        # Locked legs are a pose edit, and a pose edit bakes the animation: lock on its frames.
        self.times, self.frames = ctx.output_frames(path, baked=True)
        self.root = _top(agent, self.legs[0].hip)
        pose, skel_pos, skel_rot = _posed_legs(ctx, path, self.frames, self.times, shared)
        self.pose = pose
        self.columns = {name: k for k, name in enumerate(pose.joints)}
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
        turn_q = _yaw_quat(turn, up_vector)
        world_q = trs_from_matrices(to_world)[1].astype(np.float64)        # (1 or T, 4)
        # World, before the ground motion (the posed source) and as edited.
        posed = {j: np.einsum("ti,tij->tj", p, to_world[:, :3, :3]) + to_world[:, 3, :3] for j, p in skel_pos.items()}
        pos = {j: np.einsum("ti,tij->tj", p, motion[:, :3, :3]) + motion[:, 3, :3] for j, p in posed.items()}
        posed_rot = {j: quat_multiply(world_q, q) for j, q in skel_rot.items()}
        rot = {j: quat_multiply(turn_q, q) for j, q in posed_rot.items()}

        def per_leg(values, key):
            return np.stack([values[getattr(leg, key)] for leg in self.legs], axis=1)

        self.hip, self.knee, self.ankle = (per_leg(pos, k) for k in ("hip", "knee", "ankle"))
        self.hip_rot, self.knee_rot, self.ankle_rot = (per_leg(rot, k) for k in ("hip", "knee", "ankle"))
        parent_rot = []
        for leg in self.legs:
            p = int(agent.parents[leg.hip])
            parent_rot.append(rot[p] if p >= 0 else quat_multiply(turn_q, np.broadcast_to(world_q, turn_q.shape)))
        self.parent_rot = np.stack(parent_rot, axis=1)
        self.hinge = np.stack([footlock.world_hinge(rot[leg.knee], footlock.knee_hinge(
            skel_pos[leg.hip], skel_pos[leg.knee], skel_pos[leg.ankle], skel_rot[leg.knee])) for leg in self.legs], 1)

        # Plants: per contact, the source foot carried by one turn and one ground translation.
        fps = info.time_codes_per_second
        step = np.median(np.diff(agent.sample_times)) if agent.frame_count > 1 else 1.0
        blend = max(2.0, BLEND_SECONDS * fps / max(step, 1e-9))
        self.blend_frames = int(np.ceil(blend))
        self.agent_fps = fps
        self.contact = np.zeros((count, len(self.legs)), dtype=bool)
        self.locked = 0
        stationary = self.keep = np.zeros(count, dtype=bool)
        for _, first, last in agent.stationary:
            stationary |= (self.frames >= first - 1e-9) & (self.frames <= last + 1e-9)
        self.up_vector = up_vector
        self._rows = [self._contacts(k, leg, source_contacts[k], info, turn, posed, pos, stationary, blend)
                      for k, leg in enumerate(self.legs)]
        self._plan_data = (info, blend, posed, posed_rot, rot)
        self.plan()

    def plan(self, stretch=(1.0, 1.0)) -> None:
        """The targets, turns and weights of the legs from the contacts' plants, where feet step
        (their steps ``stretch`` times as long as :func:`footplant.replant` would make them)."""
        info, blend, posed, posed_rot, rot = self._plan_data
        count = len(self.times)
        up_vector = self.up_vector
        rows = [None if r is None else dataclasses.replace(r, shift=r.shift.copy(), yaw=r.yaw.copy(),
                                                           lift=r.lift.copy()) for r in self._rows]
        self.steps = self._replant(rows, info, posed, posed_rot, stretch) if all(r is not None for r in rows) else 0
        self.stepping = np.zeros((count, len(self.legs)), dtype=bool)
        self.target = self.ankle.copy()
        self.target_rot = self.ankle_rot.copy()
        self.weight = np.zeros((count, len(self.legs)))
        pos_sum = np.zeros((count, len(self.legs), 3))
        rot_sum = np.zeros((count, len(self.legs), 4))
        w_sum = np.zeros((count, len(self.legs)))
        for k, (leg, r) in enumerate(zip(self.legs, rows)):
            if r is None:
                continue
            self.stepping[r.at[r.lift > 0], k] = True
            # The lock eases in and out over longer where the plant lies far from the edited foot
            # (within the frames reached above).
            far = np.linalg.norm(r.shift - r.offset, axis=-1) / (LEASH_M / info.meters_per_unit)    # (C,W)
            rows_c = np.arange(len(r.at))
            ends = r.inside.argmax(axis=1), r.at.shape[1] - 1 - r.inside[:, ::-1].argmax(axis=1)
            blend_in, blend_out = (blend * np.clip(far[rows_c, e], 1.0, MAX_LEASH_M / LEASH_M)[:, None] for e in ends)
            w = np.where(r.valid, _ramp(self.frames[r.at], r.ranges[:, :1], r.ranges[:, 1:], blend_in, blend_out), 0.0)
            valid = r.valid & (w > 0)
            plant_rot = quat_multiply(_yaw_quat(r.yaw.reshape(-1), up_vector).reshape(r.yaw.shape + (4,)),
                                      posed_rot[leg.ankle][r.at])
            plant_rot *= np.where(np.sum(plant_rot * rot[leg.ankle][r.at], -1) < 0, -1.0, 1.0)[..., None]
            plant = r.carried + r.shift + (r.lift * (STEP_HEIGHT_M / info.meters_per_unit))[..., None] * up_vector
            # Where the ramps of two contacts meet, their plants blend by weight: no jump.
            at = r.at[valid]
            np.add.at(pos_sum[:, k], at, (w[..., None] * plant)[valid])
            np.add.at(rot_sum[:, k], at, (w[..., None] * plant_rot)[valid])
            np.add.at(w_sum[:, k], at, w[valid])
            np.maximum.at(self.weight[:, k], at, w[valid])
        some = w_sum > 0
        self.target[some] = pos_sum[some] / w_sum[some][:, None]
        self.target_rot[some] = footlock.normalize(rot_sum[some])

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
                source = _turn_speed(self.pose.rotations[:, self.columns[self.agent.joints[j]]], seconds).max()
                locked = _turn_speed(new[lo:hi, k], seconds)[around].max()
                out_ratio[k] = max(out_ratio[k], locked / max(source, 1e-9))
        return out_ratio

    def _contacts(self, k: int, leg, ranges, info, turn, posed, pos, stationary, blend) -> "_Contacts | None":
        """The contacts of one foot at once, one row each over the frames its ramp reaches, with
        their leashed plants; None without contacts on the output frames."""
        count = len(self.times)
        up = ground.up_index(info.up_axis)
        # The leash: as far as the leg reaches with the pelvis lowered a little, from LEASH_M
        # to MAX_LEASH_M.
        radius = np.clip(_reach(self.hip[:, k], self.knee[:, k], self.ankle[:, k], self.up_vector,
                                MAX_DROP_M / info.meters_per_unit),
                         LEASH_M / info.meters_per_unit, MAX_LEASH_M / info.meters_per_unit)
        ranges = np.array(ranges, dtype=np.float64).reshape(-1, 2)
        inside = (self.frames >= ranges[:, :1] - 1e-9) & (self.frames <= ranges[:, 1:] + 1e-9)   # (C,T)
        used = inside.any(axis=1)
        ranges, inside = ranges[used], inside[used]
        if not len(ranges):
            return None
        self.locked += len(ranges)
        self.contact[:, k] = inside.any(axis=0)
        reached = _ramp(self.frames, ranges[:, :1], ranges[:, 1:], blend * MAX_LEASH_M / LEASH_M) > 0  # (C,T)
        lo = reached.argmax(axis=1)
        width = int((reached.sum(axis=1)).max())
        at = lo[:, None] + np.arange(width)                                                      # (C,W)
        valid = at < count
        at = np.minimum(at, count - 1)
        valid &= np.take_along_axis(reached, at, axis=1)
        inside = np.take_along_axis(inside, at, axis=1) & valid
        # Where a contact meets a stationary range, the body moves rigidly there: the plant
        # is that motion, so the range keeps its shape (no correction inside it).
        rigid = inside & stationary[at]
        chosen = np.where(rigid.any(axis=1, keepdims=True), rigid, inside)
        n_chosen = chosen.sum(axis=1)[:, None]
        turn_c = turn[at]
        yaw0 = np.arctan2((np.sin(turn_c) * chosen).sum(1), (np.cos(turn_c) * chosen).sum(1))[:, None]
        # An edit that turns the body far during a contact turns the plant too.
        apart = np.angle(np.exp(1j * (turn_c - yaw0)))
        yaw = yaw0 + footplant.leash_rows(apart[..., None], np.zeros((len(at), 1)), inside, rigid,
                                          np.radians(LEASH_DEGREES))[..., 0]
        # Turned about the planted foot itself, so a plant that turns along does not slide.
        foot = posed[leg.ankle][at]                                                               # (C,W,3)
        pivot = (foot * chosen[..., None]).sum(1) / n_chosen
        base = np.einsum("ci,cij->cj", pivot, kinematics.yaw_matrix((yaw * chosen).sum(1) / n_chosen[:, 0],
                                                                    info.up_axis)[:, :3, :3])
        out = _Contacts(ranges=ranges, at=at, valid=valid, inside=inside, rigid=rigid, turn=turn_c, yaw=yaw,
                        foot=foot, pivot=pivot, base=base, radius=radius[at], up_axis=info.up_axis)
        out.offset = pos[leg.ankle][at] - out.carried
        out.offset[..., up] = 0.0  # feet stay at their source height: never below their ground
        out.shift = footplant.leash_rows(out.offset, (out.offset * chosen[..., None]).sum(1) / n_chosen, inside,
                                         rigid, out.radius)
        out.lift = np.zeros(at.shape)
        return out

    def _replant(self, rows: list["_Contacts"], info, posed: dict, posed_rot: dict, stretch) -> int:
        """Where the leash lets a foot slide through a contact and the other foot bears the
        weight, the foot steps instead (:func:`footplant.replant`), no faster than the source
        moves and turns that foot; returns the steps taken."""
        count = len(self.times)
        sliding = [r.sliding(STEP_SLIDE_M / info.meters_per_unit, np.radians(STEP_SLIDE_DEGREES)) for r in rows]
        if not any(s.any() for s in sliding) or count < 3:
            return 0
        contact = np.full((count, 2), -1)
        movable = np.zeros((count, 2), dtype=bool)
        offset = np.zeros((count, 2, 3))
        shift = np.zeros((count, 2, 3))
        radius = np.zeros((count, 2))
        turn = np.zeros((count, 2))
        yaw = np.zeros((count, 2))
        for k, (r, s) in enumerate(zip(rows, sliding)):
            c, w = np.nonzero(r.inside)
            t = r.at[c, w]
            contact[t, k] = c
            movable[t, k] = s[c] & ~r.rigid[c, w]
            offset[t, k], shift[t, k], radius[t, k] = r.offset[c, w], r.shift[c, w], r.radius[c, w]
            turn[t, k], yaw[t, k] = r.turn[c, w], r.yaw[c, w]
        seconds = self.times / info.time_codes_per_second
        # The fastest the source moves each foot against its hip, turns it, and bends its knee.
        speed = [float(np.linalg.norm(np.gradient(posed[leg.ankle] - posed[leg.hip], seconds, axis=0), axis=-1).max())
                 for leg in self.legs]
        spin = [float(_turn_speed(posed_rot[leg.ankle], seconds).max()) for leg in self.legs]
        knee_spin = [float(_turn_speed(quat_multiply(posed_rot[leg.hip] * _CONJUGATE, posed_rot[leg.knee]),
                                       seconds).max()) for leg in self.legs]
        height = STEP_HEIGHT_M / info.meters_per_unit
        bend = footplant.lift_bend(np.linalg.norm(self.knee - self.hip, axis=-1),
                                   np.linalg.norm(self.ankle - self.knee, axis=-1),
                                   np.linalg.norm(self.ankle - self.hip, axis=-1), height)
        frame = float(np.median(np.diff(seconds)))
        out = footplant.replant(contact, movable, offset, radius, turn, shift, yaw, np.radians(LEASH_DEGREES),
                                seconds=frame, shortest=max(2, int(round(STEP_SECONDS / frame))),
                                longest=max(2, int(round(STEP_LONGEST_SECONDS / frame))),
                                height=height, bend=bend, speed=np.array(speed), spin=np.array(spin),
                                knee_spin=np.array(knee_spin), stretch=np.asarray(stretch, dtype=np.float64))
        if not out.steps:
            return 0
        for k, (r, s) in enumerate(zip(rows, sliding)):
            for c in np.flatnonzero(s):
                w = np.flatnonzero(r.inside[c])
                t = r.at[c, w]
                for values, new in ((r.shift, out.shift), (r.yaw, out.yaw), (r.lift, out.lift)):
                    values[c, w] = new[t, k]
                    values[c, :w[0]] = values[c, w[0]]
                    values[c, w[-1] + 1:] = values[c, w[-1]]
                r.lift[c, :w[0]] = r.lift[c, w[-1] + 1:] = 0.0
        return out.steps

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

    def world(pose, placement):
        skel = _skel_space(agent, pose, feet)
        return np.stack([np.einsum("ti,tij->tj", skel[f][:, 3, :3], placement[:, :3, :3]) + placement[:, 3, :3]
                         for f in feet], axis=1)

    same = count == agent.frame_count and np.allclose(lock.times, agent.sample_times)
    if same:
        clip = ctx.data.clip_of(agent)
        source = np.stack([trajectory.joint_world(agent, clip, f, chains)[:, 3, :3] for f in feet], axis=1)
    else:
        source = world(animation.sample_pose(ctx.data.clip_of(agent), lock.frames), to_world)
    before = metrics.foot_skate_of_positions(source, lock.times, *units)

    def skate(pose):
        feet_world = world(pose, place)
        contact = metrics.on_ground(before.contact, source, feet_world, info.up_axis, info.meters_per_unit)
        return metrics.foot_skate_of_positions(feet_world, lock.times, *units, contact=contact).mean

    unlocked = skate(lock.pose)
    return before.mean, unlocked, skate(legs.apply(lock.pose)) if legs is not None else unlocked


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
    """Runs the IK job on some agents' legs and fills in their results."""
    info = ctx.data.info
    up = np.zeros(3)
    up[ground.up_index(info.up_axis)] = 1.0
    solved = _solve_legs([lock for lock, _ in locks], up)
    # A step that turns a leg's joint too fast against the pose is made longer, and the agent's
    # legs solved again.
    stretch = {a: np.ones(2) for a in range(len(locks))}
    for _ in range(STEP_ROUNDS):
        again = []
        for a, ((lock, _), (legs, lo, hi)) in enumerate(zip(locks, solved)):
            ratio = lock.step_speed(legs, lo, hi) / STEP_SPEED_RATIO
            if np.any(ratio > 1.0 + 1e-6):
                stretch[a] = stretch[a] * np.maximum(ratio * 1.05, 1.0)
                lock.plan(stretch[a])
                again.append(a)
        if not again:
            break
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
