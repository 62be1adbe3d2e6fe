"""Foot contacts and foot locking: legs by name, detection, the solver's job against numpy,
and the locked feet measured on the composed stage by UsdSkel forward kinematics."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from mocapedit.geometry import contacts
from mocapedit.data import examples, walker
from mocapedit.solve import footlock, footplant
from mocapedit.inspect import metrics
from mocapedit.tools import measure
from mocapedit.usd import evaluate
from mocapedit.model.errors import MocapEditError
from mocapedit.model.report import foot_locking_lines
from mocapedit.solve.layering import trs_from_matrices
from mocapedit.pipeline.processor import solve

from conftest import run_cli

CROWD = "/World/Crowd"
FPS = 24.0
MOCAP = Path(__file__).resolve().parents[2] / ".." / "shared" / "mocap"


@pytest.fixture(scope="module")
def walk_clip():
    return walker.walk(frames=193, fps=FPS, speed=1.25, name="ten_metres")


def _bent_path_stage(tmp_path, clip, **kw):
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips", **kw)
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/middle", a, 96, (1.5, 0.0, 5.0))
    examples.add_position_constraint(stage, "/Edits/end", a, 192, (0.0, 0.0, 10.0))
    stage.GetRootLayer().Save()
    return stage, a


def _solve(tmp_path, name="out", **kw):
    edits, composed = tmp_path / f"{name}.edits.usda", tmp_path / f"{name}.usda"
    result = solve(str(tmp_path / "shot.usda"), output=str(edits), composed=str(composed), **kw)
    return result, Usd.Stage.Open(str(composed))


def _fk(stage, agent, times):
    """(world matrices (T,J,4,4), local matrices (T,J,4,4), joint names) by UsdSkel."""
    return evaluate.joint_transforms(stage, agent, times)


def _leg_quality(src, out, agent, times, leg_names, fps, unlocked=None, least=(0.0, 0.0, 0.0)):
    """(largest bone length change, knee flips, largest joint angular speed over the source's) of
    the legs on a composed stage. Knee sides are compared with ``unlocked`` (the same edit without
    foot locking, whose turns of the whole body are not flips), by default the source. ``least``:
    radians per second the hip, knee and ankle are allowed at least, however still the source
    holds them."""
    w0, l0, joints = _fk(src, agent, times)
    w1, l1, _ = _fk(out, agent, times)
    wr = w0 if unlocked is None else _fk(unlocked, agent, times)[0]
    index = [[next(i for i, j in enumerate(joints) if j.endswith("/" + n) or j == n) for n in leg] for leg in leg_names]
    bones, bend_flip, speed_ratio = 0.0, 0, 0.0
    for hip, knee, ankle in index:
        for a, b in ((hip, knee), (knee, ankle)):
            d0 = np.linalg.norm(w0[:, a, 3, :3] - w0[:, b, 3, :3], axis=-1)
            d1 = np.linalg.norm(w1[:, a, 3, :3] - w1[:, b, 3, :3], axis=-1)
            bones = max(bones, float(np.abs(d1 - d0).max()))
        # Wherever the source knee is clearly bent (sine of the bend over 0.05), the locked knee
        # bends to the same side: never backwards.
        bends = [np.cross(w[:, knee, 3, :3] - w[:, hip, 3, :3], w[:, ankle, 3, :3] - w[:, knee, 3, :3]) for w in (wr, w1)]
        lengths = np.linalg.norm(wr[:, knee, 3, :3] - wr[:, hip, 3, :3], axis=-1) * \
            np.linalg.norm(wr[:, ankle, 3, :3] - wr[:, knee, 3, :3], axis=-1)
        bent = np.linalg.norm(bends[0], axis=-1) > 0.05 * lengths
        bend_flip += int(np.sum(bent & (np.einsum("ti,ti->t", bends[0], bends[1]) <= 0)))
        for j, floor in zip((hip, knee, ankle), least):
            q0, q1 = trs_from_matrices(l0[:, j])[1], trs_from_matrices(l1[:, j])[1]
            speed = [2 * np.arccos(np.clip(np.abs(np.sum(q[1:] * q[:-1], -1)), 0, 1)) * fps for q in (q0, q1)]
            speed_ratio = max(speed_ratio, float(speed[1].max() / max(speed[0].max(), floor, 1e-9)))
    return bones, bend_flip, speed_ratio


# ---- legs and contacts -------------------------------------------------------------------------


@pytest.mark.parametrize("names, hip, toe", [
    (list(walker.JOINTS), "LeftUpLeg", "LeftToe"),
    (["Hips", "Hips/LHipJoint", "Hips/LHipJoint/LeftUpLeg", "Hips/LHipJoint/LeftUpLeg/LeftLeg",
      "Hips/LHipJoint/LeftUpLeg/LeftLeg/LeftFoot", "Hips/LHipJoint/LeftUpLeg/LeftLeg/LeftFoot/LeftToeBase",
      "Hips/RHipJoint", "Hips/RHipJoint/RightUpLeg", "Hips/RHipJoint/RightUpLeg/RightLeg",
      "Hips/RHipJoint/RightUpLeg/RightLeg/RightFoot"], "LeftUpLeg", "LeftToeBase"),
    (["R", "R/CC_Base_Hip", "R/CC_Base_Hip/CC_Base_Pelvis", "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_L_Thigh",
      "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_L_Thigh/CC_Base_L_Calf",
      "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_L_Thigh/CC_Base_L_ThighTwist01",
      "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_L_Thigh/CC_Base_L_Calf/CC_Base_L_Foot",
      "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_L_Thigh/CC_Base_L_Calf/CC_Base_L_Foot/CC_Base_L_ToeBase",
      "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_R_Thigh", "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_R_Thigh/CC_Base_R_Calf",
      "R/CC_Base_Hip/CC_Base_Pelvis/CC_Base_R_Thigh/CC_Base_R_Calf/CC_Base_R_Foot"], "CC_Base_L_Thigh",
     "CC_Base_L_ToeBase"),
    (["mixamorig:Hips", "mixamorig:Hips/mixamorig:LeftUpLeg", "mixamorig:Hips/mixamorig:LeftUpLeg/mixamorig:LeftLeg",
      "mixamorig:Hips/mixamorig:LeftUpLeg/mixamorig:LeftLeg/mixamorig:LeftFoot",
      "mixamorig:Hips/mixamorig:RightUpLeg", "mixamorig:Hips/mixamorig:RightUpLeg/mixamorig:RightLeg",
      "mixamorig:Hips/mixamorig:RightUpLeg/mixamorig:RightLeg/mixamorig:RightFoot"], "mixamorig:LeftUpLeg", None),
])
def test_legs_are_found_by_name_on_common_rigs(names, hip, toe):
    parents = np.array([-1 if "/" not in n else names.index(n.rsplit("/", 1)[0]) for n in names])
    legs = contacts.find_legs(names, parents)
    assert [leg.side for leg in legs] == ["left", "right"]
    left = legs[0]
    assert names[left.hip].rsplit("/", 1)[-1] == hip
    assert int(parents[left.knee]) == left.hip and int(parents[left.ankle]) == left.knee
    assert (names[left.toe].rsplit("/", 1)[-1] if left.toe is not None else None) == toe


def _rig(pelvis: str, left: list[str], right: list[str], extra: tuple = ()) -> tuple[list[str], np.ndarray]:
    """Joint paths of a pelvis with two leg chains (each joint the child of the one before) and
    ``extra`` (parent leaf, leaf) joints hung from a chain joint, and their parents."""
    names = [pelvis]
    for chain in (left, right):
        path = pelvis
        for leaf in chain:
            path = f"{path}/{leaf}"
            names.append(path)
    for parent, leaf in extra:
        names.append(next(n for n in names if n.rsplit("/", 1)[-1] == parent) + "/" + leaf)
    return names, np.array([-1 if "/" not in n else names.index(n.rsplit("/", 1)[0]) for n in names])


@pytest.mark.parametrize("rig, left, right, extra", [
    # Mixamo as USD exporters write it: the "mixamorig:" namespace becomes a prefix.
    ("mixamo in USD", ["mixamorig_LeftUpLeg", "mixamorig_LeftLeg", "mixamorig_LeftFoot", "mixamorig_LeftToeBase"],
     ["mixamorig_RightUpLeg", "mixamorig_RightLeg", "mixamorig_RightFoot", "mixamorig_RightToeBase"], ()),
    ("Unreal mannequin", ["thigh_l", "calf_l", "foot_l", "ball_l"], ["thigh_r", "calf_r", "foot_r", "ball_r"],
     (("thigh_l", "thigh_twist_01_l"), ("calf_l", "calf_twist_01_l"))),
    ("3ds Max biped", ["Bip01_L_Thigh", "Bip01_L_Calf", "Bip01_L_Foot", "Bip01_L_Toe0"],
     ["Bip01_R_Thigh", "Bip01_R_Calf", "Bip01_R_Foot", "Bip01_R_Toe0"], ()),
    ("Xsens MVN", ["LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToe"],
     ["RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToe"], ()),
    ("Rokoko", ["LeftThigh", "LeftShin", "LeftFoot", "LeftToe"], ["RightThigh", "RightShin", "RightFoot", "RightToe"], ()),
    ("OptiTrack Motive", ["LThigh", "LShin", "LFoot", "LToe"], ["RThigh", "RShin", "RFoot", "RToe"], ()),
    # SMPL's "Foot" is the toe end below its ankle.
    ("SMPL", ["L_Hip", "L_Knee", "L_Ankle", "L_Foot"], ["R_Hip", "R_Knee", "R_Ankle", "R_Foot"], ()),
    ("Rigify deform bones", ["DEF_thigh_L", "DEF_shin_L", "DEF_foot_L", "DEF_toe_L"],
     ["DEF_thigh_R", "DEF_shin_R", "DEF_foot_R", "DEF_toe_R"], ()),
    ("Maya HumanIK, lower case", ["leftUpLeg", "leftLeg", "leftFoot", "leftToeBase"],
     ["rightUpLeg", "rightLeg", "rightFoot", "rightToeBase"], (("leftUpLeg", "leftUpLegRoll"),)),
    ("one case, no separators", ["leftupleg", "leftleg", "leftfoot", "lefttoebase"],
     ["RIGHTUPLEG", "RIGHTLEG", "RIGHTFOOT", "RIGHTTOEBASE"], ()),
    ("CMU ASF", ["lfemur", "ltibia", "lfoot", "ltoes"], ["rfemur", "rtibia", "rfoot", "rtoes"], ()),
])
def test_legs_are_found_on_rigs_as_they_arrive_in_usd(rig, left, right, extra):
    names, parents = _rig("Hips", left, right, extra)
    legs = contacts.find_legs(names, parents)
    assert [leg.side for leg in legs] == ["left", "right"], rig
    for leg, chain in zip(legs, (left, right)):
        assert [names[j].rsplit("/", 1)[-1] for j in leg.joints] == chain, rig


def test_legs_are_not_made_of_joints_that_only_sound_like_legs():
    # Twist and roll joints beside the chain, a prop named after a foot, a left arm: no leg.
    names, parents = _rig("Hips", ["LeftUpLegRoll", "LeftLegTwist", "LeftFootProp"], ["RightArm", "RightForeArm", "RightHand"])
    assert contacts.find_legs(names, parents) == []
    # The chain must be hip, knee, ankle, each the child of the one before.
    names, parents = _rig("Hips", ["thigh_l", "foot_l"], ["thigh_r", "calf_r"], (("thigh_l", "calf_l"),))
    assert contacts.find_legs(names, parents) == []


def test_no_legs_on_a_rig_without_leg_names():
    names = ["Root", "Root/A", "Root/A/B", "Root/A/B/C"]
    assert contacts.find_legs(names, np.array([-1, 0, 1, 2])) == []


def test_walker_contacts_alternate_and_hold_still(walk_clip):
    world = walker.joint_world_positions(walk_clip)
    seconds = np.arange(walk_clip.num_frames) / FPS
    found = {}
    for side in ("Left", "Right"):
        ankle, toe = world[:, walk_clip.joint_index(side + "Foot")], world[:, walk_clip.joint_index(side + "Toe")]
        found[side] = contacts.detect_leg(seconds, ankle, toe, "Y", 1.0)
        mask = contacts.mask_of(found[side], walk_clip.num_frames)
        # Planted toes barely move during a contact; the foot is in the air between contacts.
        speed = contacts.ground_speed(seconds, toe, "Y")
        assert np.median(speed[mask]) < 0.05
        assert (~mask).sum() > 0.2 * walk_clip.num_frames
    # 10 m at 1.25 m/s: about 7 steps per foot.
    assert all(6 <= len(r) <= 9 for r in found.values())
    # Walking, never both feet in the air.
    both = contacts.mask_of(found["Left"], walk_clip.num_frames) | contacts.mask_of(found["Right"], walk_clip.num_frames)
    assert both.all()


def test_a_cut_in_the_clip_changes_no_contact(walk_clip):
    """Many captures keep their rest pose at the origin in the first frame. The jump from it to
    the take is a cut: it neither raises the speeds a foot may plant at (they grow with the
    clip's mean foot speed) nor joins that frame to a contact."""
    world = walker.joint_world_positions(walk_clip)
    moved = world[:1] + np.array([3.0, 0.0, -2.5])               # 3.9 m away, feet on the ground
    cut = np.concatenate([moved, world])
    seconds = np.arange(len(cut)) / FPS
    for side in ("Left", "Right"):
        ankle, toe = walk_clip.joint_index(side + "Foot"), walk_clip.joint_index(side + "Toe")
        plain = contacts.detect_leg(seconds[:-1], world[:, ankle], world[:, toe], "Y", 1.0)
        after = contacts.detect_leg(seconds, cut[:, ankle], cut[:, toe], "Y", 1.0)
        assert [(a - 1, b - 1) for a, b in after] == plain, side


def _locked_skate_over_source(tmp_path, cut: bool) -> float:
    """A 193-frame walk at 60 fps (its first frame moved 3.9 m away when ``cut``, as a rest
    pose left at the origin), bent 40 cm sideways at its middle by handles at its first,
    middle and last frames; metres per second its locked feet slide more than the source's."""
    clip = walker.walk(frames=193, fps=60.0, speed=1.25, name="take")
    if cut:
        clip.translations[0, 0] += np.array([3.0, 0.0, -2.5], dtype=np.float32)
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=60.0, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    at = evaluate.agent_root_positions(stage, a, [0.0, 96.0, 192.0])
    for name, frame, p in zip(("first", "middle", "last"), (0, 96, 192), at):
        examples.add_position_constraint(stage, f"/Edits/{name}", a, frame,
                                         tuple(map(float, p + (0.4 if frame == 96 else 0.0, 0.0, 0.0))))
    stage.GetRootLayer().Save()
    _, out = _solve(tmp_path)
    source = measure.foot_skate(stage, a)
    edited = measure.foot_skate(out, a, times=source.times, contact=source.contact)
    return edited.mean - source.mean


def test_a_cut_in_the_clip_leaves_the_locked_feet_as_planted(tmp_path):
    clean = _locked_skate_over_source(tmp_path / "clean", False)
    cut = _locked_skate_over_source(tmp_path / "cut", True)
    assert clean <= 0.005 and cut <= 0.005, (clean, cut)


def test_a_run_has_contacts_on_both_feet_in_turn():
    clip = walker.run(frames=120, fps=60.0, speed=3.5)
    world = walker.joint_world_positions(clip)
    seconds = np.arange(clip.num_frames) / 60.0
    found = [contacts.detect_leg(seconds, world[:, clip.joint_index(s + "Foot")],
                                 world[:, clip.joint_index(s + "Toe")], "Y", 1.0) for s in ("Left", "Right")]
    assert all(len(r) >= 2 for r in found)
    left, right = (contacts.mask_of(r, clip.num_frames) for r in found)
    assert not np.any(left & right)                   # a run never has both feet down
    with pytest.raises(ValueError, match="relative-speed"):
        contacts.DetectSettings(relative_speed=-1.0).validate()


def test_detection_thresholds_follow_meters_per_unit(walk_clip):
    world = walker.joint_world_positions(walk_clip)
    seconds = np.arange(walk_clip.num_frames) / FPS
    ankle = world[:, walk_clip.joint_index("LeftFoot")]
    in_m = contacts.detect_leg(seconds, ankle, None, "Y", 1.0)
    in_cm = contacts.detect_leg(seconds, ankle * 100.0, None, "Y", 0.01)
    assert in_m == in_cm and in_m


# ---- the job -----------------------------------------------------------------------------------


def _random_legs(rng, agents=3, poses=40):
    weights = np.clip(rng.uniform(-0.5, 1.5, (agents * poses, 2)), 0, 1)
    weights[5, 0] = 1.0
    inputs = examples.leg_inputs(rng, agents, poses, 0.15, [0, 2, 4], weights)
    inputs.target[5, 0] = inputs.hip[5, 0] + (0, -1.2, 0.1)        # out of reach: the pelvis must drop
    return inputs


@pytest.mark.parametrize("keep", [False, True])
def test_the_solver_job_matches_numpy(keep):
    inputs = _random_legs(np.random.default_rng(7))
    if keep:  # a stationary range: no pelvis drop there, easing back in around it
        inputs.keep = np.zeros(len(inputs.hip), np.uint8)
        inputs.keep[50:60] = 1
    fast, slow = footlock.lock_feet(inputs), footlock.lock_feet_numpy(inputs)
    for name in ("hip_local", "knee_local", "ankle_local", "drop", "reached"):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), atol=1e-9, err_msg=name)
    assert fast.drop[5] > 0.2 and fast.drop[5] >= fast.drop[:40].max()
    if keep:
        assert np.all(fast.drop[50:60] == 0) and fast.drop[40:100].max() > 0


