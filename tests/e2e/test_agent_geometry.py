"""Agents as characters come out of a crowd tool: skinned meshes under the SkelRoot bound to the
body's skeleton, and sometimes a second skeleton beside it (a prop, a cloth rig). The solve must
edit the body, and the composed stage must play the same motion as the same shot without the
geometry."""
from __future__ import annotations

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdSkel

from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.usd import evaluate

from conftest import run_cli

FRAMES = 72
AGENTS = ("/World/Crowd/a0", "/World/Crowd/a1")


def _mesh(stage, path, skeleton):
    """A triangle skinned to ``skeleton``'s first joint."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0)])
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skeleton])
    binding.CreateJointIndicesPrimvar(False, 1).Set([0, 0, 0])
    binding.CreateJointWeightsPrimvar(False, 1).Set([1.0, 1.0, 1.0])
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))


def _prop(stage, agent):
    """A one-joint prop skeleton with its own (still) animation, authored before the body's."""
    prop = UsdSkel.Skeleton.Define(stage, f"{agent}/Prop")
    prop.CreateJointsAttr(["stick"])
    prop.CreateRestTransformsAttr([Gf.Matrix4d(1.0)])
    prop.CreateBindTransformsAttr([Gf.Matrix4d(1.0)])
    anim = UsdSkel.Animation.Define(stage, f"{agent}/Prop/Anim")
    anim.CreateJointsAttr(["stick"])
    anim.CreateTranslationsAttr([Gf.Vec3f(0.0, 1.0, 0.0)])
    anim.CreateRotationsAttr([Gf.Quatf(1.0)])
    anim.CreateScalesAttr([Gf.Vec3h(1.0, 1.0, 1.0)])
    UsdSkel.BindingAPI.Apply(prop.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    stage.GetPrimAtPath(agent).SetChildrenReorder(["Prop", "Skel"])


def _shot(folder, geometry: bool, prop: bool = False, prop_mesh: bool = False) -> str:
    """Two walkers, each pinned at its start and moved 1 m aside at its end; a1 also plays its
    frame 30 at shot time 36. ``geometry``: a mesh under each agent skinned to its skeleton;
    ``prop``: a prop skeleton under a1 before its body's (``prop_mesh``: with a mesh of its own)."""
    folder.mkdir()
    clip = walker.walk(frames=FRAMES, name="walk")
    stage = examples.build_crowd_stage(folder / "shot.usda",
                                       [examples.AgentSpec(f"a{i}", clip, position=(2.0 * i, 0.0, 0.0))
                                        for i in range(2)])
    source = Usd.Stage.Open(stage.GetRootLayer())
    ends = {a: evaluate.agent_root_positions(source, a, [0.0, FRAMES - 1.0]) for a in AGENTS}
    for agent in AGENTS:
        if prop and agent.endswith("a1"):
            _prop(stage, agent)
            if prop_mesh:
                _mesh(stage, f"{agent}/Sword", f"{agent}/Prop")
        if geometry:
            _mesh(stage, f"{agent}/Body", f"{agent}/Skel")
        start, end = ends[agent]
        name = agent.rsplit("/", 1)[-1]
        examples.add_position_constraint(stage, f"/Edits/{name}_start", agent, 0, tuple(map(float, start)))
        examples.add_position_constraint(stage, f"/Edits/{name}_end", agent, FRAMES - 1,
                                         tuple(map(float, end + np.array([1.0, 0.0, 0.0]))))
    examples.add_time_constraint(stage, "/Edits/a1_late", AGENTS[1], 30, 36.0)
    stage.GetRootLayer().Save()
    return str(folder / "shot.usda")


def _composed(folder, shot):
    result = solve(shot, output=str(folder / "edits.usda"), composed=str(folder / "composed.usda"), guides=False)
    return result, Usd.Stage.Open(str(folder / "composed.usda"))


def _joints(stage, agent):
    times = np.arange(FRAMES + 8, dtype=np.float64)
    return evaluate.joint_world_positions(stage, f"{agent}/Skel", times)


def test_skinned_meshes_under_the_agents_play_the_same_edit(tmp_path):
    _, plain = _composed(tmp_path / "plain", _shot(tmp_path / "plain", geometry=False))
    result, skinned = _composed(tmp_path / "skinned", _shot(tmp_path / "skinned", geometry=True))
    assert result.report.stats["editedAgents"] == 2
    for agent in AGENTS:
        np.testing.assert_allclose(_joints(skinned, agent), _joints(plain, agent), atol=1e-6, err_msg=agent)
        # The mesh is bound to the skeleton the edit plays.
        query = UsdSkel.Cache()
        root = UsdSkel.Root(skinned.GetPrimAtPath(agent))
        query.Populate(root, Usd.PrimDefaultPredicate)
        bindings = query.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
        assert [str(b.GetSkeleton().GetPath()) for b in bindings] == [f"{agent}/Skel"]
        assert [str(q.GetPrim().GetPath()) for q in bindings[0].GetSkinningTargets()] == [f"{agent}/Body"]


def test_a_prop_skeleton_beside_the_body_is_not_taken_for_it(tmp_path):
    _, plain = _composed(tmp_path / "plain", _shot(tmp_path / "plain", geometry=True))
    result, with_prop = _composed(tmp_path / "prop", _shot(tmp_path / "prop", geometry=True, prop=True))
    assert result.report.stats["editedAgents"] == 2
    for agent in AGENTS:
        np.testing.assert_allclose(_joints(with_prop, agent), _joints(plain, agent), atol=1e-6, err_msg=agent)
    # The prop is carried by the agent's edit and keeps its own animation.
    prop = UsdSkel.Skeleton(with_prop.GetPrimAtPath(f"{AGENTS[1]}/Prop"))
    assert [str(t) for t in UsdSkel.BindingAPI(prop).GetAnimationSourceRel().GetTargets()] == [f"{AGENTS[1]}/Prop/Anim"]


def test_two_skeletons_with_geometry_are_an_error_until_the_agent_binds_one(tmp_path):
    shot = _shot(tmp_path / "shot", geometry=True, prop=True, prop_mesh=True)
    out = tmp_path / "shot" / "out.usda"
    proc = run_cli("solve", shot, "-o", out)
    assert proc.returncode == 1, proc.stderr
    assert "</World/Crowd/a1>.skel:skeleton: agent has several skeletons" in proc.stderr, proc.stderr
    assert "</World/Crowd/a1/Prop>" in proc.stderr and "bind the one to edit" in proc.stderr
    assert "Traceback" not in proc.stderr and not out.exists()
    # What the message says to do.
    stage = Usd.Stage.Open(shot)
    UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(AGENTS[1])).CreateSkeletonRel().SetTargets([f"{AGENTS[1]}/Skel"])
    stage.GetRootLayer().Save()
    composed_path = tmp_path / "shot" / "composed.usda"
    proc = run_cli("solve", shot, "-o", out, "--composed", composed_path)
    assert proc.returncode == 0, proc.stderr
    _, plain = _composed(tmp_path / "plain", _shot(tmp_path / "plain", geometry=True))
    composed = Usd.Stage.Open(str(composed_path))
    np.testing.assert_allclose(_joints(composed, AGENTS[1]), _joints(plain, AGENTS[1]), atol=1e-6)


