"""Tests of the example-stage authoring: clip layers, crowd stages, constraints, tags."""
from __future__ import annotations

import filecmp
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel

from mocapedit.data import examples, walker

from layer_compare import assert_layers_close

REPO = Path(__file__).resolve().parents[2]


def _agent_matrix(position, yaw_degrees, up_axis):
    """Column-vector matrix of an agent's translate + rotate-about-up ops."""
    a = np.radians(float(np.float32(yaw_degrees)))   # the op is authored as a float
    c, s = np.cos(a), np.sin(a)
    m = np.eye(4)
    if up_axis == "Y":
        m[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    else:
        m[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    m[:3, 3] = position
    return m


def _api_schemas(prim):
    """API schemas authored on a prim (GetAppliedSchemas lists only registered ones)."""
    ops = prim.GetMetadata("apiSchemas")
    return list(ops.GetAddedOrExplicitItems()) if ops else []


def _skel_query(stage, agent_path):
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetPrimAtPath(agent_path)), Usd.PrimDefaultPredicate)
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath(f"{agent_path}/Skel"))
    query = cache.GetSkelQuery(skel)
    assert query, f"no skeleton query for {agent_path}"
    return query


def test_clip_layer_rejects_empty_clips(tmp_path):
    clip = walker.walk(4)
    empty = walker.Clip(**{**clip.__dict__, "translations": clip.translations[:0],
                           "rotations": clip.rotations[:0]})
    with pytest.raises(ValueError, match="no samples"):
        examples.write_clip_layer(empty, tmp_path / "empty.usda")
    assert not (tmp_path / "empty.usda").exists()


@pytest.mark.parametrize("ext", ["usda", "usdc"])
def test_clip_layer_holds_the_clip(tmp_path, ext):
    clip = walker.run(30, 30.0, up="Z", meters_per_unit=0.01)
    layer = examples.write_clip_layer(clip, tmp_path / f"run.{ext}", {"pause": (3, 7)})
    assert layer.GetFileFormat().primaryFileExtension == ext
    stage = Usd.Stage.Open(str(tmp_path / f"run.{ext}"))
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    assert stage.GetTimeCodesPerSecond() == 30.0 and stage.GetFramesPerSecond() == 30.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 29.0)
    assert stage.GetDefaultPrim().GetPath() == examples.CLIP_SKELETON_PATH

    skel = UsdSkel.Skeleton(stage.GetPrimAtPath(examples.CLIP_SKELETON_PATH))
    assert list(skel.GetJointsAttr().Get()) == clip.joints
    bind = np.array(skel.GetBindTransformsAttr().Get())
    np.testing.assert_allclose(np.swapaxes(bind, 1, 2), walker.rest_world_transforms(clip),
                               atol=1e-9)
    rest = np.array(skel.GetRestTransformsAttr().Get())
    np.testing.assert_allclose(np.swapaxes(rest, 1, 2), walker.rest_local_matrices(clip),
                               atol=1e-9)
    binding = UsdSkel.BindingAPI(skel.GetPrim())
    assert binding.GetAnimationSourceRel().GetTargets() == [examples.CLIP_ANIMATION_PATH]

    anim = UsdSkel.Animation(stage.GetPrimAtPath(examples.CLIP_ANIMATION_PATH))
    assert list(anim.GetJointsAttr().Get()) == clip.joints
    for attr in (anim.GetTranslationsAttr(), anim.GetRotationsAttr(), anim.GetScalesAttr()):
        assert attr.GetTimeSamples() == [float(f) for f in range(30)]
    for f in (0, 11, 29):
        np.testing.assert_array_equal(np.array(anim.GetTranslationsAttr().Get(f)),
                                      clip.translations[f])
        np.testing.assert_array_equal(np.array(anim.GetRotationsAttr().Get(f)), clip.rotations[f])
        np.testing.assert_array_equal(np.array(anim.GetScalesAttr().Get(f)), 1.0)
    assert "MocapStationaryAPI:pause" in _api_schemas(anim.GetPrim())
    assert anim.GetPrim().GetAttribute("stationary:pause:frames").Get() == Gf.Vec2i(3, 7)