def test_the_job_keeps_bones_reaches_its_targets_and_never_overstretches():
    inputs = _random_legs(np.random.default_rng(3))
    out = footlock.lock_feet(inputs)
    shift = -out.drop[:, None, None] * inputs.up
    hip = inputs.hip + shift
    thigh = np.linalg.norm(inputs.knee - inputs.hip, axis=-1)
    shin = np.linalg.norm(inputs.ankle - inputs.knee, axis=-1)
    reach = np.linalg.norm(out.reached - hip, axis=-1)
    assert np.all(reach <= footlock.MAX_REACH * (thigh + shin) + 1e-12)
    # Targets within the soft reach are met exactly.
    wanted = inputs.ankle + inputs.weight[..., None] * (inputs.target - inputs.ankle)
    easy = np.linalg.norm(wanted - hip, axis=-1) < footlock.SOFT_REACH * (thigh + shin) - 1e-6
    easy &= np.linalg.norm(wanted - hip, axis=-1) > np.abs(thigh - shin) + 1e-3
    assert easy.sum() > 100
    np.testing.assert_allclose(out.reached[easy], wanted[easy], atol=1e-9)


def test_the_job_rejects_bad_arrays():
    inputs = _random_legs(np.random.default_rng(1))
    inputs.weight[0, 0] = 2.0
    with pytest.raises(ValueError, match="weights"):
        footlock.lock_feet(inputs)
    inputs = _random_legs(np.random.default_rng(1))
    inputs.knee = inputs.knee[:-1]
    with pytest.raises(ValueError, match="knee"):
        footlock.lock_feet(inputs)


# ---- end to end --------------------------------------------------------------------------------


LEGS = [("LeftUpLeg", "LeftLeg", "LeftFoot"), ("RightUpLeg", "RightLeg", "RightFoot")]


