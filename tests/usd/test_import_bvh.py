"""BVH import end to end: the written USD, read back by UsdSkel forward kinematics, puts
every joint where an independent BVH implementation (bvhio) does, on every frame."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel

from mocapedit.formats import bvh
from mocapedit.usd import bvh_usd, reader
from mocapedit.geometry import trajectory
from mocapedit.data import walker
from mocapedit.usd.bvh_usd import ImportSettings

from bvh_reference import REAL_MOCAP, world_positions
from bvhgen import random_motion, random_rig, walk_idle_walk, walker_rig, write_bvh
from conftest import run_cli, world_joints

TOLERANCE = 1e-4   # in the clip's own length unit


def _to_bvh_frame(points: np.ndarray, up_axis: str, scale: float) -> np.ndarray:
    """Stage positions back to the BVH's Y-up frame and unit."""
    p = points / scale
    return p if up_axis == "Y" else np.stack([p[..., 0], p[..., 2], -p[..., 1]], -1)


def _imported_world(path, settings: ImportSettings, out) -> np.ndarray:
    result = bvh_usd.import_bvh(path, out, settings)
    stage = Usd.Stage.Open(str(out))
    joints = world_joints(stage, result.skeleton, range(result.frames))
    return _to_bvh_frame(joints, settings.up_axis, settings.scale)


