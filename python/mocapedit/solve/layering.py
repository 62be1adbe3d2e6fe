"""Animation layering (chapter 7 of the deliverable), the numpy side of the C++ job.

A layer puts the joints of a subtree of another clip (the layer clip) over an agent's own
animation, in each joint's local space:

- **blend** interpolates from the pose below to the layer clip's local transforms by the
  weight: translations and scales linearly, rotations by normalised shortest-arc slerp;
- **additive** adds the layer clip's difference from its reference pose (its first frame
  or the skeleton's rest pose) on top, scaled by the weight: ``t + w * (layer - reference)``,
  ``slerp(identity, delta, w) * rotation`` with ``delta = layer * inverse(reference)``,
  ``scale * (1 + w * (layer / reference - 1))``.

Layers of one agent stack in stage order, each on the result of the ones before. The
deltas are made once per clip and reference by the offline builder
(``_solver.build_additive_clip``); poses are layered by the runtime job
(``_solver.apply_layers``). This module matches joints, samples layer clips and weight
curves at output times, and holds :func:`apply_layers_numpy`, a vectorised numpy version of
the job used as its peer in the benchmark and as an independent check in the tests.

Quaternions are ``(x, y, z, w)``; ``a * b`` is the Hamilton product (rotate by ``b``, then
by ``a``). Matrices follow USD's row-vector convention (see :mod:`mocapedit.geometry.kinematics`).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import animation
from mocapedit.geometry.animation import Pose
from mocapedit.geometry.kinematics import quat_multiply
from mocapedit.model.errors import prim_error
from mocapedit.model.data import CHANNELS, Agent, AnimationLayer, Clip
from mocapedit.model.names import joint_leaf, resolve_joint

#: A pose as the job takes it: (translations (T,J,3), rotations (T,J,4), scales (T,J,3)).
PoseArrays = tuple[np.ndarray, np.ndarray, np.ndarray]


def match_joints(layer_joints: list[str], skeleton_joints: list[str]) -> np.ndarray:
    """(K,) skeleton index of each layer clip joint, -1 where it has none.

    A joint matches by its full joint path, or else by its bare name when that name is
    unique among both the layer clip's and the skeleton's joints (clips made on a skeleton
    rooted elsewhere). No skeleton joint is matched twice; a full path wins.
    """
    index = {j: i for i, j in enumerate(skeleton_joints)}
    skel_leaves = Counter(joint_leaf(j) for j in skeleton_joints)
    by_leaf = {joint_leaf(j): i for i, j in enumerate(skeleton_joints) if skel_leaves[joint_leaf(j)] == 1}
    layer_leaves = Counter(joint_leaf(j) for j in layer_joints)
    exact = {index[j] for j in layer_joints if j in index}
    out = np.full(len(layer_joints), -1, dtype=np.int64)
    for k, name in enumerate(layer_joints):
        if name in index:
            out[k] = index[name]
        elif layer_leaves[joint_leaf(name)] == 1 and by_leaf.get(joint_leaf(name), -1) not in exact | {-1}:
            out[k] = by_leaf[joint_leaf(name)]
    return out


def trs_from_matrices(m: np.ndarray) -> PoseArrays:
    """(...,4,4) row-vector matrices -> translations (...,3), rotations (...,4), scales (...,3),
    float32, such that ``kinematics.compose_trs`` gives the matrices back (no shear)."""
    m = np.asarray(m, dtype=np.float64)
    t = m[..., 3, :3]
    rs = m[..., :3, :3]                           # rows: scale_i * rotation row i
    s = np.linalg.norm(rs, axis=-1)
    r = rs / s[..., :, None]
    flip = np.linalg.det(r) < 0                   # a mirror: carry it in one scale
    s[..., 0] = np.where(flip, -s[..., 0], s[..., 0])
    r[..., 0, :] = np.where(flip[..., None], -r[..., 0, :], r[..., 0, :])
    c = np.swapaxes(r, -1, -2)                    # column-vector rotation
    tr = c[..., 0, 0] + c[..., 1, 1] + c[..., 2, 2]
    cand = np.stack([1 + 2 * c[..., 0, 0] - tr, 1 + 2 * c[..., 1, 1] - tr, 1 + 2 * c[..., 2, 2] - tr, 1 + tr], -1)
    k = np.argmax(cand, axis=-1)[..., None]
    big = 0.5 * np.sqrt(np.maximum(np.take_along_axis(cand, k, -1)[..., 0], 1e-300))
    f = 0.25 / big
    options = np.stack([
        np.stack([big, (c[..., 0, 1] + c[..., 1, 0]) * f, (c[..., 0, 2] + c[..., 2, 0]) * f,
                  (c[..., 2, 1] - c[..., 1, 2]) * f], -1),
        np.stack([(c[..., 0, 1] + c[..., 1, 0]) * f, big, (c[..., 1, 2] + c[..., 2, 1]) * f,
                  (c[..., 0, 2] - c[..., 2, 0]) * f], -1),
        np.stack([(c[..., 0, 2] + c[..., 2, 0]) * f, (c[..., 1, 2] + c[..., 2, 1]) * f, big,
                  (c[..., 1, 0] - c[..., 0, 1]) * f], -1),
        np.stack([(c[..., 2, 1] - c[..., 1, 2]) * f, (c[..., 0, 2] - c[..., 2, 0]) * f,
                  (c[..., 1, 0] - c[..., 0, 1]) * f, big], -1),
    ], -2)
    q = np.take_along_axis(options, k[..., None], -2)[..., 0, :]
    q = np.where(q[..., 3:] < 0, -q, q)
    return t.astype(np.float32), q.astype(np.float32), s.astype(np.float32)


def apply_layers_numpy(source: PoseArrays, layers: list) -> PoseArrays:
    """The layering job in vectorised numpy (float64 trigonometric slerp): same arguments
    and results as ``_solver.apply_layers``, to within float rounding."""
    t, r, s = (np.array(a, dtype=np.float64) for a in source)
    for mode, (lt, lr, ls), weights, joint_weights in layers:
        w = np.asarray(weights, dtype=np.float64)[:, None]
        if joint_weights is not None:
            w = w * np.asarray(joint_weights, dtype=np.float64)[None, :]
        w = np.broadcast_to(w, t.shape[:2])
        on = w > 0
        w3 = w[..., None]
        if mode == "blend":
            t = np.where(on[..., None], (1 - w3) * t + w3 * lt, t)
            s = np.where(on[..., None], (1 - w3) * s + w3 * ls, s)
            r = np.where(on[..., None], animation.slerp(r, lr, w), r)
        else:
            t = t + w3 * lt
            s = s * (1 + w3 * (ls - 1))
            identity = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), r.shape)
            r = np.where(on[..., None], quat_multiply(animation.slerp(identity, lr, w), r), r)
    return t.astype(np.float32), r.astype(np.float32), s.astype(np.float32)


def additive_clip(clip: Clip, reference: PoseArrays) -> Clip:
    """The clip's deltas from a reference pose (J,...) in the clip's joint order."""
    t, r, s = _solver.build_additive_clip(reference, (clip.translations, clip.rotations, clip.scales))
    return Clip(key=("additive",) + tuple(clip.key), source=f"{clip.source} (additive)",
                joints=list(clip.joints), times=clip.times, translations=t, rotations=r, scales=s,
                channels=clip.channels)


def layer_frames(layer: AnimationLayer, clip: Clip, times: np.ndarray) -> tuple[np.ndarray, bool]:
    """(fractional layer clip frame at each shot time, looped?).

    At shot time ``t`` the layer clip plays its own (composed) time ``t - timeOffset``. With
    ``wrap = loop`` a clip of F frames repeats every F frame intervals, its last frame
    interpolating back to its first; with ``clamp`` it holds its first and last frames.
    """
    sample_times = layer.sample_times if layer.sample_times is not None else clip.times
    n = len(sample_times)
    u = np.asarray(times, dtype=np.float64) - layer.time_offset
    if n == 1:
        return np.zeros(len(u)), False
    index = np.arange(n, dtype=np.float64)
    if layer.wrap == "clamp":
        return np.interp(u, sample_times, index), False
    first, last = float(sample_times[0]), float(sample_times[-1])
    step = (last - first) / (n - 1)
    v = first + np.mod(u - first, last - first + step)
    return np.where(v <= last, np.interp(v, sample_times, index), (n - 1) + (v - last) / step), True


def layer_weights(layer: AnimationLayer, times: np.ndarray) -> np.ndarray:
    """(T,) float32 weight at each shot time: linear between time samples, held outside."""
    if layer.weight_times.size:
        w = np.interp(times, layer.weight_times, layer.weight_values)
    else:
        w = np.full(len(times), float(layer.weight_values[0]))
    return np.clip(w, 0.0, 1.0).astype(np.float32)


@dataclass
class PreparedLayer:
    """One layer made ready for one skeleton and source joint order."""
    layer: AnimationLayer
    clip: Clip                  # the layer clip, or its deltas (additive)
    clip_columns: np.ndarray    # (K,) layer clip joint of each layered joint
    pose_columns: np.ndarray    # (K,) its column in the (extended) source pose
    joint_name: str             # the subtree's top joint, for reports
    #: (joint, its parent in the layer clip or None, its parent in the skeleton or None) of the
    #: top blended joint whose parents differ by bare name, for reports; None when none does
    rehung: tuple | None = None
    _samples: dict = field(default_factory=dict, repr=False)

    @property
    def missing(self) -> tuple[str, ...]:
        """The channels the layer clip does not author: they stay as the pose below has them
        (blend), and add nothing (additive)."""
        return tuple(c for c in CHANNELS if c not in self.clip.channels)

    def describe(self) -> str:
        """What the layer does, for the report."""
        text = f"{self.layer.mode} on {len(self.pose_columns)} joints from {self.joint_name}"
        if self.missing:
            keeps = "stay as below" if self.layer.mode == "blend" else "get nothing added"
            text += (f"; the clip authors {' and '.join(c for c in CHANNELS if c not in self.missing)} only: "
                     f"{' and '.join(self.missing)} {keeps}")
        if self.rehung is not None:
            joint, in_clip, here = self.rehung
            text += (f"; '{joint}' hangs from {repr(in_clip) if in_clip else 'nothing'} in the layer's clip but from "
                     f"{repr(here) if here else 'nothing'} here: its transform is taken as it is (a clip of a rig "
                     f"rooted elsewhere puts the body elsewhere; layer below that joint)")
        return text

    def sample(self, times: np.ndarray, width: int) -> tuple[PoseArrays, np.ndarray, np.ndarray]:
        """(layer transforms (T,width,...), weights (T,), joint weights (width,)) for the job;
        agents layered at the same shot times share them."""
        key = (times.tobytes(), width)
        hit = self._samples.get(key)
        if hit is None:
            hit = self._samples[key] = self._sample(times, width)
        return hit

    def _sample(self, times: np.ndarray, width: int) -> tuple[PoseArrays, np.ndarray, np.ndarray]:
        frames, loop = layer_frames(self.layer, self.clip, times)
        sampled = animation.sample_pose(self.clip, frames, loop)
        count = len(times)
        t = np.zeros((count, width, 3), np.float32)
        r = np.zeros((count, width, 4), np.float32)
        r[..., 3] = 1.0
        s = np.ones((count, width, 3), np.float32)
        t[:, self.pose_columns] = sampled.translations[:, self.clip_columns]
        r[:, self.pose_columns] = sampled.rotations[:, self.clip_columns]
        s[:, self.pose_columns] = sampled.scales[:, self.clip_columns]
        joint_weights = np.zeros(width, np.float32)
        joint_weights[self.pose_columns] = 1.0
        return (t, r, s), layer_weights(self.layer, times), joint_weights


class AgentLayers:
    """The layers of one agent (in stacking order) for poses of its source clip.

    ``extra_joints`` are skeleton joints the layers touch but the source clip does not
    animate: the layered pose appends them, starting from their rest transforms.
    """

    def __init__(self, source_joints: list[str], extra_joints: list[str], extra_rest: PoseArrays,
                 layers: list[PreparedLayer]):
        self.joints = list(source_joints) + list(extra_joints)
        self.extra_rest = extra_rest
        self.layers = layers
        self._memo: dict[bytes, tuple[Pose, Pose]] = {}

    def extend(self, pose: Pose) -> PoseArrays:
        """The pose's arrays with the extra joints appended at their rest transforms."""
        if not len(self.joints) > len(pose.joints):
            return pose.translations, pose.rotations, pose.scales
        count = pose.translations.shape[0]
        return tuple(np.concatenate([a, np.broadcast_to(rest, (count,) + rest.shape)], axis=1)
                     for a, rest in zip((pose.translations, pose.rotations, pose.scales), self.extra_rest))

    def apply(self, pose: Pose, times: np.ndarray) -> Pose:
        """The layered pose at shot times ``times`` (T,); the same inputs give the same object."""
        times = np.asarray(times, dtype=np.float64)
        key = times.tobytes()
        hit = self._memo.get(key)
        if hit is not None and (hit[0] is pose or all(np.array_equal(a, b) for a, b in zip(
                (hit[0].translations, hit[0].rotations, hit[0].scales),
                (pose.translations, pose.rotations, pose.scales)))):
            return hit[1]
        arrays = self.extend(pose)
        # Layers run in one job, except that a layer missing some channels runs alone and
        # its joints get those channels back from the pose below it.
        batch: list = []
        for p in self.layers + [None]:
            if batch and (p is None or p.missing):
                arrays = _solver.apply_layers(arrays, [(q.layer.mode,) + q.sample(times, len(self.joints))
                                                       for q in batch])
                batch = []
            if p is not None and p.missing:
                below = arrays
                arrays = tuple(np.array(a) for a in _solver.apply_layers(
                    arrays, [(p.layer.mode,) + p.sample(times, len(self.joints))]))
                for channel in p.missing:
                    k = CHANNELS.index(channel)
                    arrays[k][:, p.pose_columns] = below[k][:, p.pose_columns]
            elif p is not None:
                batch.append(p)
        t, r, s = arrays
        out = Pose(joints=list(self.joints), translations=t, rotations=r, scales=s)
        self._memo[key] = (pose, out)
        return out

    def changes(self, pose: Pose, times: np.ndarray) -> bool:
        """Whether layering changes this pose at all (bit for bit)."""
        out = self.apply(pose, times)
        return not all(np.array_equal(a, b) for a, b in zip(
            self.extend(pose), (out.translations, out.rotations, out.scales)))


