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


# What a leg joint's name says it is, once split into words with its side word taken out
# (``mixamorig_LeftUpLeg`` -> left, "upleg"; ``thigh_l`` -> left, "thigh"; ``Bip01_L_Toe0`` ->
# left, "toe"): the words of hip, knee, ankle and toe on CMU, Mixamo, HumanIK, Character
# Creator, Unreal, 3ds Max Biped, Xsens, Rokoko, OptiTrack, SMPL and Rigify rigs. A name may
# also end in one of them after a prefix (``DEF_thigh_L``). SMPL's "foot" is the toe end below
# its "ankle".
_ROLE_WORDS = {
    "hip": ("upleg", "upperleg", "thigh", "hip"),
    "knee": ("lowerleg", "leg", "calf", "shin", "knee"),
    "ankle": ("foot", "ankle"),
    "toe": ("toebase", "toes", "toe", "ball"),
}
_SIDE_WORDS = {"left": "left", "l": "left", "right": "right", "r": "right"}
_WORD = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|[0-9]+")


def side_and_role(leaf: str, prefixed: bool = True) -> tuple[str | None, str | None]:
    """(side, role) a joint's leaf name says ("left"/"right"; "hip", "knee", "ankle", "toe"), or
    None for what it does not say. ``prefixed``: also a role word after a prefix (``DEF_thigh_L``)."""
    words = [w.lower() for w in _WORD.findall(leaf) if not w.isdigit()]
    sides = [k for k, w in enumerate(words) if w in _SIDE_WORDS]
    if len(sides) != 1:
        return None, None
    k = sides[0]
    rest = "".join(words[k + 1:]) or "".join(words[:k])
    exact = [role for role, names in _ROLE_WORDS.items() if rest in names]
    if exact:
        return _SIDE_WORDS[words[k]], exact[0]
    if not prefixed:
        return _SIDE_WORDS[words[k]], None
    # A prefix before the role (DEF_thigh_L): the longest role word the name ends with.
    ends = sorted(((len(n), role) for role, names in _ROLE_WORDS.items() for n in names if rest.endswith(n)),
                  reverse=True)
    return _SIDE_WORDS[words[k]], (ends[0][1] if ends else None)


_FOOT_WORDS = ("foot", "toe", "ankle")
_NOT_FOOT_WORDS = ("end", "site")


def default_foot_joints(joints: Sequence[str]) -> list[int]:
    """Indices of the joints whose own name says foot, toe or ankle (not an end site), or is
    a side's ankle or toe by another word (``ball_l``)."""
    out = []
    for k, j in enumerate(joints):
        leaf = joint_leaf(str(j))
        low = leaf.lower()
        if any(w in low for w in _FOOT_WORDS) and not any(w in low for w in _NOT_FOOT_WORDS) or \
                side_and_role(leaf, prefixed=False)[1] in ("ankle", "toe"):
            out.append(k)
    return out


_FACING_NAMES = ("hips", "hip", "pelvis")


def hips_joint(joints: Sequence[str], skip: int | None = None) -> int | None:
    """Index of the joint named for the hips: the one named hips, hip or pelvis (leaf name, any
    case), else the first whose leaf name contains one of those words and names no side or leg
    (not ``LHipJoint``, ``thigh_l``); None when there is none. ``skip``: a joint not to take."""
    leaves = [joint_leaf(str(j)) for j in joints]
    for k, leaf in enumerate(leaves):
        if k != skip and leaf.lower() in _FACING_NAMES:
            return k
    for k, leaf in enumerate(leaves):
        low = leaf.lower()
        if k != skip and any(w in low for w in ("hip", "pelvis")) and \
                not any(w in low for w in ("leg", "thigh", "up")) and side_and_role(leaf)[0] is None:
            return k
    return None


def default_facing_joint(joints: Sequence[str]) -> int:
    """Index of the joint whose frame stands for the body's facing: :func:`hips_joint`, else the
    skeleton's root (0)."""
    k = hips_joint(joints)
    return 0 if k is None else k