def test_a_bent_path_keeps_the_planted_feet_where_they_are(tmp_path, walk_clip):
    _, a = _bent_path_stage(tmp_path, walk_clip)
    free, free_stage = _solve(tmp_path, "free", foot_locking=False)
    locked, out = _solve(tmp_path, "locked")
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    feet = ["LeftFoot", "LeftToe", "RightFoot", "RightToe"]
    source = measure.foot_skate(src, a, foot_joints=feet)
    before = measure.foot_skate(free_stage, a, times=source.times, foot_joints=feet, contact=source.contact)
    after = measure.foot_skate(out, a, times=source.times, foot_joints=feet, contact=source.contact)
    assert before.mean > source.mean + 0.02          # the edit alone slides the feet
    assert after.mean <= source.mean + 0.005         # locked: the source's skate, within 0.5 cm/s
    bones, flips, speed = _leg_quality(src, out, a, source.times, LEGS, FPS, unlocked=free_stage)
    assert bones < 1e-6 and flips == 0 and speed < 1.5
    # No foot goes below the ground it stood on.
    heights = [evaluate.joint_world_positions(st, a, source.times)[..., 1] for st in (src, out)]
    ankles = [walk_clip.joint_index(n) for n in ("LeftFoot", "RightFoot", "LeftToe", "RightToe")]
    assert np.all(heights[1][:, ankles] >= heights[0][:, ankles].min(axis=0) - 1e-6)
    # The constraints still hold.
    assert all(c["met"] and c["residual"] < 1e-6 for c in locked.report.constraints)
    entry = locked.report.agents[a]
    assert entry["footContactsLocked"] >= 12
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005 < entry["footSkateUnlocked"]
    assert entry["footSkateEdited"] == pytest.approx(after.mean, rel=1e-4)     # as the composed stage plays
    assert entry["footSkateUnlocked"] == pytest.approx(before.mean, rel=1e-4)
    assert 0 < entry["maxFootCorrection"] < 0.1 and 0 <= entry["maxPelvisDrop"] < 0.05
    assert locked.report.stats["footLockedAgents"] == 1
    plants = locked.layer.GetPrimAtPath("/MocapEdit/Guides/FootPlants")
    assert plants and len(plants.attributes["points"].default) == entry["footContactsLocked"]


UNREAL_NAMES = {"Root": "root", "Hips": "pelvis", "LeftUpLeg": "thigh_l", "LeftLeg": "calf_l", "LeftFoot": "foot_l",
                "LeftToe": "ball_l", "RightUpLeg": "thigh_r", "RightLeg": "calf_r", "RightFoot": "foot_r",
                "RightToe": "ball_r"}


@pytest.mark.parametrize("rename", [lambda leaf: UNREAL_NAMES.get(leaf, leaf), lambda leaf: "mixamorig_" + leaf],
                         ids=["Unreal mannequin", "Mixamo in USD"])
def test_a_rig_named_another_way_keeps_its_feet_as_the_walker_does(tmp_path, walk_clip, rename):
    """The walker with its joints renamed as another rig family names them: the same legs are
    found, the same contacts locked, and the composed stage plays the same motion."""
    joints = tuple("/".join(rename(leaf) for leaf in j.split("/")) for j in walk_clip.joints)
    renamed = dataclasses.replace(walk_clip, joints=joints, name="renamed")
    (tmp_path / "walker").mkdir()
    (tmp_path / "renamed").mkdir()
    _bent_path_stage(tmp_path / "walker", walk_clip)
    _, a = _bent_path_stage(tmp_path / "renamed", renamed)
    base, base_stage = _solve(tmp_path / "walker")
    other, other_stage = _solve(tmp_path / "renamed")
    entry, expected = other.report.agents[a], base.report.agents[a]
    assert entry["footContactsLocked"] == expected["footContactsLocked"] >= 12
    assert entry["footSkateEdited"] == pytest.approx(expected["footSkateEdited"], abs=1e-9)
    times = np.arange(193, dtype=np.float64)
    np.testing.assert_allclose(evaluate.joint_world_positions(other_stage, a, times),
                               evaluate.joint_world_positions(base_stage, a, times), atol=1e-6)


def test_locking_is_off_by_setting_and_by_agent(tmp_path, walk_clip):
    stage, a = _bent_path_stage(tmp_path, walk_clip)
    settings = stage.DefinePrim("/Settings", "MocapSolveSettings")
    settings.CreateAttribute("footLocking", Sdf.ValueTypeNames.Bool, False, Sdf.VariabilityUniform).Set(False)
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, "off")
    assert "footSkateUnlocked" not in result.report.agents[a]
    settings.GetAttribute("footLocking").Set(True)
    stage.GetPrimAtPath(a).CreateAttribute("mocap:footLocking", Sdf.ValueTypeNames.Bool, False,
                                           Sdf.VariabilityUniform).Set(False)
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, "opt_out")
    assert "footSkateUnlocked" not in result.report.agents[a]
    assert any("mocap:footLocking = false" in n for n in result.report.agents[a]["notes"])
    stage.GetPrimAtPath(a).GetAttribute("mocap:footLocking").Set(True)
    stage.GetRootLayer().Save()
    for flags, locked in (([], True), (["--no-foot-locking"], False)):
        out = run_cli("solve", tmp_path / "shot.usda", "-o", tmp_path / "cli.usda", "--report", tmp_path / "cli.json", *flags)
        assert out.returncode == 0, out.stderr
        assert ("feet:" in out.stderr) == locked
        assert ("footSkateUnlocked" in (tmp_path / "cli.json").read_text()) == locked


def test_authored_contacts_replace_detection(tmp_path, walk_clip):
    stage, a = _bent_path_stage(tmp_path, walk_clip)
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    anim.ApplyAPI("MocapFootContactAPI", "left1")
    anim.CreateAttribute("footContact:left1:joint", Sdf.ValueTypeNames.Token, False,
                         Sdf.VariabilityUniform).Set("LeftToe")
    anim.CreateAttribute("footContact:left1:frames", Sdf.ValueTypeNames.Int2, False,
                         Sdf.VariabilityUniform).Set(Gf.Vec2i(30, 40))
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path)
    assert result.report.agents[a]["footContactsLocked"] == 1


def test_detect_contacts_skips_an_agent_without_legs_and_says_so(tmp_path, walk_clip):
    """A prop agent (a rig without legs) among walkers: the walkers' contacts are written and
    the prop named (the whole shot was refused over it, though solve takes it)."""
    from mocapedit.data import walker as walkers
    prop = walkers.walk(frames=48, fps=FPS, name="prop")
    keep = [i for i, j in enumerate(prop.joints) if "Leg" not in j and "Foot" not in j and "Toe" not in j]
    prop = dataclasses.replace(prop, joints=[prop.joints[i] for i in keep],
                               parents=np.array([keep.index(p) if p >= 0 else -1 for p in prop.parents[keep]]),
                               rest_translations=prop.rest_translations[keep], rest_rotations=prop.rest_rotations[keep],
                               translations=prop.translations[:, keep], rotations=prop.rotations[:, keep])
    examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", walk_clip),
                                                        examples.AgentSpec("prop", prop, (3.0, 0.0, 0.0))],
                               up_axis="Y", fps=FPS, clips_dir=tmp_path / "clips")
    out = run_cli("detect-contacts", tmp_path / "shot.usda", "-o", tmp_path / "contacts.usda")
    assert out.returncode == 0, out.stderr
    assert "/World/Crowd/prop" in out.stderr and "no legs" in out.stderr
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "contacts.usda"))
    paths = []
    layer.Traverse(Sdf.Path.absoluteRootPath, paths.append)
    assert any(p.name == "footContact:left1:frames" for p in paths if p.IsPropertyPath())
    assert not any("prop" in str(p) for p in paths)


def test_heel_and_toe_contacts_that_overlap_are_one_plant(tmp_path, walk_clip):
    """Each detected contact authored as a heel strike on the ankle and a toe-off on the toe that
    overlap it: the foot is planted once, where it was two plants fighting over the same frames
    (locked skate 4.7 -> 6.8 cm/s)."""
    _bent_path_stage(tmp_path, walk_clip)
    detected = solve(str(tmp_path / "shot.usda")).report.agents[f"{CROWD}/a"]
    assert run_cli("detect-contacts", tmp_path / "shot.usda", "-o", tmp_path / "contacts.usda",
                   "--composed", tmp_path / "reviewed.usda").returncode == 0
    stage = Usd.Stage.Open(str(tmp_path / "reviewed.usda"))
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    for name in [s.split(":", 1)[1] for s in anim.GetAppliedSchemas() if s.startswith("MocapFootContactAPI:")]:
        first, last = anim.GetAttribute(f"footContact:{name}:frames").Get()
        toe = "LeftToe" if "Left" in anim.GetAttribute(f"footContact:{name}:joint").Get() else "RightToe"
        middle = (first + last) // 2
        anim.GetAttribute(f"footContact:{name}:frames").Set(Gf.Vec2i(first, min(last, middle + 3)))
        anim.ApplyAPI("MocapFootContactAPI", name + "toe")
        _author(stage, anim.GetPath(), f"footContact:{name}toe:joint", Sdf.ValueTypeNames.Token, toe)
        _author(stage, anim.GetPath(), f"footContact:{name}toe:frames", Sdf.ValueTypeNames.Int2,
                Gf.Vec2i(max(first, middle - 3), last))
    stage.Save()
    split = solve(str(tmp_path / "reviewed.usda")).report.agents[f"{CROWD}/a"]
    assert split["footContactsLocked"] == detected["footContactsLocked"]
    assert split["footSkateEdited"] == pytest.approx(detected["footSkateEdited"], abs=1e-6)