CASES = {
    # name: (seed, joints, frames, up axis, scale, share of six-channel joints, frame time, newline)
    "mixed-orders-y-up": (11, 24, 90, "Y", 1.0, 0.25, "0.0166667", "\n"),
    "z-up-scaled": (12, 40, 50, "Z", 0.37, 0.1, ".0333333", "\r\n"),
    "three-channel-body": (13, 31, 120, "Y", 5.644, 0.0, ".0083333", "\r\n"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_world_joints_match_bvhio_on_every_frame_of_written_files(tmp_path, case):
    seed, joints, frames, up, scale, six, frame_time, newline = CASES[case]
    rng = np.random.default_rng(seed)
    rig = random_rig(rng, joints, six_channel_share=six)
    # The root and one inner joint spin by more than 360 degrees.
    values = random_motion(rng, rig, frames, spin_joints=(0, joints // 2), spin_degrees=900.0)
    path = tmp_path / f"{case}.bvh"
    write_bvh(path, rig, values, frame_time=frame_time, newline=newline)

    names, expect = world_positions(path)
    assert names == rig.names and expect.shape == (frames, joints, 3)
    settings = ImportSettings(scale=scale, up_axis=up, agent=True, position_mode="absolute")
    got = _imported_world(path, settings, tmp_path / f"{case}.usda")
    err = np.abs(got - expect).max()
    assert err < TOLERANCE, f"largest joint position error {err:.2e} in BVH units"
    # The spins are stored without a quaternion sign flip between neighbouring frames.
    stage = Usd.Stage.Open(str(tmp_path / f"{case}.usda"))
    rotations = stage.GetPrimAtPath(f"/{case.replace('-', '_')}/Skel/Anim").GetAttribute("rotations")
    rot = np.array([np.asarray(rotations.Get(t)) for t in range(frames)])
    assert np.sum(rot[1:] * rot[:-1], axis=-1).min() > 0


def test_an_importer_fault_shows_against_bvhio(tmp_path, monkeypatch):
    """The comparison above can fail: a wrong Euler order (reversed) is caught."""
    rng = np.random.default_rng(14)
    rig = random_rig(rng, 8, six_channel_share=0.0)
    path = tmp_path / "f.bvh"
    write_bvh(path, rig, random_motion(rng, rig, 10))
    _, expect = world_positions(path)
    original = bvh.Converter.__init__

    def reversed_order(self, skeleton, *args, **kwargs):
        skeleton.channels = [tuple(reversed(c)) for c in skeleton.channels]
        original(self, skeleton, *args, **kwargs)

    monkeypatch.setattr(bvh.Converter, "__init__", reversed_order)
    got = _imported_world(path, ImportSettings(agent=True, position_mode="absolute"), tmp_path / "f.usda")
    assert np.abs(got - expect).max() > 1.0


def test_the_clip_layer_sets_units_rate_and_layout(tmp_path):
    rig, values, _ = walk_idle_walk(fps=50.0, walk1=1.0, idle=1.0, walk2=1.0)
    write_bvh(tmp_path / "walk idle.bvh", rig, values, frame_time="0.02")
    out = tmp_path / "clip.usda"
    result = bvh_usd.import_bvh(tmp_path / "walk idle.bvh", out, ImportSettings(
        scale=1.0, meters_per_unit=0.01, up_axis="Z", agent=True, root_joint="Hips", hip_joint="Hips"))
    assert result.prim == "/walk_idle" and result.fps == 50.0 and result.frames == len(values)
    assert 1.5 < result.height_m < 2.0
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01 and UsdGeom.GetStageUpAxis(stage) == "Z"
    assert stage.GetTimeCodesPerSecond() == 50.0 and stage.GetFramesPerSecond() == 50.0
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == len(values) - 1
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/walk_idle")
    agent = stage.GetPrimAtPath("/walk_idle")
    assert agent.IsA(UsdSkel.Root) and "MocapAgentAPI" in agent.GetAppliedSchemas()
    assert agent.GetAttribute("mocap:rootJoint").Get() == "Hips"
    assert (result.skeleton, result.animation) == ("/walk_idle/Skel", "/walk_idle/Skel/Anim")
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/walk_idle/Skel"))
    assert list(skel.GetJointsAttr().Get())[:3] == ["Hips", "Hips/Spine", "Hips/Spine/Chest"]
    assert len(skel.GetRestTransformsAttr().Get()) == len(rig.names)
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/walk_idle/Skel/Anim"))
    assert UsdSkel.BindingAPI(skel).GetAnimationSourceRel().GetTargets() == [anim.GetPath()]
    assert anim.GetRotationsAttr().GetNumTimeSamples() == len(values)
    assert anim.GetTranslationsAttr().GetNumTimeSamples() == len(values)
    assert len(anim.GetScalesAttr().Get()) == len(rig.names)
    meta = Sdf.Layer.FindOrOpen(str(out)).customLayerData["mocapedit"]["bvh"]
    assert meta["source"] == "walk idle.bvh" and meta["positionChannels"] == {"Hips": "absolute"}
    # The reader takes the file as a stage with one agent and one clip.
    data = reader.read_stage(stage)
    assert list(data.agents) == ["/walk_idle"]
    assert data.agents["/walk_idle"].frame_count == len(values)
    # Quaternions are stored sign-continuous.
    rot = np.array([np.asarray(anim.GetRotationsAttr().Get(t)) for t in range(len(values))])
    assert np.sum(rot[1:] * rot[:-1], axis=-1).min() > 0


def test_a_clip_without_agent_plays_when_referenced_into_a_skelroot(tmp_path):
    rng = np.random.default_rng(15)
    rig = random_rig(rng, 10)
    write_bvh(tmp_path / "c.bvh", rig, random_motion(rng, rig, 20))
    bvh_usd.import_bvh(tmp_path / "c.bvh", tmp_path / "c.usda", ImportSettings(position_mode="absolute"))
    clip = Usd.Stage.Open(str(tmp_path / "c.usda"))
    assert clip.GetDefaultPrim().GetPath() == Sdf.Path("/Skel") and clip.GetPrimAtPath("/Skel/Anim")
    # Referenced the way mocapedit.data.examples references its clip layers into agents.
    shot = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    UsdGeom.SetStageMetersPerUnit(shot, 0.01)
    shot.SetTimeCodesPerSecond(clip.GetTimeCodesPerSecond())
    UsdSkel.Root.Define(shot, "/agent")
    shot.DefinePrim("/agent/Skel").GetReferences().AddReference("c.usda")
    shot.GetRootLayer().Save()
    _, expect = world_positions(tmp_path / "c.bvh")
    got = world_joints(shot, "/agent/Skel", range(20))
    assert np.abs(got - expect).max() < TOLERANCE


def _real_clips():
    if not REAL_MOCAP.is_dir():
        return [pytest.param(None, marks=pytest.mark.skip(reason="../shared/mocap is not present"))]
    return sorted(p.name for p in REAL_MOCAP.glob("*.bvh"))


@pytest.mark.slow
@pytest.mark.realdata
@pytest.mark.parametrize("name", _real_clips())
def test_real_clips_match_bvhio_on_every_frame(tmp_path, name):
    path = REAL_MOCAP / name
    names, expect = world_positions(path)
    skeleton = bvh.read_header(path)
    assert names == skeleton.names
    got = _imported_world(path, ImportSettings(agent=True, position_mode="absolute"), tmp_path / "a.usda")
    err = np.abs(got - expect).max()
    assert err < TOLERANCE, f"{name}: largest joint position error {err:.2e} in BVH units"

    # The automatic reading differs only where the file moves its root about the OFFSET:
    # a hip-rooted rig stands on the ground instead of sinking by its hip height.
    auto = bvh_usd.import_bvh(path, tmp_path / "b.usda", ImportSettings(agent=True))
    got_auto = world_joints(Usd.Stage.Open(str(tmp_path / "b.usda")), auto.skeleton, range(auto.frames))
    shift = np.zeros(3)
    if auto.position_modes.get(skeleton.names[0]) == "relative":
        shift = skeleton.offsets[0]
        assert name.startswith("cc_") and skeleton.names[0] == "CC_Base_Hip"
    else:
        assert skeleton.names[0] in ("RL_BoneRoot", "Hips")
    assert np.abs(got_auto - (expect + shift)).max() < TOLERANCE
    # Feet on the ground: the lowest joint of the clip is near height zero (within 15 cm).
    unit_m = bvh.UNITS["cmu"] if name.startswith("cmu") else 0.01
    assert abs(got_auto[..., 1].min()) * unit_m < 0.15


def test_cli_converts_one_file_and_a_folder(tmp_path):
    rng = np.random.default_rng(16)
    src = tmp_path / "clips"
    src.mkdir()
    for k in range(3):
        rig = random_rig(rng, 6)
        write_bvh(src / f"clip{k}.bvh", rig, random_motion(rng, rig, 8))
    (src / "notes.txt").write_text("not a clip")
    one = run_cli("import-bvh", src / "clip0.bvh", "-o", tmp_path / "one.usdc", "--unit", "cmu",
                  "--meters-per-unit", "1", "--up", "Z", "--fps", "24", "--agent", "--root-joint", "joint0")
    assert one.returncode == 0, one.stderr
    assert "wrote" in one.stderr and "import clip0.bvh" in one.stderr
    stage = Usd.Stage.Open(str(tmp_path / "one.usdc"))
    assert stage.GetTimeCodesPerSecond() == 24 and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetPrimAtPath("/clip0").GetAttribute("mocap:rootJoint").Get() == "joint0"
    scale = Sdf.Layer.FindOrOpen(str(tmp_path / "one.usdc")).customLayerData["mocapedit"]["bvh"]["scale"]
    assert scale == pytest.approx(0.0254 / 0.45)

    many = run_cli("import-bvh", src, "-o", tmp_path / "out", "-q")
    assert many.returncode == 0, many.stderr
    assert many.stderr == "" and many.stdout == ""
    assert sorted(os.listdir(tmp_path / "out")) == ["clip0.usda", "clip1.usda", "clip2.usda"]
    # An output without a USD extension is a folder, even for one file.
    folder = run_cli("import-bvh", src / "clip1.bvh", "-o", tmp_path / "single", "--ext", ".usdc", "-q")
    assert folder.returncode == 0, folder.stderr
    assert os.listdir(tmp_path / "single") == ["clip1.usdc"]


def test_cli_writes_nothing_for_a_malformed_file(tmp_path):
    rng = np.random.default_rng(17)
    rig = random_rig(rng, 5)
    write_bvh(tmp_path / "good.bvh", rig, random_motion(rng, rig, 6))
    text = (tmp_path / "good.bvh").read_text().splitlines()
    text[-2] = " ".join(text[-2].split()[:-1])          # a row with one value missing
    (tmp_path / "bad.bvh").write_text("\n".join(text) + "\n")
    bad_line = len(text) - 1

    single = run_cli("import-bvh", tmp_path / "bad.bvh", "-o", tmp_path / "bad.usda")
    assert single.returncode == 1
    assert f"bad.bvh:{bad_line}: frame row has too few values" in single.stderr
    assert not (tmp_path / "bad.usda").exists()

    batch = run_cli("import-bvh", tmp_path / "good.bvh", tmp_path / "bad.bvh", "-o", tmp_path / "out")
    assert batch.returncode == 1 and f"bad.bvh:{bad_line}:" in batch.stderr
    assert not (tmp_path / "out").exists(), "all or nothing: neither the good file nor the folder for it"

    going = run_cli("import-bvh", tmp_path / "good.bvh", tmp_path / "bad.bvh", "-o", tmp_path / "out",
                    "--keep-going")
    assert going.returncode == 1 and "wrote 1 of 2 clips" in going.stderr
    assert os.listdir(tmp_path / "out") == ["good.usda"]

    empty = (tmp_path / "good.bvh").read_text().split("MOTION")[0] + "MOTION\nFrames: 0\nFrame Time: 0.04\n"
    (tmp_path / "empty.bvh").write_text(empty)
    nothing = run_cli("import-bvh", tmp_path / "empty.bvh", "-o", tmp_path / "x.usda")
    frames_line = empty.count("\n") - 1
    assert nothing.returncode == 1 and f"empty.bvh:{frames_line}: 'Frames: 0'" in nothing.stderr

    missing = run_cli("import-bvh", tmp_path / "good.bvh", "-o", tmp_path / "x.usda", "--root-joint", "Pelvis")
    assert missing.returncode == 1 and "root joint 'Pelvis' is not a joint" in missing.stderr
    assert not (tmp_path / "x.usda").exists()


def test_the_trajectory_of_an_imported_walk_follows_the_bvh_root(tmp_path):
    rig, values, _ = walk_idle_walk()
    write_bvh(tmp_path / "w.bvh", rig, values)
    result = bvh_usd.import_bvh(tmp_path / "w.bvh", tmp_path / "w.usda",
                                ImportSettings(agent=True, up_axis="Z", scale=1.0))
    data = reader.read_stage(Usd.Stage.Open(str(tmp_path / "w.usda")))
    agent = data.agents[result.prim]
    traj = trajectory.extract(agent, data.clip_of(agent), "Z", 0.01)
    # BVH (x, z) on the Y-up ground is (x, -z)... turned Z-up: ground (x, y) = (x, -z).
    np.testing.assert_allclose(traj.ground, np.stack([values[:, 0], -values[:, 2]], 1), atol=1e-4)


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_the_procedural_walker_through_bvh_comes_back_joint_for_joint(tmp_path, up):
    """Walker clip -> BVH text -> import: UsdSkel FK on the result equals the walker's own FK."""
    clip, _ = walker.walk_idle_walk(frames=96, fps=24.0, up=up, meters_per_unit=0.01)
    rig, values = walker_rig(clip)
    write_bvh(tmp_path / "walker.bvh", rig, values, frame_time="0.0416667", digits=9)
    result = bvh_usd.import_bvh(tmp_path / "walker.bvh", tmp_path / "walker.usda",
                                ImportSettings(agent=True, position_mode="absolute", up_axis="Y"))
    assert result.fps == 24.0 and result.frames == 96
    got = world_joints(Usd.Stage.Open(str(tmp_path / "walker.usda")), result.skeleton, range(96))
    expect = walker.joint_world_positions(clip)
    assert np.abs(got - expect).max() < TOLERANCE


LYING_REST_POSE = Path(__file__).parents[1] / "lying_rest_pose.bvh"


@pytest.mark.parametrize("up_axis", ["Y", "Z"])
def test_the_height_is_measured_in_frame_0_not_in_the_rest_pose(tmp_path, up_axis):
    # The rest pose lies along the ground (every OFFSET along Z); frame 0 turns the root
    # upright, so the character stands 30 + 50 + 90 + 5 cm tall.
    path = LYING_REST_POSE
    result = bvh_usd.build_clip(path, ImportSettings(scale=0.01, meters_per_unit=1.0, up_axis=up_axis,
                                                     end_sites=True))
    assert result.height_m == pytest.approx(1.75, abs=1e-5)
    proc = run_cli("import-bvh", path, "-o", tmp_path / "lying.usda", "--unit", "cm", "--end-sites")
    assert proc.returncode == 0, proc.stderr
    assert "1.75 m tall" in proc.stderr and "note" not in proc.stderr
