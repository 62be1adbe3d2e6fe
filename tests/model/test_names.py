"""Tests for mocapedit.model.names: identifiers and joints found by name."""
from __future__ import annotations

from mocapedit.model import names

JOINTS = ["Hips", "Hips/LeftUpLeg", "Hips/LeftUpLeg/LeftFoot", "Hips/RightUpLeg", "Hips/RightUpLeg/RightFoot",
          "Hips/Spine", "Hips/Spine/Neck/Head", "Hips/Spine/Neck2/Head"]


def test_a_joint_is_found_by_path_or_by_a_unique_bare_name():
    assert names.joint_leaf("Hips/LeftUpLeg/LeftFoot") == "LeftFoot"
    assert names.joint_leaf("Hips") == "Hips"
    assert names.resolve_joint(JOINTS, "Hips/Spine") == 5
    assert names.resolve_joint(JOINTS, "RightFoot") == 4
    assert names.resolve_joint(JOINTS, "Head") is None          # two joints are named Head
    assert names.resolve_joint(JOINTS, "Hips/Spine/Neck2/Head") == 7
    assert names.resolve_joint(JOINTS, "Tail") is None


def test_unique_identifier():
    taken: set[str] = set()
    assert names.unique_identifier("/World/Crowd/a-1", taken, "agent") == "_World_Crowd_a_1"
    assert names.unique_identifier("/World/Crowd/a-1", taken, "agent") == "_World_Crowd_a_1_2"
    assert names.unique_identifier("7up", taken, "agent") == "_7up"
    assert names.unique_identifier("", taken, "agent") == "agent"
