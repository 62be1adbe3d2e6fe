"""Agents whose ground motion is the agent prim's own animated transform, as crowd tools export
them (the walk's travel on the SkelRoot, the skeleton animated in place), edited like agents
whose travel is in the root joint: the composed stages must play the same motion.

A re-timed clip plays each source frame at its new shot time, but the prim's own transform
ops still play at shot time: left as they are, a delayed walker's body would run ahead of its
pose. Its edit op then stands for those ops.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.usd import evaluate

FRAMES = 96


def _clips(folder):
    """The walk, and the same walk in place (its root joint's ground travel taken out): the
    travel, (F,3)."""
    clip = walker.walk(frames=FRAMES, name="walk")
    examples.write_clip_layer(clip, folder / "clips" / "walk.usda")
    layer = Sdf.Layer.FindOrOpen(str(folder / "clips" / "walk.usda"))
    stage = Usd.Stage.Open(layer)
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    attr = anim.GetAttribute("translations")
    travel = []
    for t in attr.GetTimeSamples():
        values = np.array(attr.Get(t), dtype=np.float64)
        travel.append(values[0].copy())
        values[0, [0, 2]] = 0.0
        attr.Set(Vt.Vec3fArray.FromNumpy(values.astype(np.float32)), t)
    layer.Export(str(folder / "clips" / "walk_in_place.usda"))
    travel = np.array(travel)
    travel[:, 1] = 0.0
    return travel


def _shot(folder, carrier: str) -> str:
    """Agents a and b walking; ``carrier`` says where the travel is: "joint" (the clip's root
    joint), "agent" (the SkelRoot's xformOp:transform) or "skeleton" (the Skeleton prim's).
    a is pinned 1.5 m off its end and its frame 40 plays at shot time 46, b's frame 60 plays
    at shot time 70, c is pinned 1 m off its end."""
    folder.mkdir()
    travel = _clips(folder)
    layer = Sdf.Layer.CreateNew(str(folder / "shot.usda"))
    layer.pseudoRoot.SetInfo("upAxis", "Y")
    layer.pseudoRoot.SetInfo("metersPerUnit", 1.0)
    layer.timeCodesPerSecond = layer.framesPerSecond = 24
    layer.startTimeCode, layer.endTimeCode = 0, FRAMES - 1
    world = Sdf.PrimSpec(layer.pseudoRoot, "World", Sdf.SpecifierDef, "Xform")
    layer.defaultPrim = "World"
    for name, x0 in (("a", 0.0), ("b", 3.0), ("c", -3.0)):
        agent = Sdf.PrimSpec(world, name, Sdf.SpecifierDef, "SkelRoot")
        agent.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["MocapAgentAPI"]))
        skel = Sdf.PrimSpec(agent, "Skel", Sdf.SpecifierDef, "Skeleton")
        clip = "clips/walk.usda" if carrier == "joint" else "clips/walk_in_place.usda"
        skel.referenceList.Prepend(Sdf.Reference(clip, examples.CLIP_SKELETON_PATH))
        holder = {"joint": agent, "agent": agent, "skeleton": skel}[carrier]
        op = Sdf.AttributeSpec(holder, "xformOp:transform", Sdf.ValueTypeNames.Matrix4d)
        for k, step in enumerate(travel if carrier != "joint" else np.zeros_like(travel)):
            m = Gf.Matrix4d(1.0)
            m.SetTranslateOnly(Gf.Vec3d(float(x0 * (holder is agent) + step[0]), 0.0, float(step[2])))
            layer.SetTimeSample(op.path, float(k), m)
        if holder is skel and x0:
            Sdf.AttributeSpec(agent, "xformOp:translate", Sdf.ValueTypeNames.Double3).default = Gf.Vec3d(x0, 0, 0)
        for prim, ops in ((agent, ["xformOp:transform"] if holder is agent else ["xformOp:translate"] if x0 else []),
                          (skel, ["xformOp:transform"] if holder is skel else [])):
            if ops:
                Sdf.AttributeSpec(prim, "xformOpOrder", Sdf.ValueTypeNames.TokenArray,
                                  variability=Sdf.VariabilityUniform).default = Vt.TokenArray(ops)
    layer.Save()
    stage = Usd.Stage.Open(layer)
    examples.add_position_constraint(stage, "/Edits/keep", "/World/a", 0, (0.0, 0.0, float(travel[0, 2])))
    examples.add_position_constraint(stage, "/Edits/aside", "/World/a", FRAMES - 1, (1.5, 0.0, float(travel[-1, 2])))
    examples.add_position_constraint(stage, "/Edits/c_aside", "/World/c", FRAMES - 1, (-2.0, 0.0, float(travel[-1, 2])))
    examples.add_time_constraint(stage, "/Edits/late", "/World/b", 60, 70.0)
    examples.add_time_constraint(stage, "/Edits/a_late", "/World/a", 40, 46.0)
    layer.Save()
    return str(folder / "shot.usda")


def _solved(folder, shot, **kwargs):
    result = solve(shot, output=str(folder / "edits.usda"), composed=str(folder / "composed.usda"), guides=False,
                   **kwargs)
    return result, Usd.Stage.Open(str(folder / "composed.usda"))


@pytest.mark.parametrize("bake_timing", [False, True], ids=["value clips", "baked"])
def test_travel_on_the_agent_prim_is_edited_as_travel_in_the_root_joint(tmp_path, bake_timing):
    by_joint, in_joint = _solved(tmp_path / "joint", _shot(tmp_path / "joint", "joint"), bake_timing=bake_timing)
    by_prim, on_prim = _solved(tmp_path / "agent", _shot(tmp_path / "agent", "agent"), bake_timing=bake_timing)
    assert by_joint.report.stats["editedAgents"] == by_prim.report.stats["editedAgents"] == 3
    # Every joint, at the frames and between them.
    times = np.concatenate([np.arange(FRAMES, dtype=np.float64), np.arange(FRAMES - 1) + 0.5])
    for agent in ("/World/a", "/World/b", "/World/c"):
        np.testing.assert_allclose(evaluate.joint_world_positions(on_prim, agent, times),
                                   evaluate.joint_world_positions(in_joint, agent, times), atol=1e-6, err_msg=agent)
    # b's frame 60 is where its source has it, at shot time 70.
    source = Usd.Stage.Open(str(tmp_path / "agent" / "shot.usda"))
    np.testing.assert_allclose(evaluate.agent_root_positions(on_prim, "/World/b", [70.0]),
                               evaluate.agent_root_positions(source, "/World/b", [60.0]), atol=1e-6)
    # The re-timed agents' edit ops stand for their own: the input's op is out of their order.
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "agent" / "edits.usda"))
    for agent in ("/World/a", "/World/b"):
        order = list(layer.GetAttributeAtPath(f"{agent}.xformOpOrder").default)
        assert order and all(op.endswith(":mocapEdit") for op in order), agent
    # c is not re-timed: its op is prepended to the input's, which still plays.
    assert list(layer.GetAttributeAtPath("/World/c.xformOpOrder").default)[-1] == "xformOp:transform"


def test_travel_on_the_skeleton_prim_is_edited_as_travel_in_the_root_joint(tmp_path):
    by_joint, in_joint = _solved(tmp_path / "joint", _shot(tmp_path / "joint", "joint"))
    by_skel, on_skel = _solved(tmp_path / "skel", _shot(tmp_path / "skel", "skeleton"))
    times = np.concatenate([np.arange(FRAMES, dtype=np.float64), np.arange(FRAMES - 1) + 0.5])
    for agent in ("/World/a", "/World/b", "/World/c"):
        np.testing.assert_allclose(evaluate.joint_world_positions(on_skel, agent, times),
                                   evaluate.joint_world_positions(in_joint, agent, times), atol=1e-6, err_msg=agent)
    # The re-timed agents' skeletons play the edits layer's ops instead of their own.
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "skel" / "edits.usda"))
    for agent in ("/World/a", "/World/b"):
        order = list(layer.GetAttributeAtPath(f"{agent}/Skel.xformOpOrder").default)
        assert order and all(op.endswith(":mocapEdit") for op in order), agent
    assert not layer.GetAttributeAtPath("/World/c/Skel.xformOpOrder")


def test_travel_on_a_prim_between_agent_and_skeleton_of_a_retimed_agent_is_named_in_a_note(tmp_path):
    shot = _shot(tmp_path / "mid", "skeleton")
    # The skeleton's travel moved onto a prim between it and the agent.
    layer = Sdf.Layer.FindOrOpen(shot)
    for name in ("a", "b", "c"):
        agent = layer.GetPrimAtPath(f"/World/{name}")
        mid = Sdf.PrimSpec(agent, "Rig", Sdf.SpecifierDef, "Xform")
        Sdf.CopySpec(layer, f"/World/{name}/Skel", layer, f"/World/{name}/Rig/Skel")
        for prop in ("xformOp:transform", "xformOpOrder"):
            Sdf.CopySpec(layer, f"/World/{name}/Skel.{prop}", layer, f"/World/{name}/Rig.{prop}")
            mid.GetPrimAtPath("Skel").RemoveProperty(mid.GetPrimAtPath("Skel").properties[prop])
        del agent.nameChildren["Skel"]
    layer.Save()
    result, _ = _solved(tmp_path / "mid", shot)
    notes = result.report.agents["/World/b"].notes or []
    assert any("between it and its skeleton has an animated transform" in n for n in notes), notes
    # Not re-timed, nothing to say.
    assert not any("animated transform" in n for n in (result.report.agents["/World/c"].notes or []))


def test_a_retimed_agent_under_a_moving_parent_plays_each_frame_where_its_source_does(tmp_path):
    # Walkers on a platform that slides 4 m along x over the shot: b's frame 60 plays at shot
    # time 70, when the platform is 0.4 m further on than at time 60.
    clip = walker.walk(frames=FRAMES, name="walk")
    specs = [examples.AgentSpec("a", clip, (0.0, 0.0, 0.0), 0.0), examples.AgentSpec("b", clip, (3.0, 0.0, 0.0), 0.0)]
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", specs)
    crowd = stage.GetPrimAtPath("/World/Crowd")
    slide = UsdGeom.Xformable(crowd).AddTranslateOp(opSuffix="platform")
    for t in (0.0, FRAMES - 1.0):
        slide.Set(Gf.Vec3d(4.0 * t / (FRAMES - 1.0), 0.0, 0.0), t)
    examples.add_time_constraint(stage, "/Edits/late", "/World/Crowd/b", 60, 70.0)
    examples.add_position_constraint(stage, "/Edits/aside", "/World/Crowd/a", FRAMES - 1,
                                     tuple(evaluate.agent_root_positions(stage, "/World/Crowd/a", [FRAMES - 1.0])[0]
                                           + np.array([1.0, 0.0, 0.0])))
    stage.GetRootLayer().Save()
    result, composed = _solved(tmp_path, str(tmp_path / "shot.usda"))
    assert not any("animated transform" in n for n in (result.report.agents["/World/Crowd/b"].notes or []))
    source = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "edits.usda"))
    pairs = np.asarray(layer.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_b").GetInfo("clips")["default"]["times"])
    assert np.abs(pairs[:, 0] - pairs[:, 1]).max() > 5.0     # re-timed by frames, not a trifle
    np.testing.assert_allclose(evaluate.joint_world_positions(composed, "/World/Crowd/b", pairs[:, 0]),
                               evaluate.joint_world_positions(source, "/World/Crowd/b", pairs[:, 1]), atol=1e-6)
    # The pinned agent is not re-timed: it plays at its own times, pinned.
    np.testing.assert_allclose(evaluate.agent_root_positions(composed, "/World/Crowd/a", [FRAMES - 1.0])[0, [0, 2]],
                               (evaluate.agent_root_positions(source, "/World/Crowd/a", [FRAMES - 1.0])[0]
                                + np.array([1.0, 0.0, 0.0]))[[0, 2]], atol=1e-6)
