"""Names: valid, unique USD identifiers from arbitrary names (joint names, prim paths), and
joints found by path, bare name, or what their name says (foot, hips)."""
from __future__ import annotations

import re
from typing import Sequence

_NOT_IDENTIFIER = re.compile(r"[^A-Za-z0-9_]")


def unique_identifier(text: str, taken: set[str], fallback: str) -> str:
    """A USD identifier for ``text``, not in ``taken`` (and added to it).

    Characters outside ``[A-Za-z0-9_]`` become ``_``, a leading digit gets a ``_`` in front,
    an empty result becomes ``fallback``, and a name already taken gets ``_2``, ``_3``, ...
    """
    base = _NOT_IDENTIFIER.sub("_", text) or fallback
    if base[0].isdigit():
        base = "_" + base
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    taken.add(name)
    return name


def joint_leaf(joint_path: str) -> str:
    """The joint's own name: the last element of its joint path."""
    return joint_path.rsplit("/", 1)[-1]


def resolve_joint(joints: list[str], name: str) -> int | None:
    """Index of a joint given as a full joint path or as a bare name that is unique."""
    if name in joints:
        return joints.index(name)
    matches = [i for i, j in enumerate(joints) if joint_leaf(j) == name]
    return matches[0] if len(matches) == 1 else None


_FOOT_WORDS = ("foot", "toe", "ankle")
_NOT_FOOT_WORDS = ("end", "site")


def default_foot_joints(joints: Sequence[str]) -> list[int]:
    """Indices of the joints whose own name says foot, toe or ankle (not an end site)."""
    out = []
    for k, j in enumerate(joints):
        leaf = joint_leaf(str(j)).lower()
        if any(w in leaf for w in _FOOT_WORDS) and not any(w in leaf for w in _NOT_FOOT_WORDS):
            out.append(k)
    return out


_FACING_NAMES = ("hips", "hip", "pelvis")


def default_facing_joint(joints: Sequence[str]) -> int:
    """Index of the joint whose frame stands for the body's facing: the one named hips, hip or
    pelvis (leaf name, any case), else the first joint whose leaf name contains one of those
    words without naming a leg, else the skeleton's root (0)."""
    leaves = [joint_leaf(str(j)).lower() for j in joints]
    for k, leaf in enumerate(leaves):
        if leaf in _FACING_NAMES:
            return k
    for k, leaf in enumerate(leaves):
        if any(w in leaf for w in ("hip", "pelvis")) and not any(w in leaf for w in ("leg", "thigh", "up", "left", "right")):
            return k
    return 0