def check_weights(layer: AnimationLayer) -> None:
    """Raises a MocapEditError naming the layer prim unless every weight is within [0, 1]."""
    for i, value in enumerate(np.asarray(layer.weight_values, dtype=np.float64)):
        if not 0.0 <= value <= 1.0:
            when = f" at time {layer.weight_times[i]:g}" if layer.weight_times.size else ""
            raise prim_error(layer.path, f"weight must be within [0, 1], got {value:g}{when}", "weight")


def _reference_pose(layer: AnimationLayer, clip: Clip, agent: Agent, skel_of: np.ndarray):
    """(cache key, reference pose (J,...) in the layer clip's joint order) of an additive layer."""
    if layer.reference_pose == "firstFrame":
        return (clip.key, "firstFrame"), (clip.translations[0], clip.rotations[0], clip.scales[0])
    rest = trs_from_matrices(agent.rest_transforms)
    have = skel_of >= 0
    reference = (np.zeros((len(clip.joints), 3), np.float32),
                 np.tile(np.array([0, 0, 0, 1], np.float32), (len(clip.joints), 1)),
                 np.ones((len(clip.joints), 3), np.float32))
    for target, values in zip(reference, rest):
        target[have] = values[skel_of[have]]
    return (clip.key, "restPose", tuple(agent.joints), agent.rest_transforms.tobytes()), reference


