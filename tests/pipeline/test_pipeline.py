"""Foundation end to end: read a stage, write an edits layer, compose, compare with UsdSkel."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, Vt

import mocapedit
from mocapedit.usd import reader
from mocapedit.data import examples, walker
from mocapedit.geometry import trajectory
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve
from mocapedit.usd import evaluate

from conftest import TOY_JOINTS, run_cli, world_joints, write_toy_stage


def test_solve_without_edits_writes_a_layer_that_plays_the_source(tmp_path, toy_stage):
    edits, composed = tmp_path / "shot.edits.usda", tmp_path / "shot.composed.usda"
    result = solve(str(toy_stage), output=str(edits), composed=str(composed))
    assert result.report.stats["agents"] == 3
    assert result.report.stats["editedAgents"] == 0

    layer = Sdf.Layer.FindOrOpen(str(edits))
    assert layer.GetPrimAtPath("/MocapEdit/Guides/SourcePaths")
    assert not layer.GetPrimAtPath("/World"), "agents without edits must not be written"
    meta = layer.customLayerData["mocapedit"]
    assert meta["inputs"][0].endswith("shot.usda")
    assert len(meta["contentHash"]) == 64

    src = Usd.Stage.Open(str(toy_stage))
    out = Usd.Stage.Open(str(composed))
    assert out.GetTimeCodesPerSecond() == src.GetTimeCodesPerSecond()
    assert UsdGeom.GetStageUpAxis(out) == UsdGeom.GetStageUpAxis(src)
    times = np.arange(48)
    for k in range(3):
        a = world_joints(src, f"/World/agent{k}/Skel", times)
        b = world_joints(out, f"/World/agent{k}/Skel", times)
        np.testing.assert_allclose(b, a, atol=1e-6)
    assert out.GetPrimAtPath("/MocapEdit/Guides/SourcePaths").GetAttribute("purpose").Get() == "guide"


def test_same_input_gives_the_same_bytes(tmp_path, toy_stage):
    a, b = tmp_path / "a.usda", tmp_path / "b.usda"
    solve(str(toy_stage), output=str(a))
    solve(str(toy_stage), output=str(b))
    assert hashlib.sha256(a.read_bytes()).digest() == hashlib.sha256(b.read_bytes()).digest()


def test_the_input_is_never_modified(tmp_path, toy_stage):
    before = toy_stage.read_bytes()
    solve(str(toy_stage), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert toy_stage.read_bytes() == before


@pytest.mark.parametrize("up_axis,mpu", [("Z", 0.01), ("Y", 1.0)])
def test_reader_trajectory_matches_usdskel_root_positions(tmp_path, up_axis, mpu):
    path = write_toy_stage(tmp_path / "s.usda", up_axis=up_axis, meters_per_unit=mpu)
    stage = Usd.Stage.Open(str(path))
    data = reader.read_stage(stage)
    assert data.info.up_axis == up_axis and data.info.meters_per_unit == mpu
    for k in range(3):
        agent = data.agents[f"/World/agent{k}"]
        traj = trajectory.extract(agent, data.clip_of(agent), up_axis, mpu)
        world = world_joints(stage, agent.skeleton_path, agent.sample_times)[:, 0]
        expect_uv = np.stack([world[:, 0], world[:, 1]] if up_axis == "Z" else [world[:, 0], -world[:, 2]], -1)
        np.testing.assert_allclose(traj.ground, expect_uv, atol=1e-4)
        # The agent prim's yaw turns the whole path: the first heading follows it.
        uv = traj.ground
        expect = np.arctan2(uv[1, 1] - uv[0, 1], uv[1, 0] - uv[0, 0])
        assert traj.heading[0] == pytest.approx(expect, abs=1e-9)
    assert data.agents["/World/agent0"].collision_radius == pytest.approx(0.3 / mpu)


def test_clip_referenced_with_a_layer_offset_keeps_its_frames(tmp_path):
    clip = write_toy_stage(tmp_path / "clip.usda", agents=1)
    shot = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    UsdGeom.SetStageUpAxis(shot, "Z")
    UsdGeom.SetStageMetersPerUnit(shot, 0.01)
    shot.SetTimeCodesPerSecond(24)
    for k, offset in enumerate([0.0, 10.0, 25.5]):
        prim = shot.DefinePrim(f"/Shot/a{k}")
        prim.GetReferences().AddReference(str(clip), "/World/agent0", Sdf.LayerOffset(offset))
    shot.GetRootLayer().Save()
    data = reader.read_stage(Usd.Stage.Open(str(tmp_path / "shot.usda")))
    assert len(data.agents) == 3
    assert len(data.clips) == 1, "a clip shared by many agents is read once"
    for k, offset in enumerate([0.0, 10.0, 25.5]):
        np.testing.assert_allclose(data.agents[f"/Shot/a{k}"].sample_times, np.arange(48) + offset)


def test_named_root_joint_and_hip_projection(tmp_path):
    path = write_toy_stage(tmp_path / "s.usda", agents=1)
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/World/agent0")
    prim.CreateAttribute("mocap:rootJoint", Sdf.ValueTypeNames.Token).Set("Hips")
    data = reader.read_stage(stage)
    assert data.agents["/World/agent0"].root_joint == TOY_JOINTS.index("Root/Hips")
    prim.GetAttribute("mocap:rootJoint").Set("Nope")
    with pytest.raises(MocapEditError, match=r"</World/agent0>\.mocap:rootJoint: joint 'Nope'"):
        reader.read_stage(stage)


def test_root_without_motion_falls_back_to_the_projected_hip(tmp_path):
    path = write_toy_stage(tmp_path / "s.usda", agents=1)
    stage = Usd.Stage.Open(str(path))
    anim = stage.GetPrimAtPath("/World/agent0/Skel/Anim")
    attr = anim.GetAttribute("translations")
    for t in attr.GetTimeSamples():
        v = np.array(attr.Get(t))
        v[1, :2] += v[0, :2]  # move the travel from the root onto the hips
        v[0] = 0
        attr.Set(type(attr.Get(t)).FromNumpy(v.astype(np.float32)), t)
    data = reader.read_stage(stage)
    agent = data.agents["/World/agent0"]
    traj = trajectory.extract(agent, data.clip_of(agent), "Z", 0.01)
    assert traj.projected_hip and traj.joint == TOY_JOINTS.index("Root/Hips")
    assert np.ptp(traj.ground[:, 0]) == pytest.approx(47 * 5.0, rel=1e-6)


@pytest.mark.parametrize("skip,needle", [
    ("skeleton", r"</World/agent0>.*no skeleton"),
    ("animation", r"</World/agent0>.*no animation"),
    ("samples", r"</World/agent0/Skel/Anim>\.translations: clip has no samples"),
])
def test_broken_agents_fail_clearly_and_write_nothing(tmp_path, skip, needle):
    path = write_toy_stage(tmp_path / "bad.usda", agents=1, skip=skip)
    out = tmp_path / "out.usda"
    proc = run_cli("solve", path, "-o", out)
    assert proc.returncode == 1, proc.stderr
    import re
    assert re.search(needle, proc.stderr), proc.stderr
    assert not out.exists()
    assert not list(tmp_path.glob(".out.*")), "no temporary file may be left behind"


def test_unreadable_input_fails_clearly(tmp_path):
    bad = tmp_path / "garbage.usda"
    bad.write_text("#usda 1.0\n( this is not usd\n")
    proc = run_cli("solve", bad, "-o", tmp_path / "o.usda")
    assert proc.returncode == 1
    assert "garbage.usda" in proc.stderr and "cannot be read" in proc.stderr
    proc = run_cli("solve", tmp_path / "missing.usda", "-o", tmp_path / "o.usda")
    assert proc.returncode == 1 and "no such file" in proc.stderr


def test_cli_help_and_plugin_path():
    proc = run_cli("--help")
    assert proc.returncode == 0 and "solve" in proc.stdout and "plugin-path" in proc.stdout
    proc = run_cli("solve", "--help")
    assert proc.returncode == 0 and "--composed" in proc.stdout
    proc = run_cli("plugin-path")
    assert proc.returncode == 0
    assert proc.stdout.strip() == mocapedit.plugin_path()


@pytest.mark.parametrize("command", ["solve", "batch"])
@pytest.mark.parametrize("pair", [("--collisions", "--no-collisions"), ("--match-speed", "--no-match-speed")])
def test_a_switch_and_its_opposite_together_are_a_usage_error(tmp_path, toy_stage, command, pair):
    """Given both, the last one won, silently."""
    out = tmp_path / "out"
    proc = run_cli(command, toy_stage, "-o", out / "e.usda" if command == "solve" else out, *pair)
    assert proc.returncode == 2 and "not allowed with argument" in proc.stderr, proc.stderr
    assert not out.exists()


def test_python_api_argument_types_are_checked(tmp_path, toy_stage):
    """Each gave an unrelated exception or a misleading message: an Sdf.Layer ("Sdf.Find(...):
    no such file"), output=5 (TypeError), progress=3 (AttributeError), a bytes output path
    ("written as .usda, not 'b'.usda''")."""
    layer = Sdf.Layer.FindOrOpen(str(toy_stage))
    assert solve(layer).report.stats["agents"] == 3          # a layer is its stage's root
    with pytest.raises(MocapEditError, match=r"the input is a int; give a Usd\.Stage"):
        solve(5)
    with pytest.raises(MocapEditError, match=r"edits layer: the output path is 5, a int"):
        solve(str(toy_stage), output=5)
    with pytest.raises(MocapEditError, match=r"the output path is b'.*', a bytes"):
        solve(str(toy_stage), output=str(tmp_path / "o.usda").encode())
    with pytest.raises(MocapEditError, match=r"progress is a int"):
        solve(str(toy_stage), progress=3)
    assert solve(toy_stage, output=tmp_path / "p.usda").report.stats["agents"] == 3   # a pathlib.Path
    assert not (tmp_path / "o.usda").exists()


def test_python_api_accepts_an_open_stage(toy_stage):
    stage = Usd.Stage.Open(str(toy_stage))
    result = solve(stage)
    assert result.layer.GetPrimAtPath("/MocapEdit")
    assert result.report.stats["agents"] == 3


def test_walker_crowd_round_trip_keeps_foot_skate(tmp_path):
    """The generated walker crowd, solved without edits: the composed stage skates no more."""
    from mocapedit.data import examples, walker
    from mocapedit.tools import measure

    clip = walker.walk(frames=72, up="Z", meters_per_unit=0.01)
    stage_path = tmp_path / "crowd.usda"
    examples.build_crowd_stage(stage_path, [examples.AgentSpec("a", clip, (0, 0, 0), 30.0, time_offset=5.0)],
                               up_axis="Z", meters_per_unit=0.01, fps=24.0, clips_dir=tmp_path / "clips")
    solve(str(stage_path), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    src = measure.foot_skate(Usd.Stage.Open(str(stage_path)), "/World/Crowd/a")
    out = measure.foot_skate(Usd.Stage.Open(str(tmp_path / "c.usda")), "/World/Crowd/a",
                             contact=src.contact, times=src.times)
    assert src.mean < 5.0, "the procedural walker plants its feet (cm/s)"
    assert out.mean == pytest.approx(src.mean, abs=1e-6)
    assert out.contact_seconds.sum() > 0.5


def test_agents_sharing_a_skeleton_asset_read_their_own_overrides(tmp_path):
    """The reader reads a skeleton or clip that many agents reference once; an agent whose own
    layer overrides the rest pose or the clip's joint order still gets its own."""
    clip = walker.walk(frames=10, name="walk")
    specs = [examples.AgentSpec(n, clip, (i * 2.0, 0.0, 0.0)) for i, n in enumerate(("a", "b", "c", "d"))]
    stage = examples.build_crowd_stage(tmp_path / "s.usda", specs)
    rest = np.array(stage.GetPrimAtPath("/World/Crowd/a/Skel").GetAttribute("restTransforms").Get())
    moved = rest.copy()
    moved[1, 3, :3] += (0.0, 0.25, 0.0)
    stage.GetPrimAtPath("/World/Crowd/b/Skel").GetAttribute("restTransforms").Set(Vt.Matrix4dArray.FromNumpy(moved))
    anim = stage.GetPrimAtPath("/World/Crowd/c/Skel/Anim").GetAttribute("joints")
    joints = list(anim.Get())
    swapped = joints[:1] + joints[2:3] + joints[1:2] + joints[3:]
    anim.Set(Vt.TokenArray(swapped))
    stage.GetRootLayer().Save()
    data = reader.read_stage(Usd.Stage.Open(str(tmp_path / "s.usda")))
    agents = data.agents
    assert np.allclose(agents["/World/Crowd/a"].rest_transforms, rest)
    assert np.allclose(agents["/World/Crowd/b"].rest_transforms, moved)
    assert np.allclose(agents["/World/Crowd/d"].rest_transforms, rest)
    assert data.clip_of(agents["/World/Crowd/c"]).joints == swapped
    assert data.clip_of(agents["/World/Crowd/d"]).joints == joints


def test_skeletons_without_the_agent_api_are_named_in_a_note(tmp_path, toy_stage):
    """A crowd built from clips without MocapAgentAPI solved to nothing, silently."""
    assert not any("MocapAgentAPI" in n for n in solve(str(toy_stage), output=str(tmp_path / "a.usda")).report.notes)
    stage = Usd.Stage.Open(str(toy_stage))
    stage.DefinePrim("/World/prop", "SkelRoot")
    stage.DefinePrim("/World/prop/Skel", "Skeleton")
    stage.DefinePrim("/World/loose", "Skeleton")
    stage.GetRootLayer().Save()
    notes = [n for n in solve(str(toy_stage), output=str(tmp_path / "b.usda")).report.notes if "MocapAgentAPI" in n]
    assert len(notes) == 1 and notes[0].startswith("2 skeletons without MocapAgentAPI are left as authored")
    assert "</World/prop>" in notes[0] and "</World/loose>" in notes[0]
    assert "/World/prop/Skel" not in notes[0] and "agent" not in notes[0].split("(")[1].split(")")[0]


def test_a_stage_without_agents_says_so(tmp_path):
    # The wrong file given (a set, an empty layer): the solve succeeds with nothing to do, and
    # says why, rather than reporting 0 agents as if that were the shot.
    shot = tmp_path / "set.usda"
    shot.write_text('#usda 1.0\ndef Xform "World"\n{\n    def Xform "Props"\n    {\n    }\n}\n')
    proc = run_cli("solve", shot, "-o", tmp_path / "set.edits.usda")
    assert proc.returncode == 0, proc.stderr
    assert "note: the stage has no agents" in proc.stdout + proc.stderr


def test_long_clips_solved_by_sparse_qr_give_one_note_for_the_shot(tmp_path):
    # Paths of 9,000 frames (75 s at 120 fps) are too ill-conditioned for LDLT and are solved by
    # sparse QR, exactly. That is the solver's business, not the artist's: before, every agent
    # printed a note of its own (a crowd of long clips printed thousands).
    frames, agents = 9000, 3
    clip = walker.walk(frames=frames, name="long")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [
        examples.AgentSpec(f"a{i}", clip, position=(2.0 * i, 0.0, 0.0)) for i in range(agents)], clip_format="usdc")
    for i in range(agents):
        agent = f"/World/Crowd/a{i}"
        start, middle = evaluate.agent_root_positions(stage, agent, [0.0, float(frames // 2)])
        examples.add_position_constraint(stage, f"/Edits/start{i}", agent, 0, tuple(map(float, start)))
        examples.add_position_constraint(stage, f"/Edits/middle{i}", agent, frames // 2,
                                         tuple(map(float, middle + (3.0, 0.0, 0.0))))
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "out.usdc"))
    report = result.report
    assert all(c.met for c in report.constraints)
    solvers = [report.agents[f"/World/Crowd/a{i}"].solver for i in range(agents)]
    assert all("SPQR" in s for s in solvers), solvers
    notes = [n for n in report.notes if "sparse QR" in n]
    assert len(notes) == 1, notes
    assert notes[0].startswith(f"path solve: {agents} of {agents} path components were solved by sparse QR"), notes
    assert "</World/Crowd/a0>" in notes[0]


def test_a_clip_layer_in_other_units_than_the_stage_gets_a_note_naming_it(tmp_path):
    """USD converts neither a referenced layer's metersPerUnit nor its upAxis: a clip written in
    metres under a centimetre stage plays its agent a hundredth of its size, and its edits with
    it. The solve says so once per clip layer, naming it (it had said nothing); a clip that
    agrees with the stage gets no note."""
    clip = walker.walk(frames=48, fps=24.0, up="Z", meters_per_unit=0.01, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip), examples.AgentSpec(
        "b", clip, (300.0, 0.0, 0.0))], up_axis="Z", meters_per_unit=0.01, clips_dir=tmp_path / "clips")
    stage.GetRootLayer().Save()
    agrees = solve(str(tmp_path / "shot.usda"))
    assert not [n for n in agrees.report.notes if "clip layer" in n]
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "clips" / "walk.usda"))
    layer.pseudoRoot.SetInfo("metersPerUnit", 1.0)
    layer.pseudoRoot.SetInfo("upAxis", "Y")
    layer.Save()
    result = solve(str(tmp_path / "shot.usda"))
    notes = [n for n in result.report.notes if "clip layer" in n]
    assert len(notes) == 1
    assert "walk.usda says upAxis Y (the stage: Z) and metersPerUnit 1 (the stage: 0.01)" in notes[0]


