"""The output-layer contract: what the passes produce plays through plain UsdSkel.

These tests register small passes by hand (a rigid path move, a time shift, a pose
change) and check the composed stage with UsdSkel forward kinematics.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd

from mocapedit.pipeline import processor
from mocapedit.pipeline.passes import Pass
from mocapedit.pipeline.processor import EditedPath, solve

from conftest import world_joints, write_toy_stage


@pytest.fixture
def with_pass(monkeypatch):
    def install(fn):
        monkeypatch.setattr(processor, "PASSES", (Pass("test", fn),))
    return install


def _compose(tmp_path, stage_path):
    edits, composed = tmp_path / "e.usda", tmp_path / "c.usda"
    result = solve(str(stage_path), output=str(edits), composed=str(composed))
    return result, Usd.Stage.Open(str(composed))


@pytest.mark.parametrize("up_axis", ["Y", "Z"])
def test_a_turned_and_moved_path_moves_the_whole_body_rigidly(tmp_path, with_pass, up_axis):
    src_path = write_toy_stage(tmp_path / "s.usda", up_axis=up_axis, agents=2)
    angle, shift = 0.7, np.array([30.0, -12.0])
    rot = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])

    def move(ctx):
        traj = ctx.trajectories["/World/agent1"]
        ctx.paths["/World/agent1"] = EditedPath(ground=traj.ground @ rot + shift, heading=traj.heading + angle)

    with_pass(move)
    result, out = _compose(tmp_path, src_path)
    assert result.report.stats["editedAgents"] == 1
    src = Usd.Stage.Open(str(src_path))
    times = np.arange(48)
    a = world_joints(src, "/World/agent1/Skel", times)
    b = world_joints(out, "/World/agent1/Skel", times)
    up = 2 if up_axis == "Z" else 1
    ground = [0, 1] if up_axis == "Z" else [0, 2]
    sign = np.array([1.0, 1.0]) if up_axis == "Z" else np.array([1.0, -1.0])
    expect = (a[..., ground] * sign) @ rot + shift
    np.testing.assert_allclose(b[..., ground] * sign, expect, atol=1e-6 * 100)
    np.testing.assert_allclose(b[..., up], a[..., up], atol=1e-9)
    # The agent that was not edited is not written and plays its source exactly.
    layer = result.layer
    assert not layer.GetPrimAtPath("/World/agent0")
    np.testing.assert_allclose(world_joints(out, "/World/agent0/Skel", times),
                               world_joints(src, "/World/agent0/Skel", times), atol=1e-9)


class _Lift:
    def apply(self, pose, out_times, src_frames):
        pose.translations[:, 1, 2] += 5.0
        return pose


def test_a_time_map_and_a_pose_edit_are_baked_on_shot_frames(tmp_path, with_pass):
    src_path = write_toy_stage(tmp_path / "s.usda", agents=1)

    def retime(ctx):
        agent = ctx.data.agents["/World/agent0"]
        ctx.time_maps["/World/agent0"] = agent.sample_times * 2.0 + 10.0  # half speed, later

        ctx.pose_edits["/World/agent0"] = [_Lift()]

    with_pass(retime)
    result, out = _compose(tmp_path, src_path)
    anim = out.GetPrimAtPath("/MocapEdit/Animations/World_agent0")
    assert anim and anim.GetTypeName() == "SkelAnimation"
    samples = anim.GetAttribute("translations").GetTimeSamples()
    assert samples[0] == 10.0 and samples[-1] == 10.0 + 2 * 47 and len(samples) == 2 * 47 + 1
    src = Usd.Stage.Open(str(src_path))
    frames = np.array([0, 5, 20, 47])
    a = world_joints(src, "/World/agent0/Skel", frames)
    b = world_joints(out, "/World/agent0/Skel", frames * 2.0 + 10.0)
    np.testing.assert_allclose(b[:, [0, 2, 3]], a[:, [0, 2, 3]] + [0, 0, 5.0] * np.array([0, 1, 1])[None, :, None],
                               atol=1e-4)
    np.testing.assert_allclose(b[:, 1], a[:, 1] + [0, 0, 5.0], atol=1e-4)
    # Half way between two frames the pose is interpolated.
    mid = world_joints(out, "/World/agent0/Skel", [11.0])[0, 0]
    np.testing.assert_allclose(mid, (a[0, 0] + world_joints(src, "/World/agent0/Skel", [1])[0, 0]) / 2, atol=1e-4)
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "e.usda"))
    skel = layer.GetPrimAtPath("/World/agent0/Skel")
    assert skel.relationships["skel:animationSource"].targetPathList.explicitItems == \
        [Sdf.Path("/MocapEdit/Animations/World_agent0")]


def test_the_passes_run_in_the_listed_order_and_time_each(tmp_path, monkeypatch):
    from mocapedit.pipeline import passes
    assert [p.name for p in processor.PASSES] == ["layering-check", "path", "time", "collisions", "stance",
                                                  "layering", "foot locking"]
    ran = []
    monkeypatch.setattr(processor, "PASSES", tuple(
        Pass(p.name, lambda ctx, p=p: (ran.append(p.name), p.run(ctx))) for p in reversed(passes.PASSES)))
    result = solve(str(write_toy_stage(tmp_path / "s.usda", agents=2)))
    assert ran == [p.name for p in reversed(passes.PASSES)], "the processor runs the list as it is, no sorting"
    assert all(p.name in result.report.timings for p in passes.PASSES)