def _crowd(up_axis, mpu, fps):
    kw = dict(fps=fps, up=up_axis, meters_per_unit=mpu)
    walk = walker.walk(40, name="walk", **kw)
    idle = walker.idle(40, name="idle", **kw)
    run = walker.run(40, name="run", phase=0.3, **kw)
    s = 1.0 / mpu
    return [
        examples.AgentSpec("agent_0000", walk, (0.0, 0.0, 0.0), 0.0),
        examples.AgentSpec("agent_0001", walk, (2 * s, 0.0, -1 * s), 37.5, time_offset=7.0),
        examples.AgentSpec("agent_0002", run, (-3 * s, 0.0, 1 * s), -120.0, time_offset=2.5),
        examples.AgentSpec("agent_0003", idle, (0.5 * s, 0.0, 4 * s), 200.0, time_offset=-5.0),
    ]


@pytest.mark.parametrize("up_axis,mpu,fps", [("Y", 1.0, 24.0), ("Z", 0.01, 30.0)])
def test_usdskel_plays_the_numpy_clip_at_the_agent_transform(tmp_path, up_axis, mpu, fps):
    agents = _crowd(up_axis, mpu, fps)
    if up_axis == "Z":   # place the agents on the Z-up ground plane
        for a in agents:
            a.position = (a.position[0], -a.position[2], 0.0)
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", agents, up_axis=up_axis,
                                       meters_per_unit=mpu, fps=fps)
    tolerance = 1e-4   # stage units
    for agent in agents:
        path = f"/World/Crowd/{agent.name}"
        query = _skel_query(stage, path)
        world = walker.world_transforms(agent.clip)
        placed = _agent_matrix(agent.position, agent.yaw, up_axis) @ world
        for frame in (0, 1, 17, agent.clip.num_frames - 1):
            xf_cache = UsdGeom.XformCache(Usd.TimeCode(agent.time_offset + frame))
            usd = np.swapaxes(np.array(query.ComputeJointWorldTransforms(xf_cache)), 1, 2)
            np.testing.assert_allclose(usd[0, :3, 3], placed[frame, 0, :3, 3], atol=tolerance,
                                       err_msg=f"root of {agent.name} at frame {frame}")
            np.testing.assert_allclose(usd[:, :3, 3], placed[frame, :, :3, 3], atol=tolerance)
            np.testing.assert_allclose(usd[:, :3, :3], placed[frame, :, :3, :3], atol=1e-5)


def test_layer_offsets_shift_the_clip_in_shot_time(tmp_path):
    agents = _crowd("Y", 1.0, 24.0)
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", agents)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (-5.0, 46.0)
    for agent in agents:
        anim = UsdSkel.Animation(stage.GetPrimAtPath(f"/World/Crowd/{agent.name}/Skel/Anim"))
        samples = np.array(anim.GetTranslationsAttr().GetTimeSamples())
        np.testing.assert_allclose(samples, agent.time_offset + np.arange(40), atol=1e-9)
        for frame in (0, 23):
            value = np.array(anim.GetRotationsAttr().Get(agent.time_offset + frame))
            np.testing.assert_array_equal(value, agent.clip.rotations[frame])
    # Half-way between two samples of the offset clip, UsdSkel interpolates.
    moving = agents[1]
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/World/Crowd/agent_0001/Skel/Anim"))
    mid = np.array(anim.GetTranslationsAttr().Get(moving.time_offset + 10.5))[0]
    np.testing.assert_allclose(mid, moving.clip.translations[10:12, 0].mean(0), atol=1e-6)


