"""Time-only edits written as value clips that re-time the source clip, checked against the baked form.

An agent whose joints change only in timing gets a SkelAnimation that references its source
clip and maps shot time to clip time (``clips:times``). Placed over the input and evaluated
by plain UsdSkel, it must play what the baked samples play, at every shot frame.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdSkel

from mocapedit import examples, walker
from mocapedit.processor import solve

from conftest import world_joints

CROWD = "/World/Crowd"
FRAMES = 60


def _stage(tmp_path, up="Y", mpu=1.0, fps=24.0, stage_fps=None, clip_format="usda"):
    clip = walker.walk(frames=FRAMES, fps=fps, up=up, meters_per_unit=mpu, name="walk")
    turn = walker.turn(frames=FRAMES, fps=fps, up=up, meters_per_unit=mpu, name="turn")
    specs = [examples.AgentSpec("a", clip, (0, 0, 0), 0.0, 0.0),
             examples.AgentSpec("b", turn, (2 / mpu, 0, 0), 30.0, 7.0),
             examples.AgentSpec("c", clip, (-2 / mpu, 0, 0), -20.0, 13.5),
             examples.AgentSpec("still", clip, (0, 0, 4 / mpu), 0.0, 2.0)]
    path = tmp_path / "shot.usda"
    stage = examples.build_crowd_stage(path, specs, up_axis=up, meters_per_unit=mpu, fps=fps,
                                       clip_format=clip_format)
    if stage_fps is not None:
        # Clips at their own rate under a stage at another: USD scales the references.
        layer = stage.GetRootLayer()
        layer.timeCodesPerSecond = layer.framesPerSecond = stage_fps
        layer.endTimeCode = layer.endTimeCode * stage_fps / fps
        layer.Save()
        stage = Usd.Stage.Open(str(path))
    scale = (stage_fps or fps) / fps
    # Frame k of an agent with offset o plays at o + k * scale: push some frames later.
    examples.add_time_constraint(stage, "/Edits/a_late", f"{CROWD}/a", 30, 30 * scale + 6.5)
    examples.add_time_constraint(stage, "/Edits/b_early", f"{CROWD}/b", 40, 7 + 40 * scale - 4.0)
    examples.add_time_constraint(stage, "/Edits/b_keep", f"{CROWD}/b", 5, 7 + 5 * scale)
    examples.add_sync_constraint(stage, "/Edits/sync", f"{CROWD}/c", 20, f"{CROWD}/a", 20, 1.25)
    stage.GetRootLayer().Save()
    return str(path)


def _world(stage, agent, times):
    return world_joints(stage, f"{agent}/Skel", times)


def _composed(tmp_path, shot, name, **kwargs):
    edits, composed = tmp_path / f"{name}.usda", tmp_path / f"{name}.composed.usda"
    result = solve(shot, output=str(edits), composed=str(composed), guides=False, **kwargs)
    return result, Usd.Stage.Open(str(composed)), edits


def _anim_times(stage, agent):
    skel = UsdSkel.BindingAPI(stage.GetPrimAtPath(f"{agent}/Skel"))
    anim = stage.GetPrimAtPath(skel.GetAnimationSourceRel().GetTargets()[0])
    return np.asarray(anim.GetAttribute("rotations").GetTimeSamples())


#: Metres. Between two source samples USD interpolates the clip's float quaternions in
#: single precision, the baked form in double before rounding to float: at 120 fps, where
#: neighbouring samples are close, the poses differ by up to 2e-6 m (measured); on the
#: source samples themselves the two are the same to 1e-6.
BETWEEN_SAMPLES = 5e-6


@pytest.mark.parametrize("up,mpu,fps,stage_fps", [("Y", 1.0, 24.0, None), ("Z", 0.01, 30.0, None),
                                                   ("Y", 1.0, 60.0, None), ("Z", 0.01, 120.0, 24.0)])
def test_value_clips_play_what_the_baked_samples_play(tmp_path, up, mpu, fps, stage_fps):
    shot = _stage(tmp_path, up, mpu, fps, stage_fps)
    retimed, out, layer_path = _composed(tmp_path, shot, "clips")
    baked, ref, _ = _composed(tmp_path, shot, "baked", bake_timing=True)
    assert retimed.report.stats["editedAgents"] == baked.report.stats["editedAgents"] == 3
    layer = Sdf.Layer.FindOrOpen(str(layer_path))
    anims = layer.GetPrimAtPath("/MocapEdit/Animations").nameChildren
    assert len(anims) == 3
    for spec in anims:
        # Nothing baked: the animation re-times its source clip.
        assert len(spec.GetInfo("clips")["default"]["times"]) == FRAMES
        assert not any(layer.GetNumTimeSamplesForPath(a.path) for a in spec.attributes)
    src = Usd.Stage.Open(shot)
    scale = (stage_fps or fps) / fps
    for agent in ("a", "b", "c"):
        path = f"{CROWD}/{agent}"
        # Every baked sample (the shot's frames the clip covers), and before and after the clip.
        baked_times = _anim_times(ref, path)
        times = np.concatenate([[baked_times[0] - 3.5], baked_times, [baked_times[-1] + 2.0]])
        a, b = _world(out, path, times) * mpu, _world(ref, path, times) * mpu
        assert np.abs(a - b).max() < BETWEEN_SAMPLES, agent
        # The edit did something: the source plays otherwise.
        assert np.abs(_world(src, path, times) * mpu - a).max() > 1e-3
    # A constrained frame plays exactly the source frame, exactly at its time.
    frame_time = {"a": (30, 30 * scale + 6.5), "b": (40, 7 + 40 * scale - 4.0)}
    for agent, (frame, t) in frame_time.items():
        offset = {"a": 0.0, "b": 7.0}[agent]
        edited = _world(out, f"{CROWD}/{agent}", [t])
        source = _world(src, f"{CROWD}/{agent}", [offset + frame * scale])
        assert np.abs(edited - source).max() * mpu < 1e-6
    # The agent without edits is not written.
    assert not layer.GetPrimAtPath(f"{CROWD}/still")


def test_value_clip_layers_are_smaller_and_deterministic(tmp_path):
    shot = _stage(tmp_path)
    _, _, clips = _composed(tmp_path, shot, "clips")
    _, _, again = _composed(tmp_path, shot, "clips")
    _, _, baked = _composed(tmp_path, shot, "baked", bake_timing=True)
    assert clips.read_bytes() == again.read_bytes()
    assert clips.stat().st_size < 0.5 * baked.stat().st_size
    # The clip is found relative to the edits layer, so the folder can move.
    assert "@./clips/walk.usda@" in clips.read_text()


def test_layered_and_in_memory_clips_are_still_baked(tmp_path):
    clip = walker.walk(frames=FRAMES, name="walk")
    on_disk = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)])
    # The same shot flattened into memory: its clip lives in an anonymous layer.
    stage = Usd.Stage.Open(on_disk.Flatten())
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/a", 30, 36.5)
    result = solve(stage, guides=False)
    spec = result.layer.GetPrimAtPath("/MocapEdit/Animations").nameChildren[0]
    assert not spec.HasInfo("clips")
    assert result.layer.GetNumTimeSamplesForPath(spec.path.AppendProperty("rotations")) > 0