def test_an_arm_given_as_a_leg_is_not_planted_and_is_named(tmp_path, walk_clip):
    """mocap:leftLegJoints naming the arm: its hand never comes near the ground the body stands
    on, so it gets no contacts (it had 7, its hand held in the air by the lock) and the agent's
    notes say which leg and property; detect-contacts finds none on it and says why."""
    stage, a = _bent_path_stage(tmp_path, walk_clip)
    both = solve(str(tmp_path / "shot.usda")).report.agents[a]["footContactsLocked"]
    _author(stage, a, "mocap:leftLegJoints", Sdf.ValueTypeNames.TokenArray,
            Vt.TokenArray(["LeftArm", "LeftForeArm", "LeftHand"]))
    stage.GetRootLayer().Save()
    entry = solve(str(tmp_path / "shot.usda")).report.agents[a]
    assert 0 < entry["footContactsLocked"] < both - 4
    assert any("left leg" in n and "mocap:leftLegJoints" in n and "LeftHand" in n for n in entry["notes"])
    out = run_cli("detect-contacts", tmp_path / "shot.usda", "-o", tmp_path / "contacts.usda")
    assert out.returncode == 0 and "contacts left 0, right" in out.stderr and "LeftHand" in out.stderr


def _author(stage, path, name, type_name, value):
    stage.GetPrimAtPath(path).CreateAttribute(name, type_name, False, Sdf.VariabilityUniform).Set(value)
    stage.GetRootLayer().Save()


@pytest.mark.parametrize("prop, value, message", [
    ("mocap:leftLegJoints", ["LeftUpLeg", "LeftKnee", "LeftFoot"], "'LeftKnee' is not in the skeleton"),
    ("mocap:leftLegJoints", ["LeftUpLeg", "LeftFoot", "LeftToe"], "is not a child of"),
    ("mocap:rightLegJoints", ["RightUpLeg", "RightLeg"], "hip, knee, ankle"),
    # The left leg on both sides: the right foot was never locked, silently.
    ("mocap:rightLegJoints", ["LeftUpLeg", "LeftLeg", "LeftFoot"], "shares joint '[^']*LeftUpLeg' with the left leg"),
])
def test_bad_legs_name_the_agent_and_property(tmp_path, walk_clip, prop, value, message):
    stage, a = _bent_path_stage(tmp_path, walk_clip)
    _author(stage, a, prop, Sdf.ValueTypeNames.TokenArray, Vt.TokenArray(value))
    with pytest.raises(MocapEditError, match=f"<{a}>.{prop}: .*{message}"):
        solve(str(tmp_path / "shot.usda"))
    out = run_cli("solve", tmp_path / "shot.usda", "-o", tmp_path / "never.usda")
    assert out.returncode == 1 and prop in out.stderr and "Traceback" not in out.stderr
    assert not (tmp_path / "never.usda").exists()


def test_a_contact_outside_the_clip_names_the_clip_and_property(tmp_path, walk_clip):
    stage, a = _bent_path_stage(tmp_path, walk_clip)
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    anim.ApplyAPI("MocapFootContactAPI", "late")
    _author(stage, anim.GetPath(), "footContact:late:joint", Sdf.ValueTypeNames.Token, "LeftFoot")
    _author(stage, anim.GetPath(), "footContact:late:frames", Sdf.ValueTypeNames.Int2, Gf.Vec2i(180, 200))
    with pytest.raises(MocapEditError, match=r"footContact:late:frames: .*\[180, 200\] is outside the clip"):
        solve(str(tmp_path / "shot.usda"))
    _author(stage, anim.GetPath(), "footContact:late:frames", Sdf.ValueTypeNames.Int2, Gf.Vec2i(18, 20))
    _author(stage, anim.GetPath(), "footContact:late:joint", Sdf.ValueTypeNames.Token, "Spine")
    with pytest.raises(MocapEditError, match=r"footContact:late:joint: .*not the ankle or toe"):
        solve(str(tmp_path / "shot.usda"))


@pytest.mark.skipif(not MOCAP.exists(), reason="needs ../shared/mocap")
def test_a_real_walk_edited_by_a_handle_keeps_its_feet(tmp_path):
    clip = MOCAP / "cc_cmu07_01_walk.bvh"
    imported = run_cli("import-bvh", clip, "-o", tmp_path / "clip.usda", "--agent")
    assert imported.returncode == 0, imported.stderr
    stage = Usd.Stage.Open(str(tmp_path / "clip.usda"))
    agent = next(p for p in stage.Traverse() if "MocapAgentAPI" in p.GetAppliedSchemas())
    a = str(agent.GetPath())
    frames = evaluate.sample_times(stage, a)
    mid = len(frames) // 2
    root = evaluate.agent_root_positions(stage, a, frames[[0, mid, -1]])
    shot = Sdf.Layer.CreateNew(str(tmp_path / "shot.usda"))
    shot.subLayerPaths = ["clip.usda"]
    clip_layer = stage.GetRootLayer()   # a stage follows its root layer's time and units
    shot.timeCodesPerSecond = clip_layer.timeCodesPerSecond
    shot.framesPerSecond = clip_layer.framesPerSecond
    for key in ("upAxis", "metersPerUnit"):
        shot.pseudoRoot.SetInfo(key, clip_layer.pseudoRoot.GetInfo(key))
    shot.Save()
    shot_stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    up = UsdGeom.GetStageUpAxis(shot_stage)
    side = np.array([40.0, 0.0, 0.0])                        # 40 cm sideways at the middle
    for k, (f, p) in enumerate(zip((0, mid, len(frames) - 1), root)):
        examples.add_position_constraint(shot_stage, f"/Edits/c{k}", a, int(f), p + (side if k == 1 else 0))
    shot_stage.GetRootLayer().Save()
    result, out = _solve(tmp_path)
    source = measure.foot_skate(shot_stage, a)
    after = measure.foot_skate(out, a, times=source.times, foot_joints=list(source.joints), contact=source.contact)
    mpu = UsdGeom.GetStageMetersPerUnit(shot_stage)
    assert (after.mean - source.mean) * mpu <= 0.005, (source.mean, after.mean, up)
    assert result.report.agents[a]["footContactsLocked"] > 0


def test_detect_contacts_writes_a_layer_that_the_solve_uses(tmp_path, walk_clip):
    _bent_path_stage(tmp_path, walk_clip)
    out = run_cli("detect-contacts", tmp_path / "shot.usda", "-o", tmp_path / "contacts.usda",
                  "--composed", tmp_path / "reviewed.usda")
    assert out.returncode == 0, out.stderr
    assert "contacts left" in out.stderr
    reviewed = Usd.Stage.Open(str(tmp_path / "reviewed.usda"))
    anim = next(p for p in reviewed.Traverse() if p.IsA(UsdSkel.Animation))
    names = [s.split(":", 1)[1] for s in anim.GetAppliedSchemas() if s.startswith("MocapFootContactAPI:")]
    assert sum(n.startswith("left") for n in names) >= 6 and sum(n.startswith("right") for n in names) >= 6
    first, last = anim.GetAttribute(f"footContact:{names[0]}:frames").Get()
    assert 0 <= first <= last < walk_clip.num_frames
    detected = solve(str(tmp_path / "shot.usda"), foot_locking=True).report
    authored = solve(str(tmp_path / "reviewed.usda")).report
    a = f"{CROWD}/a"
    assert authored.agents[a]["footContactsLocked"] == detected.agents[a]["footContactsLocked"] == len(names)
    assert authored.agents[a]["footSkateEdited"] == pytest.approx(detected.agents[a]["footSkateEdited"], abs=1e-9)
    bad = run_cli("detect-contacts", tmp_path / "shot.usda", "-o", tmp_path / "x.usda", "--height", "-1")
    assert bad.returncode == 1 and "height" in bad.stderr and not (tmp_path / "x.usda").exists()


def test_a_dragged_idle_drags_the_plant_along_without_a_pop(tmp_path):
    clip, (first, last) = walker.walk_idle_walk(frames=150, fps=FPS, stop_frame=60, idle_frames=36, name="stop_go")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    reach = float(clip.translations[first, 0, 2])
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    # No stationary tag: the path edit slides the idle 0.5 m sideways while the feet are planted.
    examples.add_position_constraint(stage, "/Edits/in", a, first, (0.0, 0.0, reach))
    examples.add_position_constraint(stage, "/Edits/out", a, last, (0.5, 0.0, reach))
    stage.GetRootLayer().Save()
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    entry = result.report.agents[a]
    assert entry["maxFootCorrection"] <= 0.15 + 1e-9          # the leash: legs never strained further
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    times = evaluate.sample_times(src, a)
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.5
    assert entry["footSkateEdited"] < entry["footSkateUnlocked"]


@pytest.mark.parametrize("end", [12.0, 7.5])
def test_a_walk_sped_up_or_slowed_down_keeps_its_feet_beyond_the_constant_leash(tmp_path, walk_clip, end):
    # The 10 m walk made to cover 12 m (or 7.5 m) in the same time: each step drags its planted foot
    # about 0.2 m, so a plant half way along is over 8 cm from where the edit puts the foot at
    # the ends of the contact. The leg reaches that far with the pelvis lowered a little.
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", walk_clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/end", a, 192, (0.0, 0.0, end))
    stage.GetRootLayer().Save()
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    entry = result.report.agents[a]
    assert entry["footSkateUnlocked"] > entry["footSkateSource"] + 0.15
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005
    assert 0.08 < entry["maxFootCorrection"] < 0.15 and entry["maxPelvisDrop"] <= 0.08 + 1e-9
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    times = evaluate.sample_times(src, a)
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.5
    assert all(c["met"] and c["residual"] < 1e-6 for c in result.report.constraints)