def test_a_zero_quaternion_in_a_clip_plays_as_no_turn_as_usdskel_plays_it(tmp_path):
    """Some exporters write a zero quaternion for a joint they do not animate. UsdSkel plays it as
    no turn; the solve made every figure of the agent NaN. It is read as no turn too."""
    import math
    from pxr import Gf
    clip = walker.walk(frames=48, fps=24.0, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)],
                                       clips_dir=tmp_path / "clips")
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "clips" / "walk.usda"))
    attr = next(a for p in [layer.GetPrimAtPath("/Skel/Anim")] for a in p.attributes if a.name == "rotations")
    value = list(layer.QueryTimeSample(attr.path, 7.0))
    value[3] = Gf.Quatf(0.0, 0.0, 0.0, 0.0)
    layer.SetTimeSample(attr.path, 7.0, Vt.QuatfArray(value))
    layer.Save()
    start = evaluate.agent_root_positions(stage, "/World/Crowd/a", [0.0])[0]
    examples.add_position_constraint(stage, "/Edits/aside", "/World/Crowd/a", 0, tuple(map(float, start + [0.5, 0, 0])))
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"))
    figures = result.report.agents["/World/Crowd/a"].plausibility
    assert math.isfinite(figures.length_ratio) and math.isfinite(figures.max_facing_rate)