def test_agents_are_skel_roots_with_the_agent_api_and_a_bound_clip(tmp_path):
    agents = _crowd("Y", 1.0, 24.0)
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", agents)
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
    assert [p.GetName() for p in roots] == [a.name for a in agents]
    for prim, agent in zip(roots, agents):
        assert "MocapAgentAPI" in _api_schemas(prim)
        if Usd.SchemaRegistry.GetTypeFromSchemaTypeName("MocapAgentAPI"):
            assert prim.HasAPI("MocapAgentAPI")   # the schema plugin is registered
        ops = UsdGeom.Xformable(prim).GetOrderedXformOps()
        assert [op.GetOpName() for op in ops] == ["xformOp:translate", "xformOp:rotateY"]
        assert ops[1].Get() == pytest.approx(agent.yaw)
        skel = UsdSkel.Skeleton(prim.GetChild("Skel"))
        assert skel
        source = UsdSkel.BindingAPI(skel.GetPrim()).GetInheritedAnimationSource()
        assert source.GetPath() == prim.GetPath().AppendPath("Skel/Anim")
        assert UsdSkel.Animation(source)


def test_each_clip_is_written_once_and_referenced_relatively(tmp_path):
    agents = _crowd("Y", 1.0, 24.0)
    examples.build_crowd_stage(tmp_path / "shots" / "shot.usda", agents,
                               clips_dir=tmp_path / "clips", clip_format="usdc")
    assert sorted(p.name for p in (tmp_path / "clips").iterdir()) == [
        "idle.usdc", "run.usdc", "walk.usdc"]
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "shots" / "shot.usda"))
    refs = layer.GetPrimAtPath("/World/Crowd/agent_0001/Skel").referenceList.prependedItems
    assert len(refs) == 1
    assert refs[0].assetPath == "../clips/walk.usdc"
    assert refs[0].primPath == examples.CLIP_SKELETON_PATH
    assert refs[0].layerOffset == Sdf.LayerOffset(7.0, 1.0)


def test_build_rejects_inconsistent_input(tmp_path):
    walk = walker.walk(10)
    with pytest.raises(ValueError, match="used twice"):
        examples.build_crowd_stage(tmp_path / "a.usda", [examples.AgentSpec("a", walk),
                                                          examples.AgentSpec("a", walk)])
    with pytest.raises(ValueError, match="two different clips"):
        examples.build_crowd_stage(tmp_path / "b.usda", [
            examples.AgentSpec("a", walk), examples.AgentSpec("b", walker.walk(10))])
    with pytest.raises(ValueError, match="Z-up"):
        examples.build_crowd_stage(tmp_path / "c.usda", [
            examples.AgentSpec("a", walker.walk(10, up="Z"))])
    with pytest.raises(ValueError, match="0.01 m per unit"):
        examples.build_crowd_stage(tmp_path / "d.usda", [
            examples.AgentSpec("a", walker.walk(10, meters_per_unit=0.01))])
    with pytest.raises(ValueError, match="30.0 fps"):
        examples.build_crowd_stage(tmp_path / "e.usda", [
            examples.AgentSpec("a", walker.walk(10, fps=30.0))])
    with pytest.raises(ValueError, match="clip_format"):
        examples.build_crowd_stage(tmp_path / "f.usda", [examples.AgentSpec("a", walk)],
                                   clip_format="abc")
    with pytest.raises(ValueError, match="up_axis"):
        examples.build_crowd_stage(tmp_path / "g.usda", [examples.AgentSpec("a", walk)],
                                   up_axis="X")
    with pytest.raises(ValueError, match="no agent plays"):
        examples.build_crowd_stage(tmp_path / "h.usda", [examples.AgentSpec("a", walk)],
                                   stationary={"run": {"pause": (1, 2)}})
    with pytest.raises(ValueError, match="crowd_path"):
        examples.build_crowd_stage(tmp_path / "i.usda", [examples.AgentSpec("a", walk)],
                                   crowd_path="Crowd")
    assert not list(tmp_path.glob("*.usda")), "nothing is written for bad input"


