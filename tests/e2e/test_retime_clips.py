"""Time-only edits written as value clips that re-time the source clip, checked against the baked form.

An agent whose joints change only in timing gets a SkelAnimation that references its source
clip and maps shot time to clip time (``clips:times``). Placed over the input and evaluated
by plain UsdSkel, it must play what the baked samples play, at every shot frame.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdSkel

from mocapedit.usd import bvh_usd
from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.tools import measure
from mocapedit.usd import evaluate

from conftest import SHARED_MOCAP, world_joints

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


#: Metres. Between two source samples the value clip plays the source as USD interpolates
#: it (GfSlerp on float quaternions), the baked form holds the project's own slerp rounded
#: to float: they differ by up to 2e-6 m on these clips at 120 fps (measured), and by up to
#: 4.4e-5 m on a CMU walk at 60 fps played at 24 fps. On the source samples themselves the
#: two are the same to 1e-6.
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
        # And it is the source as USD plays it, at the source time the time map gives.
        clip = layer.GetPrimAtPath(f"/MocapEdit/Animations/World_Crowd_{agent}")
        pairs = np.asarray(clip.GetInfo("clips")["default"]["times"])
        source_times = np.interp(times, pairs[:, 0], _anim_times(src, path))
        source = np.concatenate([_world(src, path, [t]) for t in source_times]) * mpu
        assert np.abs(source - a).max() < 1e-9, agent
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


def test_a_clip_the_input_already_retimes_with_value_clips_is_baked(tmp_path):
    clip = walker.walk(frames=FRAMES, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)])
    # The input plays the clip at half speed through its own value clip.
    anim = stage.GetPrimAtPath(f"{CROWD}/a/Skel/Anim")
    clips = Usd.ClipsAPI(anim)
    clips.SetClipAssetPaths([Sdf.AssetPath("./clips/walk.usda")])
    clips.SetClipPrimPath("/Skel/Anim")
    clips.SetClipActive([(0.0, 0.0)])
    clips.SetClipTimes([(0.0, 0.0), (2.0 * (FRAMES - 1), FRAMES - 1.0)])
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/a", 30, 40.0)
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), guides=False)
    spec = result.layer.GetPrimAtPath("/MocapEdit/Animations").nameChildren[0]
    assert not spec.HasInfo("clips")
    assert result.layer.GetNumTimeSamplesForPath(spec.path.AppendProperty("rotations")) > 0
    assert max(c["residual"] for c in result.report.constraints) < 1e-6


MOCAP_WALK = SHARED_MOCAP / "cc_cmu07_01_walk.bvh"


@pytest.mark.realdata
@pytest.mark.skipif(not MOCAP_WALK.exists(), reason="../shared/mocap is absent")
def test_a_cmu_walk_retimed_on_a_24_fps_z_up_stage_plays_the_source_at_its_new_times(tmp_path):
    """The CMU walk (60 fps, the 100-joint CC rig) referenced 10 time codes late into a 24 fps,
    Z-up centimetre shot; one frame pushed 8 time codes later."""
    bvh_usd.import_bvh(str(MOCAP_WALK), str(tmp_path / "walk.usda"),
                       bvh_usd.ImportSettings(up_axis="Z", scale=1 / 0.45 * 2.54, meters_per_unit=0.01))
    layer = Sdf.Layer.CreateNew(str(tmp_path / "shot.usda"))
    layer.timeCodesPerSecond = layer.framesPerSecond = 24
    layer.pseudoRoot.SetInfo("upAxis", "Z")
    layer.pseudoRoot.SetInfo("metersPerUnit", 0.01)
    layer.Save()
    stage = Usd.Stage.Open(layer)
    stage.DefinePrim(f"{CROWD}/walker", "SkelRoot").ApplyAPI("MocapAgentAPI")
    stage.DefinePrim(f"{CROWD}/walker/Skel").GetReferences().AddReference(
        "./walk.usda", "/Skel", Sdf.LayerOffset(10.0, 1.0))
    times = _anim_times(stage, f"{CROWD}/walker")
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/walker", 120, float(times[120] + 8.0))
    stage.GetRootLayer().Save()
    _, out, layer_path = _composed(tmp_path, str(tmp_path / "shot.usda"), "clips")
    _, ref, _ = _composed(tmp_path, str(tmp_path / "shot.usda"), "baked", bake_timing=True)
    edits = Sdf.Layer.FindOrOpen(str(layer_path))
    pairs = np.asarray(edits.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_walker").GetInfo("clips")
                       ["default"]["times"])
    shot = np.arange(np.ceil(pairs[0, 0]), np.floor(pairs[-1, 0]) + 1)
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    path = f"{CROWD}/walker"
    edited = _world(out, path, shot)
    source = np.concatenate([_world(src, path, [t]) for t in np.interp(shot, pairs[:, 0], times)])
    assert np.abs(edited - source).max() * 0.01 < 1e-9
    # The baked form, on the same shot frames: 4.4e-5 m apart at most (measured), see BETWEEN_SAMPLES.
    assert np.abs(edited - _world(ref, path, shot)).max() * 0.01 < 1e-4
    assert np.abs(_world(src, path, shot) - edited).max() * 0.01 > 0.1   # it was retimed


def test_locked_legs_are_baked_as_rotations_over_the_retimed_source(tmp_path):
    """Foot locking changes only leg rotations (and lowers the pelvis): the agent's animation
    re-times its source clip by a value clip and holds only the rotations as samples; the
    lowering rides on the agent's transform op. Evaluated by UsdSkel it plays what the fully
    baked form plays, and the layer is smaller."""
    clip = walker.walk(frames=FRAMES, name="walk")
    specs = [examples.AgentSpec("a", clip, (0, 0, 0), 0.0, 0.0),
             examples.AgentSpec("b", clip, (3, 0, 0), 20.0, 5.0)]
    shot = tmp_path / "shot.usda"
    stage = examples.build_crowd_stage(shot, specs)
    # Both bent sideways at their last frame (a: also played later from frame 30).
    for agent, start, dx in (("a", 0.0, 0.9), ("b", 5.0, -0.8)):
        path = f"{CROWD}/{agent}"
        ends = world_joints(stage, f"{path}/Skel", [start, start + FRAMES - 1])[:, 0]
        ends[:, 1] = 0.0
        examples.add_position_constraint(stage, f"/Edits/{agent}0", path, 0, tuple(map(float, ends[0])))
        examples.add_position_constraint(stage, f"/Edits/{agent}1", path, FRAMES - 1,
                                         tuple(map(float, ends[1] + [dx, 0.0, 0.0])))
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/a", 30, 36.5)
    stage.GetRootLayer().Save()
    clips, out, layer_path = _composed(tmp_path, str(shot), "clips")
    baked, ref, baked_path = _composed(tmp_path, str(shot), "baked", bake_timing=True)
    assert clips.report.stats.foot_locked_agents == baked.report.stats.foot_locked_agents == 2
    assert clips.report.agent(f"{CROWD}/a").max_pelvis_drop > 1e-3
    layer = Sdf.Layer.FindOrOpen(str(layer_path))
    for spec in layer.GetPrimAtPath("/MocapEdit/Animations").nameChildren:
        assert spec.HasInfo("clips")
        samples = {a.name: layer.GetNumTimeSamplesForPath(a.path) for a in spec.attributes}
        assert samples.get("rotations", 0) > 0 and not samples.get("translations") and not samples.get("scales")
    assert baked_path.stat().st_size > 1.3 * layer_path.stat().st_size
    src = Usd.Stage.Open(str(shot))
    for agent in ("a", "b"):
        path = f"{CROWD}/{agent}"
        times = _anim_times(ref, path)
        a, b = _world(out, path, times), _world(ref, path, times)
        assert np.abs(a - b).max() < 1e-6, agent
        # Between two shot frames the value clip plays the source's translations at the time the
        # map gives, the baked form interpolates its frames: a warped agent differs by a few
        # millimetres there (2.3 mm measured), an unwarped one by float rounding.
        between = times[:-1] + 0.5
        apart = np.abs(_world(out, path, between) - _world(ref, path, between)).max()
        assert apart < (5e-3 if agent == "a" else BETWEEN_SAMPLES), agent
        # The locked legs did change the pose: the source carried along plays otherwise.
        assert np.abs(_world(src, path, times) - a).max() > 1e-2
        # Measured on the stages by FK, the agent pairs with its source by the frame it plays
        # (the value clip's times), and its figures are the report's.
        fk = measure.plausibility(src, out, path)
        entry = clips.report.agent(path).plausibility
        assert np.allclose(fk.time_warp, entry.time_warp, atol=1e-6), agent
        assert abs(fk.length_ratio - entry.length_ratio) < 1e-4, agent
        assert abs(fk.max_direction_deviation - entry.max_direction_deviation) < 0.5, agent


@pytest.mark.parametrize("shift", [-9.0, -7.3])
def test_an_agent_played_earlier_and_locked_is_measured_by_fk_without_a_false_spin(tmp_path, shift):
    """A walk played from ``shift`` and a tenth slower, bent by a handle: its value clip maps its
    translations to shot times a rounding away (1e-15) from the shot frames its locked rotations
    are baked on. Composed, the animation has two samples at nearly the same time; measured by
    FK between them the body turned at 1e10 degrees per second (a spin), or the measure stopped
    with "edited sample times must increase". A sample time is one time, however it is rounded."""
    frames = 97
    clip = walker.walk(frames=frames, name="walk")
    shot = tmp_path / "shot.usda"
    stage = examples.build_crowd_stage(shot, [examples.AgentSpec("a", clip)])
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/aside", a, frames // 2, (0.5, 0.0, 2.5))
    examples.add_time_constraint(stage, "/Edits/first", a, 0, shift)
    examples.add_time_constraint(stage, "/Edits/last", a, frames - 1, shift + (frames - 1) * 1.1)
    stage.GetRootLayer().Save()
    result, out, _ = _composed(tmp_path, str(shot), "edits")
    assert result.report.stats.foot_locked_agents == 1
    times = evaluate.sample_times(out, a)
    assert np.diff(times).min() > 1e-3
    fk = measure.plausibility(Usd.Stage.Open(str(shot)), out, a)
    # The walker's source turns at up to 30 degrees per second; a spin is 900.
    assert not fk.spins and fk.spin_frames == 0 and fk.max_extra_facing_rate < 15.0
    assert abs(fk.max_facing_rate - result.report.agent(a).plausibility.max_facing_rate) < 0.1


def test_a_retimed_agent_far_from_the_origin_turned_by_its_path_stays_on_it_between_samples(tmp_path):
    """A walker 250 m from the stage origin, slowed by a time constraint and bent 72 cm aside at
    its middle by a handle (its turn goes from +29 to -33 degrees): its re-timed clip's samples
    fall between the shot's frames, and its transform ops (a translate and a turn about the
    parent's origin) were sampled there alone. USD interpolates each op on its own, so at the
    frames between, the turn swung the body about the far origin off its path: up to 15 cm here
    (18 cm within one frame in a dense crowd 55 m out). Sampled at every whole frame as well, it
    plays what the baked form plays there."""
    clip = walker.walk(frames=FRAMES, fps=24.0, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip, (180.0, 0, 170.0), 40.0, 0.0)],
                                       fps=24.0)
    stage.SetEndTimeCode(2 * FRAMES)
    a = f"{CROWD}/a"
    examples.add_time_constraint(stage, "/Edits/keep", a, 0, 0.0)
    examples.add_time_constraint(stage, "/Edits/slow", a, 40, 75.0)
    start, end = evaluate.agent_root_positions(stage, a, [0.0, 59.0])
    examples.add_position_constraint(stage, "/Edits/start", a, 0, tuple(start))
    examples.add_position_constraint(stage, "/Edits/end", a, 59, tuple(end))
    middle = evaluate.agent_root_positions(stage, a, [30.0])[0] + np.array([0.6, 0.0, -0.4])
    examples.add_position_constraint(stage, "/Edits/aside", a, 30, tuple(middle))
    stage.GetRootLayer().Save()
    shot = str(tmp_path / "shot.usda")
    retimed, out, layer_path = _composed(tmp_path, shot, "clips", foot_locking=False)
    baked, ref, _ = _composed(tmp_path, shot, "baked", bake_timing=True, foot_locking=False)
    clips = Sdf.Layer.FindOrOpen(str(layer_path)).GetPrimAtPath("/MocapEdit/Animations").nameChildren
    assert len(clips) == 1, "the walker's clip is re-timed by a value clip"
    whole = _anim_times(ref, a)
    assert len(whole) > FRAMES + 10
    gap = np.abs(_world(out, a, whole) - _world(ref, a, whole)).max()
    assert gap < 1e-4, gap


def test_a_120_fps_walk_under_a_24_fps_shot_with_locked_legs_is_measured_where_the_report_measures_it(tmp_path):
    """A 120 fps walk under a 24 fps shot, bent by handles so that its legs are locked, keeps its
    timing: its value clip plays the clip on its own samples, the locked rotations baked on the same.
    The FK tool measured its feet at the shot's whole frames (a fifth of the samples: 5.08 cm/s in
    the source) while the report measured them at the clip's (10.11): it is now measured there
    too, as an agent without a value clip is."""
    frames = 480
    clip = walker.walk(frames=frames, fps=120.0, name="walk120")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], fps=120.0)
    layer = stage.GetRootLayer()
    layer.timeCodesPerSecond = layer.framesPerSecond = 24.0
    layer.startTimeCode, layer.endTimeCode = 0.0, (frames - 1) * 0.2
    layer.Save()
    stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    a = f"{CROWD}/a"
    ends = evaluate.agent_root_positions(stage, a, [0.0, (frames // 2) * 0.2, (frames - 1) * 0.2])
    examples.add_position_constraint(stage, "/Edits/keep", a, 0, tuple(map(float, ends[0])))
    examples.add_position_constraint(stage, "/Edits/mid", a, frames // 2, tuple(map(float, ends[1] + [0.6, 0, 0])))
    examples.add_position_constraint(stage, "/Edits/end", a, frames - 1, tuple(map(float, ends[2])))
    stage.GetRootLayer().Save()
    result, out, _ = _composed(tmp_path, str(tmp_path / "shot.usda"), "locked")
    entry = result.report.agents[a]
    assert entry["footContactsLocked"] > 0, "the legs are locked"
    assert evaluate.played_frames(out, a, [0.0, 1.0]) is not None, "played through a value clip"
    fk = measure.plausibility(stage, out, a)
    assert fk.foot_skate_source == pytest.approx(entry["footSkateSource"], rel=1e-3)
    assert fk.foot_skate_edited == pytest.approx(entry["footSkateEdited"], rel=1e-3)
