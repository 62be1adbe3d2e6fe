"""Ground trajectories of agents, and the rigid ground motions that carry an edit.

The trajectory of an agent is its root joint's world position on the ground plane at
each source frame (section 5.4.1 of the deliverable): the root joint when it carries the
motion, otherwise the hip joint projected to the ground. Its source heading follows the path
tangent, held constant through stationary ranges; an edit turns it by the rotation the edit
applies to the path around each frame (:func:`deformation_turns`), never by the edited path's
own tangent.

An edit moves an agent's ground pose ``(position, heading)`` at each frame to a new one.
Because only the ground-plane motion and the yaw change, the whole body follows by one
rigid motion about the up axis per frame, ``M(t)``; everything else (height, every joint)
keeps its source value.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import ground, kinematics
from mocapedit.model.data import Agent, Clip

#: Ground travel (in metres) below which the root is said to carry no motion.
STILL_ROOT_M = 1e-4


@dataclass
class Trajectory:
    ground: np.ndarray        # (F,2) ground coordinates of the tracked joint
    heading: np.ndarray       # (F,) radians, counter-clockwise about up
    height: np.ndarray        # (F,) world height of the tracked joint
    joint: int                # skeleton index of the tracked joint
    projected_hip: bool       # True when the root carries no motion and the hip is used


def local_transforms(agent: Agent, clip: Clip) -> np.ndarray:
    """(F,J,4,4) joint-local matrices in skeleton order; joints the clip lacks take the rest pose."""
    f = clip.frame_count
    local = np.broadcast_to(agent.rest_transforms, (f,) + agent.rest_transforms.shape).copy()
    have = agent.anim_to_skel >= 0
    local[:, agent.anim_to_skel[have]] = kinematics.compose_trs(
        clip.translations[:, have], clip.rotations[:, have], clip.scales[:, have])
    return local


def joint_skel_space(agent: Agent, clip: Clip, joint: int) -> np.ndarray:
    """(F,4,4) skeleton-space matrices of one joint, composing only its chain of parents."""
    chain = []
    j = joint
    while j >= 0:
        chain.append(j)
        j = int(agent.parents[j])
    skel_to_anim = {int(s): a for a, s in enumerate(agent.anim_to_skel) if s >= 0}
    m = None
    for j in chain:  # joint first, then its parents: skel = local_j @ local_parent @ ...
        a = skel_to_anim.get(j)
        if a is None:
            local = np.broadcast_to(agent.rest_transforms[j], (clip.frame_count, 4, 4))
        else:
            local = kinematics.compose_trs(clip.translations[:, a], clip.rotations[:, a], clip.scales[:, a])
        m = local if m is None else m @ local
    return m


def skel_world(agent: Agent, clip: Clip) -> np.ndarray:
    """(F,J,4,4) world matrices of every joint at every source frame."""
    return kinematics.skel_space(local_transforms(agent, clip), agent.parents) @ agent.skel_to_world[:, None]


def joint_world(agent: Agent, clip: Clip, joint: int, cache: dict | None = None) -> np.ndarray:
    """(F,4,4) world matrices of one joint at every source frame.

    ``cache`` (optional, shared across agents) keeps the skeleton-space chains of clips
    that many agents play, so a crowd of re-used clips is composed once per clip."""
    return _skel_space_cached(agent, clip, joint, cache) @ agent.skel_to_world


def _skel_space_cached(agent: Agent, clip: Clip, joint: int, cache: dict | None) -> np.ndarray:
    key = (agent.clip_key, tuple(agent.joints), joint)
    skel = cache.get(key) if cache is not None else None
    if skel is None:
        skel = joint_skel_space(agent, clip, joint)
        if cache is not None:
            cache[key] = skel
    return skel


def joint_world_position(agent: Agent, clip: Clip, joint: int, cache: dict | None = None) -> np.ndarray:
    """(F,3) world position of one joint at every source frame: the translation of
    :func:`joint_world`, without composing the rest of the matrices (``cache`` as there)."""
    return (_skel_space_cached(agent, clip, joint, cache)[:, 3:4, :] @ agent.skel_to_world)[:, 0, :3]


def extract(agent: Agent, clip: Clip, up_axis: str, meters_per_unit: float,
            cache: dict | None = None) -> Trajectory:
    """The agent's ground trajectory, its heading and height at each source frame.

    ``cache``: see :func:`joint_world`.
    """
    def world(joint):
        return joint_world(agent, clip, joint, cache)

    root = world(agent.root_joint)
    pos = root[:, 3, :3]
    uv = ground.to_ground(pos, up_axis)
    joint, projected = agent.root_joint, False
    travel = np.ptp(uv, axis=0).max() if len(uv) else 0.0
    if travel < STILL_ROOT_M / meters_per_unit and agent.hip_joint is not None:
        hip = world(agent.hip_joint)
        if np.ptp(ground.to_ground(hip[:, 3, :3], up_axis), axis=0).max() > travel:
            pos = hip[:, 3, :3]
            uv = ground.to_ground(pos, up_axis)
            joint, projected = agent.hip_joint, True
    heading = headings(uv, [(a, b) for _, a, b in agent.stationary], meters_per_unit)
    return Trajectory(ground=uv, heading=heading, height=ground.height(pos, up_axis), joint=joint,
                      projected_hip=projected)


def headings(uv: np.ndarray, fixed: list[tuple[int, int]], meters_per_unit: float) -> np.ndarray:
    """Tangent headings; each fixed (stationary) range keeps the heading it is entered with."""
    still = 1e-5 / meters_per_unit
    free = _solver.tangent_headings(np.ascontiguousarray(uv, dtype=np.float64), [], np.zeros(0), still)
    if not fixed:
        return free
    fallback = np.array([free[a] for a, _ in fixed])
    return _solver.tangent_headings(np.ascontiguousarray(uv, dtype=np.float64), fixed, fallback, still)


#: Half-width (seconds) of each of the two box windows that average the edit's rotation.
TURN_WINDOW_S = 0.2
#: Source ground speed (metres per second) below which a frame's turn comes from the frames
#: around it instead of its own steps.
TURN_MIN_SPEED_M = 0.1
#: Source ground speed (metres per second) beyond which a step is a cut, not a motion (a clip's
#: first frame left at its rest pose, a teleport): faster than anyone runs.
CUT_SPEED_M = 15.0


def is_cut(step: np.ndarray, seconds: np.ndarray, meters_per_unit: float) -> np.ndarray:
    """Which steps are cuts: ``step`` ground lengths (stage units) taken in ``seconds``, any
    matching shapes; faster than ``CUT_SPEED_M``."""
    return np.asarray(step) > CUT_SPEED_M / meters_per_unit * np.asarray(seconds)


def samples_per_second(sample_times: np.ndarray, time_codes_per_second: float) -> float:
    """How many samples per second a path sampled at ``sample_times`` (shot time codes) has: a
    120 fps clip on a 24 fps stage has five per time code (its median step). Agents that play
    one clip share their sample times: the figure is computed once per distinct times."""
    times = np.ascontiguousarray(sample_times, dtype=np.float64)
    return _samples_per_second(times.tobytes(), times.shape, float(time_codes_per_second))


@functools.lru_cache(maxsize=1024)
def _samples_per_second(times: bytes, shape: tuple, time_codes_per_second: float) -> float:
    step = np.diff(np.frombuffer(times, dtype=np.float64).reshape(shape))
    step = step[step > 0]
    return time_codes_per_second / float(np.median(step)) if len(step) else time_codes_per_second


def turn_window(fps: float) -> int:
    """Half-width in frames of the windows of :func:`deformation_turns` at ``fps``."""
    return max(1, int(round(TURN_WINDOW_S * float(fps))))


def deformation_turns(source: np.ndarray, edited: np.ndarray, offsets, fixed=(), fixed_turn=(),
                      window: int = 2, min_travel: float = 0.0, max_step: float = 0.0,
                      keep_spot=None) -> np.ndarray:
    """(F,) turn of each frame's heading (radians, counter-clockwise) when paths go from source
    to edited: the local rotation the edit applies to the path around the frame (the least-squares
    rotation of the source steps onto the edited ones within two nested windows of ``window``
    frames each side; where the source moves less than ``min_travel`` stage units across the
    window, interpolated from the moving frames around it; each fixed range by its own turn; a source
    step longer than ``max_step`` stage units, a cut, counts for nothing (0: none)). See
    ``DeformationTurns`` in ``solver/include/mocapedit/trajectory.h``. An unedited path turns by
    exactly 0, a rigidly turned walk by its angle. A path that stays about one spot (a boxer's
    bounce, a dance, an idle) keeps its facing, however the edit turns its wiggles, rigidly or
    not, unless ``keep_spot`` says otherwise for its block (a group member turns with its
    formation; the path editor turns a component moved as one rigid body without asking).

      source, edited  (F,2) ground paths of one or more agents, concatenated
      offsets         (B+1,) first frame of each agent's block, then F
      fixed           (R,3) (block, first, last) inclusive frame ranges within the blocks, by block
      fixed_turn      (R,) turn of each fixed range
      keep_spot       (B,) bool per block, or None: every block
    """
    s = np.ascontiguousarray(source, dtype=np.float64)
    e = np.ascontiguousarray(edited, dtype=np.float64)
    off = np.asarray(offsets, dtype=np.int32)
    if s.shape != e.shape or s.ndim != 2 or s.shape[1] != 2 or len(off) < 1 or off[-1] != len(s):
        raise ValueError(f"source {s.shape} and edited {e.shape} must be (F,2) with offsets ending at F")
    blocks = np.ascontiguousarray(np.stack((off[:-1], off[1:]), axis=1))
    ranges = np.ascontiguousarray(np.asarray(fixed, dtype=np.int32).reshape(-1, 3))
    turns = np.asarray(fixed_turn, dtype=np.float64).reshape(-1)
    keep = np.ones(len(blocks), dtype=np.int32) if keep_spot is None else np.asarray(keep_spot, dtype=np.int32)
    return _solver.block_deformation_turns(source=s, edited=e, blocks=blocks, fixed=ranges, fixed_turn=turns,
                                           window=int(window), min_travel=float(min_travel),
                                           max_step=float(max_step), keep_spot=keep)


def ground_motion(src_uv: np.ndarray, src_heading: np.ndarray, new_uv: np.ndarray,
                  new_heading: np.ndarray, up_axis: str) -> np.ndarray:
    """(F,4,4) world-space rigid motions taking each source ground pose to the edited one.

    A world point ``p`` of the agent at frame ``i`` moves to ``p @ M[i]``: it is turned
    about the up axis through the source root by the change of heading, then carried
    from the source root position to the edited one. Leading axes (ground poses (..., F, 2)
    and headings (..., F)) give (..., F, 4, 4).
    """
    zero = np.zeros(np.shape(src_uv)[:-1])
    to_origin = kinematics.translation_matrix(-ground.from_ground(src_uv, zero, up_axis))
    turn = kinematics.yaw_matrix(np.asarray(new_heading) - np.asarray(src_heading), up_axis)
    to_new = kinematics.translation_matrix(ground.from_ground(new_uv, zero, up_axis))
    return to_origin @ turn @ to_new


def lowering(drop: np.ndarray, up_axis: str) -> np.ndarray:
    """(T,4,4) world translations lowering a body by ``drop`` (T,) stage units along up."""
    drop = np.asarray(drop, dtype=np.float64)
    return kinematics.translation_matrix(ground.from_ground(np.zeros(drop.shape + (2,)), -drop, up_axis))


def agent_xform_op(agent: Agent, motion: np.ndarray, shot_parent: np.ndarray | None = None) -> np.ndarray:
    """(F,4,4) values of the transform op prepended to the agent prim's xformOpOrder.

    The prepended op ``O`` makes the agent's local matrix ``local @ O``; with the parent's
    world matrix ``W`` the new world matrix is ``local @ O @ W``, which must equal
    ``local @ W @ M``: so ``O = W @ M @ W^-1``. A re-timed agent under a moving parent plays
    each frame at a shot time other than its source time: ``W`` is the parent's at the source
    time and ``shot_parent`` its own at the shot time, so ``O = W @ M @ shot_parent^-1``.
    """
    w = agent.agent_parent_to_world
    return w @ motion @ np.linalg.inv(w if shot_parent is None else shot_parent)


def xform_ops(op: np.ndarray, up_axis: str) -> list[tuple[str, np.ndarray]]:
    """The transform op values of :func:`agent_xform_op` as the fewest USD ops that make them,
    outermost first: ``("translate", (T,3))`` then ``("rotateY" or "rotateZ", (T,) degrees)``
    where each op turns about the up axis alone (an edit's turn in an upright parent: a quarter
    of a matrix's bytes, and values an artist can read; the angles unwrapped, continuous from
    sample to sample), else ``[("transform", (T,4,4))]``."""
    op = np.asarray(op, dtype=np.float64)
    rot = op[:, :3, :3]
    up = ground.up_index(up_axis)
    axis = np.zeros(3)
    axis[up] = 1.0
    upright = (np.abs(rot[:, up, :] - axis).max(initial=0.0) < 1e-12
               and np.abs(rot[:, :, up] - axis).max(initial=0.0) < 1e-12
               and np.abs(op[:, :3, 3]).max(initial=0.0) < 1e-12 and np.abs(op[:, 3, 3] - 1.0).max(initial=0.0) < 1e-12
               and np.abs(rot @ rot.transpose(0, 2, 1) - np.eye(3)).max(initial=0.0) < 1e-12)
    if not upright:
        return [("transform", op)]
    if up_axis.upper() == "Z":
        name, angle = "rotateZ", np.arctan2(rot[:, 0, 1], rot[:, 0, 0])
    else:
        name, angle = "rotateY", np.arctan2(-rot[:, 0, 2], rot[:, 0, 0])
    # Unwrapped: USD interpolates the angle linearly between samples, and a heading wrapped
    # from +180 to -180 degrees would turn the agent the long way round in between.
    return [("translate", op[:, 3, :3].copy()), (name, np.degrees(np.unwrap(angle)))]