def test_rebuilding_a_stage_replaces_its_content(tmp_path):
    agents = _crowd("Y", 1.0, 24.0)
    first = examples.build_crowd_stage(tmp_path / "shot.usda", agents)
    assert first.GetPrimAtPath("/World/Crowd/agent_0003")
    second = examples.build_crowd_stage(tmp_path / "shot.usda", agents[:2],
                                        crowd_path="/Shot/Agents")
    assert not second.GetPrimAtPath("/World")
    assert [p.GetName() for p in second.GetPrimAtPath("/Shot/Agents").GetChildren()] == [
        "agent_0000", "agent_0001"]
    reopened = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    assert not reopened.GetPrimAtPath("/World/Crowd/agent_0003")


def test_position_constraint_is_authored_with_the_schema_types(tmp_path):
    stage = Usd.Stage.CreateInMemory()
    prim = examples.add_position_constraint(stage, "/Constraints/pin", "/World/Crowd/agent_0001",
                                            frame=30, position=(1.5, 0.0, -2.0),
                                            strength="soft", weight=2.5)
    assert prim.GetTypeName() == "MocapPositionConstraint"
    assert prim.GetRelationship("agent").GetTargets() == [Sdf.Path("/World/Crowd/agent_0001")]
    expected = {"frame": ("int", 30), "position": ("point3d", Gf.Vec3d(1.5, 0.0, -2.0)),
                "strength": ("token", "soft"), "weight": ("double", 2.5)}
    for name, (type_name, value) in expected.items():
        attr = prim.GetAttribute(name)
        assert str(attr.GetTypeName()) == type_name
        assert attr.GetVariability() == Sdf.VariabilityUniform
        assert not attr.IsCustom()
        assert attr.Get() == value
    hard = examples.add_position_constraint(stage, "/Constraints/hard", "/World/Crowd/agent_0000",
                                            0, (0, 0, 0))
    assert hard.GetAttribute("strength").Get() == "hard"
    assert hard.GetAttribute("weight").Get() == 1.0
    with pytest.raises(ValueError, match="strength"):
        examples.add_position_constraint(stage, "/Constraints/bad", "/A", 0, (0, 0, 0), "firm")
    assert not stage.GetPrimAtPath("/Constraints/bad")


def test_define_mocap_prim_is_generic():
    stage = Usd.Stage.CreateInMemory()
    vt = Sdf.ValueTypeNames
    prim = examples.define_mocap_prim(
        stage, "/Constraints/sync", "MocapSyncConstraint",
        attributes={"frame": (vt.Int, 4), "targetFrame": (vt.Int, 9), "offset": (vt.Double, 1.5)},
        relationships={"agent": ["/A"], "target": ["/B"]})
    assert prim.GetTypeName() == "MocapSyncConstraint"
    assert prim.GetAttribute("offset").Get() == 1.5
    assert prim.GetAttribute("targetFrame").Get() == 9
    assert prim.GetRelationship("target").GetTargets() == [Sdf.Path("/B")]


def test_stationary_tags_on_prims_and_on_specs(tmp_path):
    stage = Usd.Stage.CreateInMemory()
    anim = stage.DefinePrim("/Anim", "SkelAnimation")
    examples.tag_stationary(anim, "pause", (10, 20))
    examples.tag_stationary(anim, "wait", [30, 30])
    examples.tag_stationary(anim, "pause", (11, 21))   # re-tagging updates the range
    assert _api_schemas(anim) == ["MocapStationaryAPI:pause", "MocapStationaryAPI:wait"]
    assert anim.GetAttribute("stationary:pause:frames").Get() == Gf.Vec2i(11, 21)
    assert anim.GetAttribute("stationary:wait:frames").Get() == Gf.Vec2i(30, 30)

    layer = Sdf.Layer.CreateAnonymous(".usda")
    spec = Sdf.CreatePrimInLayer(layer, "/Anim")
    examples.tag_stationary(spec, "pause", (1, 2))
    examples.tag_stationary(spec, "pause", (3, 4))
    assert list(spec.GetInfo("apiSchemas").prependedItems) == ["MocapStationaryAPI:pause"]
    attr = spec.properties["stationary:pause:frames"]
    assert attr.default == Gf.Vec2i(3, 4) and attr.variability == Sdf.VariabilityUniform

    for bad_name, bad_range in (("", (1, 2)), ("a:b", (1, 2)), ("1x", (1, 2)),
                                ("ok", (5, 4)), ("ok", (-1, 3))):
        with pytest.raises(ValueError):
            examples.tag_stationary(anim, bad_name, bad_range)


