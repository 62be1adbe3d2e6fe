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
    "hip": ("upleg", "upperleg", "thigh", "hip", "femur"),
    "knee": ("lowerleg", "leg", "calf", "shin", "knee", "tibia"),
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
    if len(sides) > 1:
        return None, None
    if sides:
        k = sides[0]
        side, rest = _SIDE_WORDS[words[k]], "".join(words[k + 1:]) or "".join(words[:k])
    else:
        side, rest = _side_in_one_word("".join(words))
        if side is None:
            return None, None
    exact = _role_of(rest)
    if exact or not prefixed:
        return side, exact
    # A prefix before the role (DEF_thigh_L): the longest role word the name ends with.
    ends = sorted(((len(n), role) for role, names in _ROLE_WORDS.items() for n in names if rest.endswith(n)),
                  reverse=True)
    return side, (ends[0][1] if ends else None)


def _role_of(word: str) -> str | None:
    return next((role for role, names in _ROLE_WORDS.items() if word in names), None)


def _side_in_one_word(word: str) -> tuple[str | None, str]:
    """(side, the rest) of a name written in one case without separators (``leftupleg``,
    ``LEFTFOOT``, CMU's ``lfemur``): "left" or "right" at its start or end, or "l" or "r" in front
    of a role word."""
    for name in ("left", "right"):
        if len(word) > len(name) and word.startswith(name):
            return name, word[len(name):]
        if len(word) > len(name) and word.endswith(name):
            return name, word[:-len(name)]
    if len(word) > 1 and word[0] in "lr" and _role_of(word[1:]):
        return _SIDE_WORDS[word[0]], word[1:]
    return None, word


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
    (not ``LHipJoint``, CMU's ``lhipjoint``, ``thigh_l``); None when there is none. ``skip``: a joint not to take."""
    leaves = [joint_leaf(str(j)) for j in joints]
    for k, leaf in enumerate(leaves):
        if k != skip and leaf.lower() in _FACING_NAMES:
            return k
    for k, leaf in enumerate(leaves):
        low = leaf.lower()
        if k != skip and any(w in low for w in ("hip", "pelvis")) and \
                not any(w in low for w in ("leg", "thigh", "up")) and side_and_role(leaf)[0] is None \
                and not re.match(r"[lr](?:hip|pelvis)", low):
            return k
    return None


def default_facing_joint(joints: Sequence[str]) -> int:
    """Index of the joint whose frame stands for the body's facing: :func:`hips_joint`, else the
    skeleton's root (0)."""
    k = hips_joint(joints)
    return 0 if k is None else k