def test_a_users_value_clip_over_one_channel_keeps_the_frames_of_the_others(tmp_path):
    """A walk's scales played from a value clip of one sample while its translations and rotations
    keep their own 30 samples: the frames are all of them. (Where this tool's edits layer bakes
    locked rotations over a re-timed clip, the value clip's frames are the clip's: a rule that
    took them whatever baked the other channels left this walk 2 frames.)"""
    clip = walker.walk(frames=30, fps=24.0, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)],
                                       clips_dir=tmp_path / "clips")
    scales = Sdf.Layer.CreateNew(str(tmp_path / "scales_clip.usda"))
    prim = Sdf.CreatePrimInLayer(scales, "/Anim")
    prim.specifier = Sdf.SpecifierDef
    attr = Sdf.AttributeSpec(prim, "scales", Sdf.ValueTypeNames.Half3Array)
    scales.SetTimeSample(attr.path, 0.0, Vt.Vec3hArray([(1.0, 1.0, 1.0)] * len(clip.joints)))
    scales.Save()
    clips = Usd.ClipsAPI(stage.GetPrimAtPath("/World/Crowd/a/Skel/Anim"))
    clips.SetClipAssetPaths([Sdf.AssetPath("./scales_clip.usda")])
    clips.SetClipPrimPath("/Anim")
    clips.SetClipActive([(0.0, 0.0)])
    clips.SetClipTimes([(0.0, 0.0), (7.2, 9.0)])
    stage.GetRootLayer().Save()
    agent = reader.read_stage(Usd.Stage.Open(str(tmp_path / "shot.usda"))).agents["/World/Crowd/a"]
    assert agent.frame_count >= 30
    np.testing.assert_array_equal(agent.sample_times[[0, -1]], [0.0, 29.0])