def test_a_walk_sped_up_beyond_the_legs_reach_slides_but_its_legs_move_no_faster(tmp_path, walk_clip):
    # 13 m in the time of 10 m: the planted feet are dragged further than any leash, so the plant
    # follows 15 cm from the edited foot, and the lock eases out over longer so the leg catching
    # up after the contact turns no faster than 1.5 times the source.
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", walk_clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/end", a, 192, (0.0, 0.0, 13.0))
    stage.GetRootLayer().Save()
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    entry = result.report.agents[a]
    assert entry["footSkateEdited"] < 0.5 * entry["footSkateUnlocked"]
    assert entry["maxFootCorrection"] <= 0.15 + 1e-9 and entry["maxPelvisDrop"] <= 0.08 + 1e-9
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    bones, flips, speed = _leg_quality(src, out, a, evaluate.sample_times(src, a), LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.5


def test_a_z_up_centimetre_stage_at_60_fps_with_a_time_offset(tmp_path):
    fps = 60.0
    clip = walker.walk(frames=481, fps=fps, speed=1.25, up="Z", meters_per_unit=0.01, name="zwalk")
    stage = examples.build_crowd_stage(
        tmp_path / "shot.usda", [examples.AgentSpec("a", clip, (300.0, -200.0, 0.0), yaw=30.0, time_offset=12.0)],
        up_axis="Z", meters_per_unit=0.01, fps=fps, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    times = evaluate.sample_times(stage, a)
    assert times[0] == 12.0
    root = evaluate.agent_root_positions(stage, a, times[[0, 240, 480]])
    for k, (f, p) in enumerate(zip((0, 240, 480), root)):
        examples.add_position_constraint(stage, f"/Edits/c{k}", a, f, p + (np.array([120.0, 0.0, 0.0]) if k == 1 else 0))
    stage.GetRootLayer().Save()
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    feet = ["LeftFoot", "LeftToe", "RightFoot", "RightToe"]
    source = measure.foot_skate(src, a, foot_joints=feet)
    before = measure.foot_skate(free, a, times=source.times, foot_joints=feet, contact=source.contact)
    after = measure.foot_skate(out, a, times=source.times, foot_joints=feet, contact=source.contact)
    assert before.mean > source.mean + 2.0                       # cm/s
    assert after.mean <= source.mean + 0.5
    bones, flips, speed = _leg_quality(src, out, a, source.times, LEGS, fps, unlocked=free)
    assert bones < 1e-4 and flips == 0 and speed < 1.5          # 1e-4 cm = 1e-6 m
    entry = result.report.agents[a]
    assert entry["maxFootCorrection"] <= 8.0 + 1e-6 and entry["footContactsLocked"] >= 12


def test_an_edit_that_keeps_the_feet_planted_is_not_locked_nor_baked(tmp_path, walk_clip):
    """A ten-metre walk whose middle is nudged 25 cm aside moves its feet a few millimetres from
    where they were planted, but slides them by less than 0.5 cm/s more than its source: its legs
    are kept, no animation is baked, and the report says no foot was corrected and the pelvis not
    lowered (no plant or IK is solved for it). The same walk bent 1.5 m aside is locked."""
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", walk_clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    start, middle, end = evaluate.agent_root_positions(stage, a, [0.0, 96.0, 192.0])
    for name, frame, where in (("start", 0, start), ("middle", 96, middle + (0.25, 0.0, 0.0)), ("end", 192, end)):
        examples.add_position_constraint(stage, f"/Edits/{name}", a, frame, tuple(map(float, where)))
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, "nudged")
    entry = result.report.agents[a]
    assert 0 < entry["footSkateUnlocked"] - entry["footSkateSource"] < 0.005
    assert entry["maxFootCorrection"] == 0.0 and entry["maxPelvisDrop"] == 0.0
    assert entry["footSkateEdited"] == entry["footSkateUnlocked"]
    assert result.report.stats["footLockedAgents"] == 0 and result.report.stats["footLockingNotNeeded"] == 1
    assert "SkelAnimation" not in result.layer.ExportToString()
    # The printed figures say why no legs changed (before: "N contacts locked on 0 agents").
    line = "\n".join(foot_locking_lines(result.report.stats))
    assert "legs locked on 0 agents, left as they were on 1 (as planted as the source's)" in line, line

    _bent_path_stage(tmp_path, walk_clip)
    result, _ = _solve(tmp_path, "bent")
    assert result.report.stats["footLockedAgents"] == 1
    assert "SkelAnimation" in result.layer.ExportToString()


def test_agents_a_solve_leaves_where_they_were_are_not_locked(tmp_path):
    """A solve may give back unchanged the path of an agent it includes (pinned where it already
    walks, a near miss that collision avoidance watched but never pushed): that is no edit. Foot
    locking leaves such agents alone (no figures in the report, not counted in the shot's), as
    the writer does."""
    walk = walker.walk(frames=120, fps=24.0, name="walk")
    specs = [examples.AgentSpec("moved", walk, (0.0, 0.0, 0.0), 0.0, 0.0),
             examples.AgentSpec("pinned", walk, (3.0, 0.0, 0.0), 0.0, 0.0)]
    path = tmp_path / "s.usda"
    stage = examples.build_crowd_stage(path, specs)
    for name, shift in (("moved", 0.6), ("pinned", 0.0)):
        agent = f"/World/Crowd/{name}"
        end = evaluate.agent_root_positions(stage, agent, [119.0])[0]
        end[1] = 0.0
        examples.add_position_constraint(stage, f"/Edits/{name}", agent, 119,
                                         tuple(map(float, end + np.array([shift, 0.0, 0.0]))))
    stage.GetRootLayer().Save()
    result = solve(str(path), guides=False)
    report = result.report
    assert report.stats["editedAgents"] == 1
    assert report.agent("/World/Crowd/moved").foot_contacts_locked > 0
    assert report.agent("/World/Crowd/pinned").foot_contacts_locked is None


# ---- plants that slide least, feet that step, retimed agents -----------------------------------


def test_a_plant_dragged_one_way_late_in_its_contact_starts_where_it_slides_least():
    """The edited foot stays put for most of a contact and is dragged 25 cm at its end: a leash of
    15 cm lets the plant stay put all along (it starts 10 cm ahead); followed from the least-squares
    plant (5 cm ahead), it slid 5 cm. A drag of 50 cm slides 20 cm, no more (50 less twice 15)."""
    inside = np.arange(50)
    for reach, slid in ((0.25, 0.0), (0.5, 0.2)):
        offset = np.zeros((50, 2))
        offset[40:, 0] = np.linspace(0.0, reach, 10)
        plant = footplant.leash(offset, offset.mean(axis=0), inside, np.array([], dtype=int), np.full(50, 0.15))
        assert np.all(np.linalg.norm(plant - offset, axis=1) <= 0.15 + 1e-12)
        assert np.linalg.norm(np.diff(plant, axis=0), axis=1).sum() == pytest.approx(slid, abs=1e-9)


def _dragged_stand(tmp_path, along=0.5, idle=96):
    """A walk that stops and stands 4 s: the stand's end is moved ``along`` metres forward, its
    start held, so the standing body is dragged while both feet are planted."""
    clip, (first, last) = walker.walk_idle_walk(frames=idle + 100, fps=FPS, stop_frame=50, idle_frames=idle,
                                                name="stand")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    reach, end = float(clip.translations[first, 0, 2]), float(clip.translations[-1, 0, 2])
    for name, frame, z in (("start", 0, 0.0), ("in", first, reach), ("out", last, reach + along),
                           ("end", clip.num_frames - 1, end + along)):
        examples.add_position_constraint(stage, f"/Edits/{name}", a, frame, (0.0, 0.0, z))
    stage.GetRootLayer().Save()
    return stage, a, (first, last)


def _steady_drift(speed_m_s: float, frames: int = 960, fps: float = 120.0):
    """:func:`footplant.replant` on both feet planted through ``frames`` poses while the edit
    drags the body steadily at ``speed_m_s`` along x; the source moves each foot at up to
    0.6 m/s (a CMU punch take's feet), the leash is 15 cm. Returns (steps, metres the plants
    of both feet slide on the ground)."""
    dt = 1.0 / fps
    contact, movable = np.zeros((frames, 2), dtype=np.int64), np.ones((frames, 2), dtype=bool)
    offset = np.zeros((frames, 2, 3))
    offset[..., 0] = (speed_m_s * dt * np.arange(frames))[:, None]
    turn = np.zeros((frames, 2))
    out = footplant.replant(contact, movable, offset, np.full((frames, 2), 0.15), turn, offset.copy(), turn.copy(),
                            np.radians(15.0), seconds=dt, shortest=int(0.25 * fps), longest=int(1.5 * fps),
                            height=0.05, bend=np.zeros((frames, 2)), speed=np.array([0.6, 0.6]),
                            spin=np.array([10.0, 10.0]), knee_spin=np.array([10.0, 10.0]))
    down = (out.lift[1:] == 0) & (out.lift[:-1] == 0)
    return out.steps, float(np.linalg.norm(np.diff(out.shift, axis=0), axis=-1)[down].sum())


def test_a_steady_drift_that_carries_each_landing_further_still_steps():
    """A body dragged at 5 cm/s through 8 s on both feet: while a foot is in the air the body
    drifts on, so each step must land further and take longer, and its length settles only
    after several rounds. Three rounds left it unsettled and each foot slid at the leash's
    length all the way, 25 cm (the CMU punch take bent 40 cm by handles: 2 steps where it now
    takes 6, +0.9 cm/s over its source's skate where it now is +0.2). Now the feet step, and
    slide half as far.

    A drag nearly as fast as the source's feet can follow (10 cm/s; a CMU punch take pushed 1 m
    aside and back drifts at 13): a step landing half a leash ahead of the drift cannot get there
    in time, and the feet slid at the leash's length all the way, 65 cm each, without a step.
    Now such a step lands where the foot is then: shorter steps, and half the slide."""
    steps, slid = _steady_drift(0.05)
    assert steps >= 2 and slid < 0.35, (steps, slid)
    steps, slid = _steady_drift(0.1)
    assert steps >= 3 and slid < 0.5 * 2 * (0.8 - 0.15), (steps, slid)
    steps, slid = _steady_drift(0.13)
    assert steps >= 2 and slid < 0.6 * 2 * (1.04 - 0.15), (steps, slid)


def test_a_standing_body_dragged_further_than_a_leg_reaches_steps_instead_of_sliding(tmp_path):
    """The stand dragged 50 cm over 4 s: each foot takes steps, one at a time while the other
    bears the weight, lifted 5 cm, and its plants never slide; before, the plants slid at the
    leash's length (3.3 cm/s over the source). Measured on the composed stage by UsdSkel FK."""
    _, a, (first, last) = _dragged_stand(tmp_path)
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    entry = result.report.agents[a]
    assert entry["footSteps"] >= 4 and result.report.stats["footSteps"] == entry["footSteps"]
    assert entry["footSkateUnlocked"] > entry["footSkateSource"] + 0.03
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005
    assert entry["maxFootCorrection"] <= 0.15 + 1e-9
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    p = measure.plausibility(src, out, a)
    assert p.foot_skate_edited == pytest.approx(entry["footSkateEdited"], abs=1e-5)
    # Feet leave the ground only in the stand, by the step's height, one at a time.
    times = evaluate.sample_times(src, a)
    feet = ["LeftFoot", "RightFoot"]
    lift = (evaluate.foot_positions(out, a, times, feet).positions[..., 1]
            - evaluate.foot_positions(src, a, times, feet).positions[..., 1])
    up = lift > 0.02
    assert up.any(axis=0).all() and not (up[:, 0] & up[:, 1]).any()
    assert np.all(np.flatnonzero(up.any(axis=1)) >= first) and np.all(np.flatnonzero(up.any(axis=1)) <= last)
    assert lift.max() == pytest.approx(0.05, abs=0.01)
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.5


def test_a_stand_dragged_fast_keeps_its_feet_with_quick_steps(tmp_path):
    """The stand dragged 50 cm in 2 s (25 cm/s, as a CMU balance take bent 40 cm by handles
    drifts): its feet step often enough, quickly enough, to slide at most 0.5 cm/s more than
    the source's (0.53 with steps of at least 0.3 s; the CMU take +1.81 then, +0.34 now), no
    leg joint turning faster than 1.5 times the source's fastest."""
    src, a, _ = _dragged_stand(tmp_path, along=0.5, idle=48)
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    entry = result.report.agents[a]
    assert entry["footSteps"] >= 3
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005
    times = evaluate.sample_times(src, a)
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.5


def test_a_stand_dragged_faster_than_one_foot_at_a_time_steps_timed_against_its_hip(tmp_path):
    """A 60 fps stand whose middle a handle drags 1 m aside (43 cm/s): both feet step in turn.
    A step is as long as the foot needs to move no faster than it may against its hip, and the
    hip drifts along with the step: timed by the foot's speed over the ground, the steps came
    out longer than that, fewer fitted, and the feet slid 15.0 cm/s; timed against the hip,
    12.8. (A drag this fast still slides far over #17's bar.)"""
    frames, fps = 273, 60.0
    clip, _ = walker.walk_idle_walk(frames=frames, fps=fps, stop_frame=10, idle_frames=frames - 20, name="stand")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=fps, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    for name, f, dx in (("start", 0, 0.0), ("middle", frames // 2, 1.0), ("end", frames - 1, 0.0)):
        p = clip.translations[f, 0]
        examples.add_position_constraint(stage, f"/Edits/{name}", a, f, (float(p[0]) + dx, 0.0, float(p[2])))
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path)
    held = result.report.agents[a]
    assert held["footSkateEdited"] < 0.135      # m/s
    assert held["footSteps"] >= 3
    assert all(c["residual"] < 1e-6 for c in result.report.constraints)


def test_a_step_along_a_drifting_body_is_measured_against_the_hip():
    """The distance a step's foot covers against its hip: over the ground less a third of the
    body's drift (the foot moves over the middle half of the step, at up to 1.5 times its mean
    there; the hip at its mean all along). A foot stepping with the drift moves slower against
    its hip, one stepping against it faster; a body standing still changes nothing."""
    step, drift = np.array([0.3, 0.0, 0.0]), np.array([0.3, 0.0, 0.0])
    assert footplant.against_hip(step, np.zeros(3)) == pytest.approx(0.3)
    assert footplant.against_hip(step, drift) == pytest.approx(0.2)
    assert footplant.against_hip(step, -drift) == pytest.approx(0.4)
    # The peak of the foot's speed against the hip over the step's profile is what step_frames
    # allows: sampled finely, it stays within the limit and reaches it.
    n, seconds, speed = footplant.step_frames(0.2, 0.0, 0.0, 0.0, 1.0, 1e9, 1e9, 1e-3, 2), 1e-3, 1.0
    progress, _ = footplant.step_profile(n)
    foot = progress[:, None] * step
    hip = np.linspace(0.0, 1.0, n + 1)[:, None] * drift
    relative = np.linalg.norm(np.diff(foot - hip, axis=0), axis=1) / seconds
    assert relative.max() <= speed * 1.01 and relative.max() >= speed * 0.95


def _retimed_walk(tmp_path, beats, end: float):
    """A walk re-timed by time constraints alone (clip frame, shot time), the shot shown to
    ``end`` (the report measures the shot): (result, composed stage, agent)."""
    clip = walker.walk(frames=120, fps=FPS, name="beats")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    for k, (frame, time) in enumerate(beats):
        examples.add_time_constraint(stage, f"/Edits/beat{k}", a, frame, time)
    stage.SetEndTimeCode(end)
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path)
    return result, out, a


def test_a_retimed_walk_is_measured_against_its_source_as_its_timing_plays_it(tmp_path):
    """A walk re-timed to hurry and then slow down (time constraints alone) is played by a value
    clip; its feet are where its source put them at each clip time. Its foot skate at the shot's
    frames is its source's at the same clip times, per shot second: between the clip's samples
    (where the warp falls) the poses are interpolated, and a sped-up heel-toe roll is faster.
    Measured against its source at the clip's own samples, the warp alone counted 1.2 cm/s more."""
    result, out, a = _retimed_walk(tmp_path, ((22, 24.0), (46, 44.0), (70, 72.0)), 140.0)
    entry = result.report.agents[a]
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005
    # The same by FK: the source at the clip time each shot frame plays, the edited at that frame.
    warped = next(Usd.ClipsAPI(p).GetClipTimes() for p in out.Traverse() if Usd.ClipsAPI(p).GetClipTimes())
    stage_times, clip_times = np.array(warped).T
    # The shot's frames it plays through, and the clip's first and last samples.
    shot = np.unique(np.r_[stage_times[0], np.arange(np.ceil(stage_times[0]), stage_times[-1]), stage_times[-1]])
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    units = evaluate.stage_units(src)
    played = evaluate.foot_positions(src, a, np.interp(shot, stage_times, clip_times))
    source = metrics.foot_skate_of_positions(played.positions, shot, *units)
    edited = evaluate.foot_positions(out, a, shot)
    assert source.mean == pytest.approx(entry["footSkateSource"], rel=1e-3)
    assert metrics.foot_skate_of_positions(edited.positions, shot, *units, contact=source.contact).mean == \
        pytest.approx(entry["footSkateEdited"], rel=1e-3)


def test_a_retimed_walk_measured_on_the_stage_gives_the_reports_skate(tmp_path):
    """``measure.plausibility`` judges a re-timed walk against its source as the shot plays it,
    by UsdSkel FK at the clip times each shot frame plays, as the report does: a time edit
    alone slides no foot there. Interpolating the source's foot positions between its samples
    instead (not its joints, as USD does) made the warp alone slide the feet 0.14 cm/s more,
    and on real takes 0.5 to 0.8 cm/s more (a brisk walk delayed by avoidance)."""
    result, out, a = _retimed_walk(tmp_path, ((21, 23.76), (45, 43.32), (69, 73.08)), 144.0)
    entry = result.report.agents[a]
    figures = measure.plausibility(Usd.Stage.Open(str(tmp_path / "shot.usda")), out, a)
    # (The report also counts the clip's first and last samples, between the shot's frames.)
    assert figures.foot_skate_source == pytest.approx(entry["footSkateSource"], rel=2e-3)
    assert figures.foot_skate_edited == pytest.approx(entry["footSkateEdited"], rel=2e-3)
    assert abs(figures.foot_skate_edited - figures.foot_skate_source) < 1e-4     # 0.01 cm/s


CC_LEGS = [("CC_Base_L_Thigh", "CC_Base_L_Calf", "CC_Base_L_Foot"), ("CC_Base_R_Thigh", "CC_Base_R_Calf", "CC_Base_R_Foot")]


def _imported_shot(tmp_path, name):
    """A CMU clip (centimetres, 60 fps) as an agent, on a shot stage of its own."""
    imported = run_cli("import-bvh", MOCAP / f"{name}.bvh", "-o", tmp_path / "clip.usda", "--agent")
    assert imported.returncode == 0, imported.stderr
    clip = Usd.Stage.Open(str(tmp_path / "clip.usda"))
    shot = Sdf.Layer.CreateNew(str(tmp_path / "shot.usda"))
    shot.subLayerPaths = ["clip.usda"]
    layer = clip.GetRootLayer()
    shot.timeCodesPerSecond, shot.framesPerSecond = layer.timeCodesPerSecond, layer.framesPerSecond
    for key in ("upAxis", "metersPerUnit"):
        shot.pseudoRoot.SetInfo(key, layer.pseudoRoot.GetInfo(key))
    shot.Save()
    return Usd.Stage.Open(str(tmp_path / "shot.usda")), str(clip.GetDefaultPrim().GetPath())


@pytest.mark.skipif(not MOCAP.exists(), reason="needs ../shared/mocap")
def test_a_real_standing_clip_moved_by_a_handle_steps_within_the_bars(tmp_path):
    """A 22 s standing CMU clip (washing) whose middle is moved 40 cm aside, its ends held: its
    feet step instead of sliding (before: +0.31 cm/s over the source), no leg joint turning
    faster than 1.5 times the source's fastest."""
    stage, a = _imported_shot(tmp_path, "cc_cmu02_10_wash_self")
    times = evaluate.sample_times(stage, a)
    ends = (0, len(times) // 2, len(times) - 1)
    for k, (f, p) in enumerate(zip(ends, evaluate.agent_root_positions(stage, a, times[list(ends)]))):
        examples.add_position_constraint(stage, f"/Edits/c{k}", a, f, p + (np.array([40.0, 0.0, 0.0]) if k == 1 else 0))
    stage.GetRootLayer().Save()
    _, free = _solve(tmp_path, "free", foot_locking=False)
    result, out = _solve(tmp_path)
    entry = result.report.agents[a]
    assert entry["footSteps"] >= 2
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.5        # cm/s
    bones, flips, speed = _leg_quality(stage, out, a, times, CC_LEGS, 60.0, unlocked=free)
    assert bones < 1e-4 and flips == 0 and speed < 1.5
    assert all(c["residual"] < 1e-6 for c in result.report.constraints)


@pytest.mark.skipif(not MOCAP.exists(), reason="needs ../shared/mocap")
def test_two_real_walkers_crossing_with_avoidance_keep_their_feet(tmp_path):
    """Two CMU walks crossing at right angles at their middles, parted by collision avoidance:
    each keeps its feet within 0.5 cm/s of its source, bones and knees as they were. Carried
    rigidly along the parted paths their feet slide about 0.5 cm/s more than the source's;
    pivoting on the planted feet takes that away before locking. (Weighted per frame as at
    24 fps, these 60 fps takes stepped aside over 2.5 times fewer seconds: carried rigidly they
    slid 3 cm/s more, and 0.4 to 0.7 after pivoting.)"""
    stage, _ = _imported_shot(tmp_path, "cc_cmu07_01_walk")
    stage.GetRootLayer().subLayerPaths = []
    names = [f"{CROWD}/a", f"{CROWD}/b"]
    for p in names:
        stage.DefinePrim(p).GetReferences().AddReference("./clip.usda")
    times, hips = evaluate.joint_world_matrices(stage, names[0])
    middle = hips[len(times) // 2, 3, :3] * np.array([1.0, 0.0, 1.0])
    turned = UsdGeom.Xformable(stage.GetPrimAtPath(names[1]))
    turned.AddTranslateOp().Set(Gf.Vec3d(*map(float, middle)))
    turned.AddRotateYOp().Set(90.0)
    turned.AddTranslateOp(opSuffix="back").Set(Gf.Vec3d(*map(float, -middle)))
    stage.GetRootLayer().Save()
    rigid, _ = _solve(tmp_path, "rigid", collisions=True, pivot_on_feet=False)
    _, free = _solve(tmp_path, "free", foot_locking=False, collisions=True)
    result, out = _solve(tmp_path, collisions=True)
    assert result.report.stats["remainingOverlaps"] == 0
    for a in names:
        entry = result.report.agents[a]
        assert rigid.report.agents[a]["footSkateUnlocked"] > entry["footSkateSource"] + 0.3   # avoidance slid the feet
        assert entry["footSkateUnlocked"] < rigid.report.agents[a]["footSkateUnlocked"] - 0.4
        assert entry["footSkateUnlocked"] <= entry["footSkateSource"] + 0.1
        assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.5       # cm/s
        bones, flips, speed = _leg_quality(stage, out, a, times, CC_LEGS, 60.0, unlocked=free)
        assert bones < 1e-4 and flips == 0 and speed < 1.5


def test_the_solvers_plant_placement_and_kinematics_jobs_match_numpy(tmp_path, monkeypatch, walk_clip):
    """Every call foot locking makes to the solver's FootPlantJob, PlacementJob and
    SkeletonSpaceJob, on a dragged stand (steps) and a bent walk,
    gives what their numpy versions give."""
    calls = {"plan": [], "place": [], "fk": []}

    def spy(kind, fn):
        def wrapped(*args, **kwargs):
            out = fn(*args, **kwargs)
            calls[kind].append((args, kwargs, out))
            return out
        return wrapped

    from mocapedit.geometry import kinematics
    monkeypatch.setattr(footplant, "plan_feet", spy("plan", footplant.plan_feet))
    monkeypatch.setattr(footplant, "place", spy("place", footplant.place))
    monkeypatch.setattr(kinematics, "skeleton_space", spy("fk", kinematics.skeleton_space))
    _dragged_stand(tmp_path)
    assert _solve(tmp_path, "stand")[0].report.stats["footSteps"] >= 4
    bent = tmp_path / "bent"
    bent.mkdir()
    _bent_path_stage(bent, walk_clip)
    _solve(bent)
    assert len(calls["plan"]) >= 2 and calls["place"] and len(calls["fk"]) >= 2
    for (inputs,), _, fast in calls["plan"]:
        slow = footplant.plan_feet_numpy(inputs)
        for name in ("target", "target_rot", "weight"):
            np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), atol=1e-9, err_msg=name)
        np.testing.assert_array_equal(fast.stepping, slow.stepping)
        np.testing.assert_array_equal(fast.steps, slow.steps)
    assert any(fast.steps.sum() for _, _, fast in calls["plan"])
    # Feet that step at a shorter leash than their plants may lie at (LOOSER's last step).
    for (inputs,), _, _ in list(calls["plan"]):
        held = dataclasses.replace(inputs, reach_leash=np.full_like(inputs.reach_leash, 5.0 / 3.0),
                                   step_leash=np.ones_like(inputs.step_leash))
        fast, slow = footplant.plan_feet(held), footplant.plan_feet_numpy(held)
        for name in ("target", "target_rot", "weight"):
            np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), atol=1e-9, err_msg=name)
        np.testing.assert_array_equal(fast.stepping, slow.stepping)
        np.testing.assert_array_equal(fast.steps, slow.steps)
    for args, _, fast in calls["place"]:
        for a, b in zip(fast, footplant.place_numpy(*args)):
            np.testing.assert_allclose(a, b, atol=1e-12)
    for args, _, fast in calls["fk"]:
        matrices = fast[0] if isinstance(fast, tuple) else fast
        slow = kinematics.skeleton_space_numpy(*args[:7])
        np.testing.assert_allclose(matrices, slow, atol=1e-12)
        if isinstance(fast, tuple):
            rot = trs_from_matrices(slow)[1]
            np.testing.assert_allclose(fast[1], rot, atol=1e-6)
    # Bad arrays are named.
    inputs = calls["plan"][0][0][0]
    with pytest.raises(ValueError, match="stretch"):
        footplant.plan_feet(dataclasses.replace(inputs, stretch=np.zeros_like(inputs.stretch)))
    args = calls["place"][0][0]
    with pytest.raises(ValueError, match="up must be a unit vector"):
        footplant.place(*args[:4], 2.0 * args[4], *args[5:])
    args = calls["fk"][0][0]
    with pytest.raises(ValueError, match="parent must precede"):
        kinematics.skeleton_space(np.arange(len(args[0])), *args[1:7])