def test_the_skeleton_the_agents_geometry_binds_outranks_one_inherited_from_above(tmp_path):
    """UsdSkel skins each mesh by its own binding: a skel:skeleton on an ancestor (here the
    crowd's, naming a1's prop) does not make the agents play another skeleton than their body's."""
    _, plain = _composed(tmp_path / "plain", _shot(tmp_path / "plain", geometry=True))
    shot = _shot(tmp_path / "shot", geometry=True, prop=True)
    stage = Usd.Stage.Open(shot)
    UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath("/World/Crowd")).CreateSkeletonRel().SetTargets(
        [f"{AGENTS[1]}/Prop"])
    stage.GetRootLayer().Save()
    result, composed = _composed(tmp_path / "shot", shot)
    assert result.report.stats["editedAgents"] == 2
    for agent in AGENTS:
        np.testing.assert_allclose(_joints(composed, agent), _joints(plain, agent), atol=1e-6, err_msg=agent)


def _instanced(tmp_path, pinned: bool) -> str:
    """A walker made the prototype of a PointInstancer that plays it at three points."""
    from pxr import UsdGeom

    folder = tmp_path / "instancer"
    folder.mkdir()
    clip = walker.walk(frames=48, name="walk")
    stage = examples.build_crowd_stage(folder / "shot.usda", [examples.AgentSpec("proto", clip)])
    instancer = UsdGeom.PointInstancer.Define(stage, "/World/Instancer")
    proto = stage.DefinePrim("/World/Instancer/Prototypes/walker")
    proto.GetReferences().AddInternalReference("/World/Crowd/proto")
    stage.GetPrimAtPath("/World/Crowd").SetActive(False)
    instancer.CreatePrototypesRel().SetTargets([proto.GetPath()])
    instancer.CreateProtoIndicesAttr([0, 0, 0])
    instancer.CreatePositionsAttr([(0, 0, 0), (2, 0, 0), (4, 0, 0)])
    if pinned:
        examples.add_position_constraint(stage, "/Edits/pin", str(proto.GetPath()), 47, (1.0, 0.0, 2.7))
    stage.GetRootLayer().Save()
    return str(folder / "shot.usda")


def test_a_point_instancer_prototype_is_not_edited_as_an_agent(tmp_path):
    """Its instances play at the instancer's points, which cannot be edited one by one: before,
    the prototype was solved where it stands (a pin 'met' there, where nothing plays) and its
    edit moved every instance alike."""
    result = solve(_instanced(tmp_path, pinned=False), output=str(tmp_path / "e.usda"))
    assert result.report.stats["agents"] == 0
    notes = [n for n in result.report.notes if "PointInstancer" in n]
    assert len(notes) == 1 and "</World/Instancer/Prototypes/walker>" in notes[0], result.report.notes
    # A constraint on it cannot be met where it plays: an error naming the instancer.
    (tmp_path / "pinned").mkdir()
    proc = run_cli("solve", _instanced(tmp_path / "pinned", pinned=True), "-o", tmp_path / "out.usda")
    assert proc.returncode == 1, proc.stderr
    assert "</Edits/pin>.agent: targets </World/Instancer/Prototypes/walker>, which is a prototype of " \
           "PointInstancer </World/Instancer>" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out.usda").exists()