def resolve_layer(agent: Agent, layer: AnimationLayer, clip: Clip) -> tuple[int, np.ndarray]:
    """(skeleton index of the layer's top joint or -1 for the whole skeleton, skeleton index
    of each layer clip joint or -1) for one agent.

    Raises:
      MocapEditError naming the layer prim: a ``joint`` not in the skeleton (or a bare name
      that is not unique), a layer clip that shares no joint with the skeleton.
    """
    root = -1
    if layer.joint:
        found = resolve_joint(agent.joints, layer.joint)
        if found is None:
            same = [j for j in agent.joints if joint_leaf(j) == layer.joint]
            why = (f"the bare name '{layer.joint}' is not unique ({', '.join(same)}): give its joint path"
                   if len(same) > 1 else f"joint '{layer.joint}' is not in the skeleton")
            raise prim_error(layer.path, f"{why} <{agent.skeleton_path}> of agent <{agent.path}>", "joint")
        root = int(found)
    skel_of = match_joints(clip.joints, agent.joints)
    if not np.any(skel_of >= 0):
        raise prim_error(layer.path, f"layer clip <{layer.animation}> shares no joint with the skeleton "
                         f"<{agent.skeleton_path}> of agent <{agent.path}> (it animates "
                         f"{', '.join(clip.joints[:3])}{', ...' if len(clip.joints) > 3 else ''})",
                         "animation")
    return root, skel_of