def test_easing_into_a_contact_pulls_a_foot_no_further_than_the_leash():
    """A standing agent dragged fast by avoidance swings its foot far from its next plant: easing
    towards the plant from there (85 cm, a CMU crowd) sank the pelvis 60 cm for the leg to reach.
    While a foot eases in or out, the lock pulls it at most MAX_LEASH_M from where the edit puts
    it; locked poses (weight 1) and free ones (weight 0) are left alone."""
    from types import SimpleNamespace
    from mocapedit.pipeline.passes import feet
    weight = np.array([[0.0, 0.2], [0.5, 0.45], [1.0, 0.9], [0.3, 1.0]])
    ankle = np.zeros((4, 2, 3))
    target = np.zeros((4, 2, 3))
    target[:, 0, 0] = [50.0, 50.0, 50.0, 10.0]     # centimetres from the ankle
    target[:, 1, 2] = [85.0, 64.0, 30.0, 85.0]
    run = SimpleNamespace(weight=weight.copy(), target=target, ankle=ankle, offsets=np.array([0, 4]),
                          span=lambda a: (0, 4), ctx=SimpleNamespace(data=SimpleNamespace(info=SimpleNamespace(meters_per_unit=0.01))))
    feet._Run._ease_within_leash(run, 0)
    pull = run.weight * np.linalg.norm(target - ankle, axis=-1)
    easing = (weight > 0) & (weight < 1)
    assert np.all(pull[easing] <= feet.MAX_LEASH_M * 100 + 1e-9)
    np.testing.assert_array_equal(run.weight[~easing], weight[~easing])
    np.testing.assert_allclose(run.weight[3, 0], 0.3)                 # within the leash already
    np.testing.assert_allclose(run.weight[1, 1], 15.0 / 64.0)


