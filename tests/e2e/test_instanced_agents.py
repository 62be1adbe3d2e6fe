"""Crowds of instanced agents: each agent an instanceable prim that references one character
asset, or agents inside an instanced group. Their skeletons are instance proxies; the edits
layer must still play the edited motion, so the writer makes the instances it authors under
not instanceable, and leaves instanced the agents it does not edit, or edits only by their own
prim's transform.

Checked against the same shot without instancing, by UsdSkel forward kinematics on the
composed stages, at every frame.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.usd import evaluate

FRAMES = 48
AGENTS = {"a": (0.0, 0.0, 0.0), "b": (-3.0, -3.0, 90.0), "c": (4.0, 4.0, 180.0)}


def _asset(folder, clip, name, agents: dict | None = None):
    """A character asset: a SkelRoot whose skeleton references the clip (``agents`` None), or a
    team: an Xform holding SkelRoot agents placed at ``agents``."""
    examples.write_clip_layer(clip, folder / "clips" / "walk.usda")
    layer = Sdf.Layer.CreateNew(str(folder / name))
    layer.pseudoRoot.SetInfo("upAxis", "Y")
    layer.pseudoRoot.SetInfo("metersPerUnit", 1.0)
    root = Sdf.PrimSpec(layer.pseudoRoot, "Asset", Sdf.SpecifierDef, "Xform" if agents else "SkelRoot")
    layer.defaultPrim = "Asset"
    for agent, at in (agents or {None: None}).items():
        prim = root if agent is None else Sdf.PrimSpec(root, agent, Sdf.SpecifierDef, "SkelRoot")
        if agent is not None:
            prim.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["MocapAgentAPI"]))
            _place(prim, *at)
        skel = Sdf.PrimSpec(prim, "Skel", Sdf.SpecifierDef, "Skeleton")
        skel.referenceList.Prepend(Sdf.Reference("clips/walk.usda", examples.CLIP_SKELETON_PATH))
    layer.Save()


def _place(prim: Sdf.PrimSpec, x: float, z: float, yaw: float) -> None:
    Sdf.AttributeSpec(prim, "xformOp:translate", Sdf.ValueTypeNames.Double3).default = Gf.Vec3d(x, 0.0, z)
    Sdf.AttributeSpec(prim, "xformOp:rotateY", Sdf.ValueTypeNames.Float).default = float(yaw)
    Sdf.AttributeSpec(prim, "xformOpOrder", Sdf.ValueTypeNames.TokenArray,
                      variability=Sdf.VariabilityUniform).default = Vt.TokenArray(["xformOp:translate",
                                                                                    "xformOp:rotateY"])


def _shot(folder, instanced: bool, teams: bool) -> str:
    """Agents a, b and c (each its own instance), or two teams each holding a, b and c (each
    team an instance); a is pinned off its path, b re-timed, c left as it is."""
    clip = walker.walk(frames=FRAMES, name="walk")
    if teams:
        _asset(folder, clip, "team.usda", AGENTS)
    else:
        _asset(folder, clip, "agent.usda")
    layer = Sdf.Layer.CreateNew(str(folder / "shot.usda"))
    layer.pseudoRoot.SetInfo("upAxis", "Y")
    layer.pseudoRoot.SetInfo("metersPerUnit", 1.0)
    layer.timeCodesPerSecond = layer.framesPerSecond = clip.fps
    layer.startTimeCode, layer.endTimeCode = 0, FRAMES - 1
    world = Sdf.PrimSpec(layer.pseudoRoot, "World", Sdf.SpecifierDef, "Xform")
    layer.defaultPrim = "World"
    crowd = Sdf.PrimSpec(world, "Crowd", Sdf.SpecifierDef, "Xform")
    units = {"left": (0.0, 0.0, 0.0), "right": (12.0, 0.0, 0.0)} if teams else AGENTS
    for name, at in units.items():
        prim = Sdf.PrimSpec(crowd, name, Sdf.SpecifierDef, "Xform" if teams else "SkelRoot")
        prim.referenceList.Prepend(Sdf.Reference("team.usda" if teams else "agent.usda"))
        prim.instanceable = instanced
        if not teams:
            prim.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["MocapAgentAPI"]))
        _place(prim, *at)
    layer.Save()
    stage = Usd.Stage.Open(layer)
    first = "/World/Crowd/left/" if teams else "/World/Crowd/"
    start = _root(stage, f"{first}a", 0.0)
    end = _root(stage, f"{first}a", FRAMES - 1.0)
    examples.add_position_constraint(stage, "/Edits/keep", f"{first}a", 0, tuple(start))
    examples.add_position_constraint(stage, "/Edits/aside", f"{first}a", FRAMES - 1,
                                     tuple(end + np.array([0.8, 0.0, 0.0])))
    examples.add_time_constraint(stage, "/Edits/late", f"{first}b", 30, 36.0)
    layer.Save()
    return str(folder / "shot.usda")


def _root(stage, agent, t):
    return _world(stage, agent, [t])[0, 0]


def _world(stage, agent, times) -> np.ndarray:
    """(T,J,3) joint world positions by UsdSkel FK, instance proxies included: the skeleton's
    query is its prototype's, so the joints' skeleton-space transforms are carried by the
    proxy's own local-to-world transform."""
    prim = stage.GetPrimAtPath(f"{agent}/Skel")
    skel = UsdSkel.Skeleton(prim)
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(prim), Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))
    query = cache.GetSkelQuery(skel)
    out = []
    for t in times:
        xf = UsdGeom.XformCache(Usd.TimeCode(float(t)))
        joints = np.array(query.ComputeJointSkelTransforms(Usd.TimeCode(float(t))))
        out.append((joints @ np.array(xf.GetLocalToWorldTransform(prim)))[:, 3, :3])
    return np.array(out)


