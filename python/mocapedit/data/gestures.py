"""Procedural upper-body gesture clips on the walker's skeleton, made to be layered.

``phone_call`` holds a phone to the right ear and talks with the left hand: a clip of the
joints from ``Spine`` down only (a partial joint set), looping seamlessly, whose rotations
are meant as additive deltas from the skeleton's rest pose (``referencePose = restPose``):
laid over a walk it lifts the arm to the ear while the walk's sway and arm swing go on.

Conventions are those of :mod:`mocapedit.data.walker`: Y-up metres (or Z-up with the turn
folded into the root, which a layer below ``Root`` does not see), quaternions (x, y, z, w),
bones along their local -Y, the character facing +Z with its left on +X. numpy only.
"""
from __future__ import annotations

import numpy as np

from mocapedit.data import walker

__all__ = ["phone_call", "UPPER_BODY_ROOT"]

#: The joint at the top of the gesture clips' joint set (a bare name of the walker skeleton).
UPPER_BODY_ROOT = "Spine"


def _rot(axis: str, angle: np.ndarray) -> np.ndarray:
    """(N,3,3) column-vector rotations about x, y or z."""
    a = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    rows = {"x": [[o, z, z], [z, c, -s], [z, s, c]],
            "y": [[c, z, s], [z, o, z], [-s, z, c]],
            "z": [[c, -s, z], [s, c, z], [z, z, o]]}[axis]
    return np.stack([np.stack(r, -1) for r in rows], -2)


def phone_call(frames: int = 96, fps: float = 24.0, up: str = "Y", meters_per_unit: float = 1.0,
               period: float = 4.0, name: str = "phone_call") -> walker.Clip:
    """A talking-on-the-phone upper body, looping every ``period`` seconds.

    Args:
        frames: number of samples F; with ``frames = period * fps`` the clip loops without
            a seam (every motion is a whole number of cycles over the clip).
        fps: samples per second.
        up, meters_per_unit: as for the walker (they only scale the rest translations).
        period: length of one gesture cycle, seconds.
        name: clip name.

    Returns:
        A :class:`mocapedit.data.walker.Clip` of the ``Spine`` subtree of the walker skeleton
        (joint paths as in the walker, ``Spine`` a root of this clip), rotations relative
        to the rest pose, translations at rest.
    """
    if frames < 1 or not fps > 0 or not period > 0:
        raise ValueError("frames, fps and period must be positive")
    full = walker.idle(frames=1, fps=fps, up=up, meters_per_unit=meters_per_unit)
    top = full.joint_index(UPPER_BODY_ROOT)
    keep = [i for i, j in enumerate(full.joints)
            if j == full.joints[top] or j.startswith(full.joints[top] + "/")]
    joints = [full.joints[i] for i in keep]
    index = {j.rsplit("/", 1)[-1]: k for k, j in enumerate(joints)}
    parents = np.array([keep.index(int(full.parents[i])) if int(full.parents[i]) in keep else -1
                        for i in keep], dtype=np.int32)

    t = np.arange(frames) / fps
    phase = 2 * np.pi * t / period
    talk = np.sin(2 * phase) + 0.4 * np.sin(5 * phase + 0.7)   # the free hand's beat
    nod = 0.05 * np.sin(3 * phase + 0.3)
    local = np.broadcast_to(np.eye(3), (frames, len(joints), 3, 3)).copy()

    # Lean the head towards the phone and nod while talking; turn the chest a little.
    local[:, index["Chest"]] = _rot("y", 0.06 * np.sin(phase)) @ _rot("z", np.full(frames, -0.03))
    local[:, index["Neck"]] = _rot("z", np.full(frames, -0.08)) @ _rot("x", 0.5 * nod)
    local[:, index["Head"]] = _rot("z", np.full(frames, -0.12)) @ _rot("x", nod)
    # Right hand at the ear: the upper arm out and forward, the elbow folded, the hand
    # turned so the phone lies along the cheek.
    local[:, index["RightArm"]] = (_rot("z", np.full(frames, 0.2)) @ _rot("x", -1.1 + 0.03 * np.sin(phase))
                                   @ _rot("y", np.full(frames, 0.8)))
    local[:, index["RightForeArm"]] = _rot("x", np.full(frames, -2.6))
    local[:, index["RightHand"]] = _rot("z", np.full(frames, 0.3))
    # Left hand talking: forearm raised, beating in time with the speech.
    local[:, index["LeftArm"]] = _rot("z", 0.12 + 0.04 * talk) @ _rot("x", -0.15 - 0.05 * talk)
    local[:, index["LeftForeArm"]] = _rot("x", -1.1 - 0.25 * talk) @ _rot("y", -0.4 + 0.1 * talk)
    local[:, index["LeftHand"]] = _rot("x", 0.2 * talk)

    translations = np.broadcast_to(full.rest_translations[keep], (frames, len(joints), 3)).copy()
    rotations = walker.quat_from_matrix(local).astype(np.float32)
    return walker.Clip(
        name=name, joints=joints, parents=parents,
        rest_translations=full.rest_translations[keep].copy(),
        rest_rotations=full.rest_rotations[keep].copy(),
        translations=translations.astype(np.float32), rotations=rotations, fps=float(fps),
        up_axis=up, meters_per_unit=float(meters_per_unit))