def _ankle_twist(local: np.ndarray, ankle: int) -> np.ndarray:
    """(T,) degrees the ankle's local rotation turns the foot about the shin (its bone axis)."""
    axis = local[:, ankle, 3, :3] / np.linalg.norm(local[:, ankle, 3, :3], axis=1, keepdims=True)
    q = trs_from_matrices(local[:, ankle])[1].astype(np.float64)
    return np.degrees(2.0 * np.arctan2(np.sum(q[:, :3] * axis, axis=1), q[:, 3]))


def _walk_with_handles(tmp_path, handles: dict[int, tuple[float, float]]) -> str:
    """A 4 s generated walk at 1.25 m/s on a Y-up metre stage, with a hard position handle at each
    frame of ``handles`` (ground x, z); the agent's path."""
    clip = walker.walk(frames=97, fps=FPS, speed=1.25, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    for frame, (x, z) in handles.items():
        examples.add_position_constraint(stage, f"/Edits/at{frame}", a, frame, (x, 0.0, z))
    stage.GetRootLayer().Save()
    return a


def test_a_leg_turns_at_the_hip_with_its_planted_foot(tmp_path):
    """A walk dodging 1 m aside within 4 m turns its body over its planted feet. Each locked
    leg turns at the hip with its foot: the foot keeps its turn against the shin as in the
    source. Left turned with the body, the shin turned over the planted foot and twisted the
    ankle about the shin by 11.7 degrees more than the source's."""
    a = _walk_with_handles(tmp_path, {0: (0.0, 0.0), 48: (1.0, 2.5), 96: (0.0, 5.0)})
    result, out = _solve(tmp_path)
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    times = evaluate.sample_times(src, a)
    _, local0, joints = _fk(src, a, times)
    _, local1, _ = _fk(out, a, times)
    for name in ("LeftFoot", "RightFoot"):
        j = next(i for i, n in enumerate(joints) if n.endswith("/" + name))
        change = (_ankle_twist(local1, j) - _ankle_twist(local0, j) + 180.0) % 360.0 - 180.0
        assert np.abs(change).max() < 6.0, name
    entry = result.report.agents[a]
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS)
    assert bones < 1e-6 and flips == 0 and speed < 1.5