@pytest.mark.parametrize("locking", [True, False], ids=["feet locked", "feet not locked"])
@pytest.mark.parametrize("teams", [False, True], ids=["instanced agents", "instanced teams"])
def test_instanced_agents_play_the_edits_of_the_same_shot_without_instancing(tmp_path, teams, locking):
    results, stages, shots = {}, {}, {}
    for instanced in (False, True):
        folder = tmp_path / ("instanced" if instanced else "plain")
        folder.mkdir()
        shot = shots[instanced] = _shot(folder, instanced, teams)
        results[instanced] = solve(shot, output=str(folder / "edits.usda"), composed=str(folder / "composed.usda"),
                                   guides=False, foot_locking=locking)
        stages[instanced] = Usd.Stage.Open(str(folder / "composed.usda"))
    source = Usd.Stage.Open(shots[True])
    plain, inst = results[False].report, results[True].report
    assert plain.stats["editedAgents"] == inst.stats["editedAgents"] == 2
    assert sorted(plain.agents) == sorted(inst.agents)
    times = np.arange(FRAMES, dtype=np.float64)
    for agent in plain.agents:
        edited = _world(stages[True], agent, times)
        np.testing.assert_allclose(edited, _world(stages[False], agent, times), atol=1e-6, err_msg=agent)
        moved = np.abs(edited - _world(source, agent, times)).max()
        assert (moved > 0.1) == bool(inst.agents[agent].edited), agent
    # An instance composes on its own where the edits layer authors under it (a locked or
    # re-timed agent's skeleton, any edited agent of a team); the rest stay instanced.
    composed = stages[True]
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "instanced" / "edits.usda"))
    units = ["/World/Crowd/left", "/World/Crowd/right"] if teams else [f"/World/Crowd/{a}" for a in AGENTS]
    below = {u: any(layer.GetPrimAtPath(f"{u}/{child}") for child in ("a", "b", "c", "Skel")) for u in units}
    for unit in units:
        assert composed.GetPrimAtPath(unit).IsInstance() == (not below[unit]), unit
    if teams:
        assert below == {"/World/Crowd/left": True, "/World/Crowd/right": False}
    else:
        # b plays a re-timed animation bound to its skeleton, below its instance; a's path edit
        # is its own prim's transform ops, and its legs are locked only when locking is on.
        assert below == {"/World/Crowd/a": locking, "/World/Crowd/b": True, "/World/Crowd/c": False}
    # The project's own FK (metrics, preview, measure) sees instanced agents where they are.
    for agent in plain.agents:
        for stage, plain_stage in ((source, Usd.Stage.Open(shots[False])), (composed, stages[False])):
            np.testing.assert_allclose(evaluate.joint_world_positions(stage, agent, times),
                                       evaluate.joint_world_positions(plain_stage, agent, times), atol=1e-6,
                                       err_msg=agent)
    # The input is read only.
    assert source.GetPrimAtPath("/World/Crowd/left" if teams else "/World/Crowd/a").IsInstance()
