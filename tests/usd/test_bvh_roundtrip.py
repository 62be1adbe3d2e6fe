"""Round trip: a BVH clip, imported and tagged, drives an agent through `mocapedit solve`."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom

from mocapedit.usd import bvh_usd, schema
from mocapedit.usd.report_io import read_report
from mocapedit.usd.bvh_usd import ImportSettings

from bvhgen import walk_idle_walk, write_bvh
from conftest import run_cli, world_joints


def _shot(tmp_path, up="Y"):
    """clip.usda (imported agent) + tags.usda (detected), sub-layered by shot.usda."""
    rig, values, idle = walk_idle_walk(fps=30.0, walk1=2.0, idle=2.0, walk2=2.0)
    write_bvh(tmp_path / "walk.bvh", rig, values, frame_time=".0333333")
    imported = run_cli("import-bvh", tmp_path / "walk.bvh", "-o", tmp_path / "clip.usda", "--agent",
                       "--up", up, "-q")
    assert imported.returncode == 0, imported.stderr
    tagged = run_cli("detect-stationary", tmp_path / "clip.usda", "-o", tmp_path / "tags.usda", "-q")
    assert tagged.returncode == 0, tagged.stderr
    stage = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    stage.GetRootLayer().subLayerPaths = ["tags.usda", "clip.usda"]
    clip = Usd.Stage.Open(str(tmp_path / "clip.usda"))
    UsdGeom.SetStageUpAxis(stage, up)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(clip.GetTimeCodesPerSecond())
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(clip.GetEndTimeCode())
    stage.SetDefaultPrim(stage.GetPrimAtPath("/walk"))
    return stage, values, idle


def test_an_imported_clip_goes_through_solve_and_plays_back(tmp_path):
    stage, values, idle = _shot(tmp_path)
    pin = schema.PositionConstraint.Define(stage, "/Edits/pin")
    pin.CreateAgentRel().SetTargets(["/walk"])
    pin.CreateFrameAttr(len(values) - 1)
    pin.CreatePositionAttr(Gf.Vec3d(150.0, 0.0, 500.0))
    stage.GetRootLayer().Save()

    out = run_cli("solve", tmp_path / "shot.usda", "-o", tmp_path / "edits.usda", "--composed",
                  tmp_path / "edited.usda", "--report", tmp_path / "report.json")
    assert out.returncode == 0, out.stderr
    import json
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["stats"]["agents"] == 1 and report["stats"]["constraints"] == 1
    assert report["agents"]["/walk"]["frames"] == len(values)
    edited = Usd.Stage.Open(str(tmp_path / "edited.usda"))
    assert edited.GetTimeCodesPerSecond() == 30.0
    # The reader found the detected tag on the imported clip.
    anim = edited.GetPrimAtPath("/walk/Skel/Anim")
    a, b = anim.GetAttribute("stationary:auto1:frames").Get()
    assert idle[0] - 6 <= a and b <= idle[1] + 6
    # With or without a path pass, the composed stage plays through UsdSkel: the hips
    # follow the BVH root wherever no edit applies.
    if not report["stats"]["editedAgents"]:
        hips = world_joints(edited, "/walk/Skel", range(len(values)))[:, 0]
        np.testing.assert_allclose(hips, values[:, :3], atol=1e-4)


def test_a_path_edit_moves_the_imported_walk_and_keeps_its_idle_rigid(tmp_path):
    pytest.importorskip("mocapedit.pipeline.passes.path")
    stage, values, idle = _shot(tmp_path, up="Y")
    last = len(values) - 1
    target = Gf.Vec3d(values[last, 0] + 120.0, 0.0, values[last, 2] - 80.0)
    pin = schema.PositionConstraint.Define(stage, "/Edits/pin")
    pin.CreateAgentRel().SetTargets(["/walk"])
    pin.CreateFrameAttr(last)
    pin.CreatePositionAttr(target)
    start = schema.PositionConstraint.Define(stage, "/Edits/start")
    start.CreateAgentRel().SetTargets(["/walk"])
    start.CreateFrameAttr(0)
    start.CreatePositionAttr(Gf.Vec3d(values[0, 0], 0.0, values[0, 2]))
    stage.GetRootLayer().Save()

    out = run_cli("solve", tmp_path / "shot.usda", "-o", tmp_path / "edits.usda", "--composed",
                  tmp_path / "edited.usda")
    assert out.returncode == 0, out.stderr
    edited = Usd.Stage.Open(str(tmp_path / "edited.usda"))
    source = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    frames = range(len(values))
    hips_new = world_joints(edited, "/walk/Skel", frames)[:, 0]
    hips_src = world_joints(source, "/walk/Skel", frames)[:, 0]
    # The pinned frame is where it was asked to be, on the ground plane (x, -z).
    np.testing.assert_allclose(hips_new[last, [0, 2]], [target[0], target[2]], atol=1e-3)
    np.testing.assert_allclose(hips_new[0, [0, 2]], hips_src[0, [0, 2]], atol=1e-3)
    # The tagged idle moves as one rigid piece: distances between its root positions keep.
    a, b = edited.GetPrimAtPath("/walk/Skel/Anim").GetAttribute("stationary:auto1:frames").Get()
    span_src, span_new = hips_src[a:b + 1][:, [0, 2]], hips_new[a:b + 1][:, [0, 2]]
    d_src = np.linalg.norm(span_src[:, None] - span_src[None], axis=-1)
    d_new = np.linalg.norm(span_new[:, None] - span_new[None], axis=-1)
    np.testing.assert_allclose(d_new, d_src, atol=1e-3)
    # Heights change only where foot locking lowers the pelvis, by no more than it reports.
    drop = read_report(str(tmp_path / "edits.usda")).report.agents["/walk"].max_pelvis_drop or 0.0
    assert np.all(hips_new[:, 1] <= hips_src[:, 1] + 1e-4)
    assert np.all(hips_new[:, 1] >= hips_src[:, 1] - drop - 1e-4)
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "edits.usda"))
    assert layer.GetPrimAtPath("/walk")