@pytest.mark.parametrize("corner, end", [((0.0, 2.5), (2.5, 2.5)), ((0.0, 2.5), (2.5, 1.5)), ((0.0, 2.5), (1.5, 2.5))])
def test_a_walk_turned_at_a_corner_keeps_its_planted_feet(tmp_path, corner, end):
    """A walk sent 2.5 m ahead and then round a corner by three handles turns its body by up to
    45 degrees over one planted foot. The plant lags the body's turn by up to LEASH_DEGREES and
    the leg turns at the hip with it; beyond that the plant turns along, about the ankle, and the
    toes slide. Lagging 15 degrees at most, the feet slid +0.53, +1.17 and +0.69 cm/s over the
    source's (the bar is +0.5); lagging 25, +0.00, +0.27 and +0.13."""
    a = _walk_with_handles(tmp_path, {0: (0.0, 0.0), 48: corner, 96: end})
    result, out = _solve(tmp_path)
    _, free = _solve(tmp_path, name="free", foot_locking=False)
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    figures = measure.plausibility(src, out, a)
    assert figures.foot_skate_edited <= figures.foot_skate_source + 0.004    # 0.4 cm/s, metres
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    bones, flips, speed = _leg_quality(src, out, a, evaluate.sample_times(src, a), LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.5


@pytest.mark.parametrize("corner, end", [((0.0, 2.5), (2.5, 2.5)), ((0.0, 2.5), (1.5, 2.5))])
def test_an_agent_whose_feet_still_slide_lets_its_plants_lag_the_turn_further(tmp_path, monkeypatch, corner, end):
    """An agent whose locked feet still slide over the bar is locked again with its plants
    lagging the body's turn further (LOOSER, in turn), and keeps that where its feet slide less
    and its legs turn no faster. With the plants lagging 10 degrees at most, the
    walks turned at a corner slide +0.93 and +0.61 cm/s over their source's; lagging further
    where they slide, +0.19 and -0.28 (the CMU crowds: a walker turned hard as it stops, +1.47 ->
    +0.68; one whose held pose avoidance moved, +3.17 -> +1.44)."""
    from mocapedit.pipeline.passes import feet
    monkeypatch.setattr(feet, "LEASH_DEGREES", 10.0)
    a = _walk_with_handles(tmp_path, {0: (0.0, 0.0), 48: corner, 96: end})
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    result, out = _solve(tmp_path)
    _, free = _solve(tmp_path, name="free", foot_locking=False)
    figures = measure.plausibility(src, out, a)
    assert figures.foot_skate_edited <= figures.foot_skate_source + 0.002    # 0.2 cm/s, metres
    bones, flips, speed = _leg_quality(src, out, a, evaluate.sample_times(src, a), LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.45
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    # Without the second try, over the bar.
    monkeypatch.setattr(feet, "_loosen_where_sliding", lambda run, legs, skates: skates)
    _, plain = _solve(tmp_path, name="plain")
    assert measure.plausibility(src, plain, a).foot_skate_edited > figures.foot_skate_source + 0.005


def test_a_standing_agent_whose_feet_still_slide_lets_its_plants_lie_further(tmp_path, monkeypatch):
    """An idle dragged 50 cm aside and back within 4 s by handles: with its plants no further
    than MAX_LEASH_M from where the edit puts its feet, they slid 7.5 cm/s (its source's do not
    slide). Its plants may then lie further, as far as its legs reach (LOOSER's last step): it
    stands and sways its hips over its feet, which slide no more than the source's."""
    from mocapedit.pipeline.passes import feet
    clip = walker.idle(frames=96, fps=FPS, name="idle")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    p = clip.translations[:, 0]
    for k, frame in enumerate((0, 48, 95)):
        examples.add_position_constraint(stage, f"/Edits/h{k}", a, frame,
                                         (float(p[frame][0]) + (0.5 if k == 1 else 0.0), 0.0, float(p[frame][2])))
    stage.GetRootLayer().Save()
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    times = evaluate.sample_times(src, a)
    result, out = _solve(tmp_path)
    figures = measure.plausibility(src, out, a)
    assert figures.foot_skate_edited <= figures.foot_skate_source + 0.002
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    _, free = _solve(tmp_path, name="free", foot_locking=False)
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0
    # Without that step, over the bar, and the legs turning faster.
    monkeypatch.setattr(feet, "LOOSER", tuple(step for step in feet.LOOSER if step[1] == 1.0))
    _, plain = _solve(tmp_path, name="plain")
    assert measure.plausibility(src, plain, a).foot_skate_edited > figures.foot_skate_source + 0.05
    assert _leg_quality(src, plain, a, times, LEGS, FPS, unlocked=free)[2] > speed


def test_a_walk_pushed_aside_at_its_start_eases_its_locks_in_over_longer(tmp_path, monkeypatch):
    """A walk pushed 1 m aside within half a second of its start (by a handle) swings each foot
    far from its next plant. Easing in over 0.1 s, the lock turned a hip 1.57 times as fast as
    the source ever does (the bar is 1.5). An agent whose locked legs turn faster than
    STEP_SPEED_RATIO times its pose eases in and out over longer, and keeps that where its legs
    turn slower with it. (Measured without the looser plants of LOOSER, which lower the skate of
    either ease by as much as they can.)"""
    from mocapedit.pipeline.passes import feet
    monkeypatch.setattr(feet, "LOOSER", ())
    a = _walk_with_handles(tmp_path, {0: (0.0, 0.0), 12: (1.0, 0.625), 96: (0.0, 5.0)})
    result, out = _solve(tmp_path)
    _, free = _solve(tmp_path, name="free", foot_locking=False)
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    bones, flips, speed = _leg_quality(src, out, a, evaluate.sample_times(src, a), LEGS, FPS, unlocked=free)
    assert bones < 1e-6 and flips == 0 and speed < 1.45
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    # The feet slide no more for it than easing in quickly let them.
    monkeypatch.setattr(feet, "BLEND_ROUNDS", 0)
    quick, _ = _solve(tmp_path, name="quick")
    assert result.report.agents[a]["footSkateEdited"] <= quick.report.agents[a]["footSkateEdited"] + 1e-4


def test_an_idle_dragged_aside_and_back_shuffles_at_a_calm_pace(tmp_path):
    """A generated idle (feet planted throughout, legs nearly still: its knees turn at 0.12 rad/s
    at most) dragged 60 cm aside at its middle and back by three handles over 10 s. Held to the
    idle's own leg speeds no step could be taken: the feet slid 5.5 cm/s over the source's. A
    leg the source holds still steps at a calm pace at least (STEP_MIN_FOOT_SPEED_M,
    STEP_MIN_TURN_SPEEDS): the feet shuffle, one at a time, and slide no more than the bar."""
    from mocapedit.pipeline.passes import feet
    clip = walker.idle(frames=240, fps=FPS, name="idle")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    for name, frame, dx in (("start", 0, 0.0), ("aside", 120, 0.6), ("end", 239, 0.0)):
        p = clip.translations[frame, 0]
        examples.add_position_constraint(stage, f"/Edits/{name}", a, frame, (float(p[0]) + dx, 0.0, float(p[2])))
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path)
    _, free = _solve(tmp_path, name="free", foot_locking=False)
    entry = result.report.agents[a]
    assert entry.get("footSteps", 0) >= 4
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    times = evaluate.sample_times(src, a)
    feet_at = ["LeftFoot", "RightFoot"]
    lift = (evaluate.foot_positions(out, a, times, feet_at).positions[..., 1]
            - evaluate.foot_positions(src, a, times, feet_at).positions[..., 1])
    assert not ((lift[:, 0] > 0.02) & (lift[:, 1] > 0.02)).any()
    bones, flips, speed = _leg_quality(src, out, a, times, LEGS, FPS, unlocked=free, least=feet.STEP_MIN_TURN_SPEEDS)
    assert bones < 1e-6 and flips == 0 and speed < 1.5


def test_turn_speed_of_many_joints_at_once_is_each_joints_own():
    """The leg checks measure every hip, knee and ankle of a run of agents in one call: each joint's
    speeds are those it gets alone (radians per second between uneven samples)."""
    rng = np.random.default_rng(11)
    seconds = np.cumsum(rng.uniform(1 / 60, 1 / 24, 30))
    q = rng.normal(size=(30, 3, 2, 4))
    both = footplant.turn_speed(q, seconds)
    assert both.shape == (29, 3, 2)
    for i in range(3):
        for k in range(2):
            np.testing.assert_array_equal(both[:, i, k], footplant.turn_speed(q[:, i, k], seconds))
    # A quarter turn about up over one interval, then still.
    half = np.radians(45.0)
    turning = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, np.sin(half), np.cos(half)],
                        [0.0, 0.0, np.sin(half), np.cos(half)]])
    np.testing.assert_allclose(footplant.turn_speed(turning, np.array([0.0, 0.5, 1.0])), [np.pi, 0.0], atol=1e-12)