def _rehung(agent: Agent, clip: Clip, skel_of: np.ndarray, used: np.ndarray) -> tuple | None:
    """(joint, parent in the clip, parent in the skeleton), bare names, of the top blended joint
    (fewest ancestors in the clip) whose parent differs between the two; None if none does."""
    bare = lambda path: path.rsplit("/", 1)[-1] if path else None  # noqa: E731
    for k in sorted(used.tolist(), key=lambda k: clip.joints[k].count("/")):
        path = clip.joints[k]
        in_clip = bare(path.rsplit("/", 1)[0]) if "/" in path else None
        p = int(agent.parents[int(skel_of[k])])
        here = bare(agent.joints[p]) if p >= 0 else None
        if in_clip != here:
            return bare(path), in_clip, here
    return None


def plan_agent(agent: Agent, source: Clip, layers: list[tuple[AnimationLayer, Clip]],
               delta_cache: dict) -> AgentLayers:
    """The layers of one agent, in stacking order, made ready for poses of its source clip.

    Args:
      agent: the agent; its skeleton gives the joint names, parents and rest pose.
      source: the agent's source clip (the pose's joint order).
      layers: (layer, layer clip) pairs in stage order.
      delta_cache: shared across agents: additive clips by (clip, reference pose).

    Raises:
      MocapEditError naming the layer prim: a ``joint`` not in the skeleton (or a bare name
      that is not unique), a layer clip that shares no joint with the skeleton.
    """
    pose_column = {int(s): a for a, s in enumerate(agent.anim_to_skel) if s >= 0}
    parents = [int(p) for p in agent.parents]
    resolved = []
    for layer, clip in layers:
        root, skel_of = resolve_layer(agent, layer, clip)
        subtree = _solver.subtree_joint_weights(parents, root)
        used = np.flatnonzero((skel_of >= 0) & (subtree[np.maximum(skel_of, 0)] > 0))
        resolved.append((layer, clip, root, skel_of, used))
    extra = sorted({int(skel_of[k]) for *_, skel_of, used in resolved for k in used} - set(pose_column))
    for i, s in enumerate(extra):
        pose_column[s] = len(source.joints) + i
    prepared = []
    for layer, clip, root, skel_of, used in resolved:
        data = clip
        if layer.mode == "additive":
            key, reference = _reference_pose(layer, clip, agent, skel_of)
            data = delta_cache.get(key)
            if data is None:
                data = delta_cache[key] = additive_clip(clip, reference)
        prepared.append(PreparedLayer(
            layer=layer, clip=data, clip_columns=used,
            pose_columns=np.array([pose_column[int(skel_of[k])] for k in used], dtype=np.int64),
            joint_name=agent.joints[root] if root >= 0 else "(whole skeleton)",
            rehung=_rehung(agent, clip, skel_of, used) if layer.mode == "blend" else None))
    return AgentLayers(source.joints, [agent.joints[s] for s in extra],
                       trs_from_matrices(agent.rest_transforms[extra]), prepared)