def test_a_thousand_agents_share_ten_clips(tmp_path):
    clips = [walker.walk(240, phase=i / 10, name=f"walk_{i}") for i in range(10)]
    agents = [examples.AgentSpec(f"agent_{i:04d}", clips[i % 10],
                                 (2.0 * (i % 40), 0.0, 2.0 * (i // 40)), yaw=(7.0 * i) % 360,
                                 time_offset=float(i % 17)) for i in range(1000)]
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", agents, clip_format="usdc")
    assert len(list((tmp_path / "clips").iterdir())) == 10
    roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
    assert len(roots) == 1000
    assert stage.GetEndTimeCode() == 16.0 + 239.0
    anim = stage.GetPrimAtPath("/World/Crowd/agent_0999/Skel/Anim")
    assert anim.GetAttribute("rotations").GetTimeSamples()[0] == 999 % 17


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> tuple[Path, Path]:
    """Two independent runs of make_stages.py (in parallel), in two folders."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(REPO / "python")] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    outs = (tmp_path_factory.mktemp("stages_one"), tmp_path_factory.mktemp("stages_two"))
    runs = [subprocess.Popen([sys.executable, str(REPO / "example_stages" / "make_stages.py"),
                              "--out", str(out)], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT) for out in outs]
    for run in runs:
        output, _ = run.communicate(timeout=300)
        assert run.returncode == 0, output.decode()
    return outs


def test_make_stages_is_deterministic_and_small(generated):
    first, second = generated
    files = sorted(p.relative_to(first) for p in first.rglob("*") if p.is_file())
    assert Path("crowd_yup.usda") in files and Path("crowd_zup_cm.usda") in files
    assert sorted(p.relative_to(second) for p in second.rglob("*") if p.is_file()) == files
    for rel in files:
        assert filecmp.cmp(first / rel, second / rel, shallow=False), f"{rel} differs"
        assert (first / rel).stat().st_size < 1_000_000

    for name, up_axis, mpu in (("crowd_yup.usda", "Y", 1.0), ("crowd_zup_cm.usda", "Z", 0.01)):
        stage = Usd.Stage.Open(str(first / name))
        assert UsdGeom.GetStageUpAxis(stage) == up_axis
        assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(mpu)
        roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
        assert 5 <= len(roots) <= 8
        offsets = set()
        tagged = 0
        for root in roots:
            query = _skel_query(stage, str(root.GetPath()))
            samples = query.GetAnimQuery().GetJointTransformTimeSamples()
            assert len(samples) == 120
            offsets.add(samples[0])
            anim = root.GetChild("Skel").GetChild("Anim")
            if anim.GetAttribute("stationary:pause:frames").HasAuthoredValue():
                tagged += 1
        assert len(offsets) >= 3, "agents start at different shot times"
        assert tagged >= 1


def test_checked_in_example_stages_are_up_to_date(generated):
    # Compared with tolerances: the last digit of a sin() may differ between
    # machines, which is no reason to regenerate the files.
    tmp_path = generated[0]
    fresh = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*.usda"))
    checked_in = REPO / "example_stages"
    assert sorted(p.relative_to(checked_in) for p in checked_in.rglob("*.usda")) == fresh, (
        "example_stages/ is stale: run example_stages/make_stages.py")
    for rel in fresh:
        assert_layers_close(Sdf.Layer.OpenAsAnonymous(str(tmp_path / rel)),
                            Sdf.Layer.OpenAsAnonymous(str(checked_in / rel)), f"example_stages/{rel}")
