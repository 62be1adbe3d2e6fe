"""Automatic stationary tags: the detector on known signals, then on imported clips whose
idle section is known (generated) or visible (the real start-walk-stop captures)."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd

from mocapedit.usd import bvh_usd, reader
from mocapedit.data import examples, walker
from mocapedit.geometry import stationary
from mocapedit.usd.bvh_usd import ImportSettings
from mocapedit.geometry.stationary import DetectSettings

from bvh_reference import REAL_MOCAP
from bvhgen import walk_idle_walk, write_bvh
from conftest import run_cli

FPS = 30.0


def _signal(segments):
    """(seconds, ground (F,2) metres, heading (F,)) from (duration, speed m/s, turn deg/s) pieces."""
    speed, turn = [], []
    for duration, v, w in segments:
        n = int(round(duration * FPS))
        speed += [v] * n
        turn += [w] * n
    speed, turn = np.array(speed), np.radians(np.array(turn))
    heading = np.cumsum(turn) / FPS
    step = speed / FPS
    ground = np.cumsum(np.stack([step, np.zeros_like(step)], 1), axis=0)
    return np.arange(len(speed)) / FPS, ground, heading


def test_a_still_section_between_two_walks_is_one_range_trimmed_by_half_a_window():
    seconds, ground, heading = _signal([(3, 1.2, 0), (3, 0, 0), (4, 1.2, 0)])
    ranges = stationary.detect(seconds, ground, heading, DetectSettings(window=0.2))
    # The root stands at one place from frame 89 to 179; a frame is still when the whole
    # window of 3 frames either side is.
    assert [(r.first, r.last) for r in ranges] == [(92, 176)]
    assert ranges[0].max_speed == 0.0 and ranges[0].duration == pytest.approx(85 / FPS)


def test_short_stops_turns_on_the_spot_and_slow_drifts():
    settings = DetectSettings()
    # A stop shorter than min-duration is not a range; a longer one is.
    seconds, ground, heading = _signal([(1, 1, 0), (0.4, 0, 0), (1, 1, 0), (1.0, 0, 0), (1, 1, 0)])
    assert len(stationary.detect(seconds, ground, heading, settings)) == 1
    # Turning on the spot faster than max-turn is not stationary; slower is.
    seconds, ground, heading = _signal([(2, 0, 90.0)])
    assert stationary.detect(seconds, ground, heading, settings) == []
    seconds, ground, heading = _signal([(2, 0, 10.0)])
    assert [(r.first, r.last) for r in stationary.detect(seconds, ground, heading, settings)] == [(0, 59)]
    # A drift just under the speed threshold is stationary; just over is not.
    for v, count in ((0.14, 1), (0.16, 0)):
        seconds, ground, heading = _signal([(2, v, 0)])
        assert len(stationary.detect(seconds, ground, heading, settings)) == count


def test_a_brief_fidget_inside_an_idle_is_bridged_by_max_gap():
    seconds, ground, heading = _signal([(2, 0, 0), (0.1, 1.5, 0), (2, 0, 0)])
    split = stationary.detect(seconds, ground, heading, DetectSettings(max_gap=0.0, window=0.1))
    joined = stationary.detect(seconds, ground, heading, DetectSettings(max_gap=0.3, window=0.1))
    assert len(split) == 2 and len(joined) == 1
    assert joined[0].first == split[0].first and joined[0].last == split[1].last
    # The figures of a range are those of its still frames, within the thresholds; the
    # bridged fidget is counted apart with its own figures.
    settings = DetectSettings(max_gap=0.3, window=0.1)
    assert joined[0].max_speed <= settings.max_speed and joined[0].max_turn <= settings.max_turn
    assert joined[0].bridged == joined[0].last - joined[0].first + 1 - (split[0].last - split[0].first + 1) \
        - (split[1].last - split[1].first + 1)
    assert joined[0].bridged > 0 and joined[0].bridged_max_speed > settings.max_speed


def test_settings_are_checked():
    with pytest.raises(ValueError, match="max-speed"):
        DetectSettings(max_speed=0).validate()
    with pytest.raises(ValueError, match="max-gap"):
        DetectSettings(max_gap=-1).validate()


def test_facing_follows_yaw_whatever_the_joint_convention():
    yaw = np.linspace(0, 3.0, 50)
    c, s = np.cos(yaw), np.sin(yaw)
    # A Y-up joint whose local X points up and whose local Z turns with the yaw.
    rot = np.zeros((50, 3, 3))
    rot[:, 0] = (0, 1, 0)
    rot[:, 1] = np.stack([-s, np.zeros(50), -c], 1)
    rot[:, 2] = np.stack([c, np.zeros(50), -s], 1)
    h = np.unwrap(stationary.facing(rot, "Y"))
    np.testing.assert_allclose(h - h[0], yaw - yaw[0], atol=1e-12)


def _walk_clip(tmp_path, agent: bool, up: str = "Y"):
    rig, values, idle = walk_idle_walk(fps=60.0)
    write_bvh(tmp_path / "walk.bvh", rig, values)
    bvh_usd.import_bvh(tmp_path / "walk.bvh", tmp_path / "walk.usda", ImportSettings(agent=agent, up_axis=up))
    return idle, len(values)


@pytest.mark.parametrize("agent,up", [(True, "Y"), (False, "Z")])
def test_the_idle_of_a_generated_walk_is_tagged_and_nothing_else(tmp_path, agent, up):
    anim_path = "/walk/Skel/Anim" if agent else "/Skel/Anim"
    (first, last), frames = _walk_clip(tmp_path, agent, up)
    out = run_cli("detect-stationary", tmp_path / "walk.usda", "-o", tmp_path / "tags.usda",
                  "--composed", tmp_path / "tagged.usda")
    assert out.returncode == 0, out.stderr
    assert "1 stationary range" in out.stderr
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "tags.usda"))
    assert layer.GetPrimAtPath(anim_path).specifier == Sdf.SpecifierOver
    assert not layer.GetPrimAtPath(anim_path).nameParent.properties, "only the clip is touched"
    stage = Usd.Stage.Open(str(tmp_path / "tagged.usda"))
    anim = stage.GetPrimAtPath(anim_path)
    assert "MocapStationaryAPI:auto1" in anim.GetAppliedSchemas()
    a, b = anim.GetAttribute("stationary:auto1:frames").Get()
    fps = 60
    # Inside the idle up to the slow end of the ramps, and covering all but its edges.
    assert first - 0.15 * fps <= a <= first + 0.3 * fps, (a, first)
    assert last - 0.3 * fps <= b <= last + 0.15 * fps, (b, last)
    if agent:
        # The solve reads the tags back from the composed stage.
        data = reader.read_stage(stage)
        assert data.agents["/walk"].stationary == [("auto1", a, b)]
    # The clip itself is untouched.
    assert not Usd.Stage.Open(str(tmp_path / "walk.usda")).GetPrimAtPath(anim_path).GetAppliedSchemas()

    # Running again over the tagged stage proposes nothing new (it proposed the same range again
    # as auto2); the tag already there is named.
    again = run_cli("detect-stationary", tmp_path / "tagged.usda", "-o", tmp_path / "tags2.usda")
    assert again.returncode == 0, again.stderr
    assert "0 stationary ranges" in again.stderr and "auto1" in again.stderr and "already tagged" in again.stderr
    tags2 = Sdf.Layer.FindOrOpen(str(tmp_path / "tags2.usda"))
    assert not tags2.GetPrimAtPath(anim_path)


def test_thresholds_are_options_and_bad_input_writes_nothing(tmp_path):
    _walk_clip(tmp_path, agent=True)
    strict = run_cli("detect-stationary", tmp_path / "walk.usda", "-o", tmp_path / "t.usda",
                     "--max-speed", "0.001")
    assert strict.returncode == 0 and "0 stationary ranges" in strict.stderr
    loose = run_cli("detect-stationary", tmp_path / "walk.usda", "-o", tmp_path / "t.usda",
                    "--max-speed", "5", "--max-turn", "1000", "--min-duration", "0.1")
    assert loose.returncode == 0
    assert "frames 0-" in loose.stderr and "1 stationary range" in loose.stderr
    bad = run_cli("detect-stationary", tmp_path / "walk.usda", "-o", tmp_path / "bad.usda", "--window", "0")
    assert bad.returncode == 1 and "window must be a positive number" in bad.stderr
    assert not (tmp_path / "bad.usda").exists()
    empty = tmp_path / "empty.usda"
    empty_stage = Usd.Stage.CreateNew(str(empty))
    empty_stage.GetRootLayer().Save()
    none = run_cli("detect-stationary", empty, "-o", tmp_path / "bad.usda")
    assert none.returncode == 1 and "no clip to measure" in none.stderr
    joint = run_cli("detect-stationary", tmp_path / "walk.usda", "-o", tmp_path / "bad.usda",
                    "--root-joint", "Tail")
    assert joint.returncode == 1 and "'Tail' is not a joint" in joint.stderr
    assert not (tmp_path / "bad.usda").exists()


@pytest.mark.parametrize("fps,up,mpu", [(24.0, "Y", 1.0), (30.0, "Z", 0.01), (60.0, "Y", 0.01)])
def test_the_walkers_stop_is_tagged_over_its_standing_frames(tmp_path, fps, up, mpu):
    """mocapedit.data.walker's walk-idle-walk: the root stands exactly still on known frames."""
    clip, (first, last) = walker.walk_idle_walk(frames=int(8 * fps), fps=fps, idle_frames=int(2 * fps), up=up,
                                                meters_per_unit=mpu)
    examples.write_clip_layer(clip, tmp_path / "clip.usda")
    out = run_cli("detect-stationary", tmp_path / "clip.usda", "-o", tmp_path / "tags.usda")
    assert out.returncode == 0, out.stderr
    stage = Usd.Stage.Open(str(tmp_path / "clip.usda"))
    stage.GetRootLayer().subLayerPaths.append(str(tmp_path / "tags.usda"))
    anim = stage.GetPrimAtPath(examples.CLIP_ANIMATION_PATH)
    assert [s for s in anim.GetAppliedSchemas() if s.startswith("MocapStationaryAPI")] == ["MocapStationaryAPI:auto1"]
    a, b = anim.GetAttribute("stationary:auto1:frames").Get()
    # Every standing frame is tagged; the tag reaches at most 0.3 s into the walk's ease
    # out and in, where the root moves slower than the speed threshold.
    assert a <= first and b >= last, ((a, b), (first, last))
    assert a >= first - 0.3 * fps and b <= last + 0.3 * fps, ((a, b), (first, last))


def test_on_a_crowd_stage_each_agent_playing_a_stop_is_tagged(tmp_path):
    stop_go, (first, last) = walker.walk_idle_walk(frames=144, fps=24.0, idle_frames=48)
    walk = walker.walk(frames=144, fps=24.0)
    agents = [examples.AgentSpec("a0", stop_go, (0, 0, 0), 0.0),
              examples.AgentSpec("a1", stop_go, (300, 0, 0), 70.0, time_offset=6.0),
              examples.AgentSpec("a2", walk, (-300, 0, 0), 0.0)]
    examples.build_crowd_stage(tmp_path / "shot.usda", agents, fps=24.0)
    out = run_cli("detect-stationary", tmp_path / "shot.usda", "-o", tmp_path / "tags.usda", "--composed",
                  tmp_path / "tagged.usda")
    assert out.returncode == 0, out.stderr
    data = reader.read_stage(Usd.Stage.Open(str(tmp_path / "tagged.usda")))
    tags = {p: a.stationary for p, a in data.agents.items()}
    assert tags["/World/Crowd/a2"] == []
    # A time offset keeps frame numbers: both agents get the same range of their clip.
    assert tags["/World/Crowd/a0"] == tags["/World/Crowd/a1"]
    (name, a, b), = tags["/World/Crowd/a0"]
    assert a <= first and b >= last


START_WALK_STOP = ["cmu131_01_start_walk_stop.bvh", "cmu131_02_start_walk_stop.bvh"]


@pytest.mark.realdata
@pytest.mark.parametrize("name", START_WALK_STOP)
def test_real_start_walk_stop_clips_are_tagged_where_they_stand(tmp_path, name):
    path = REAL_MOCAP / name
    if not path.is_file():
        pytest.skip("../shared/mocap is not present")
    bvh_usd.import_bvh(path, tmp_path / "c.usda", ImportSettings(scale=0.0254 / 0.45 / 0.01, agent=True))
    out = run_cli("detect-stationary", tmp_path / "c.usda", "-o", tmp_path / "t.usda")
    assert out.returncode == 0, out.stderr
    stage = Usd.Stage.Open(str(tmp_path / "c.usda"))
    stage.GetRootLayer().subLayerPaths.append(str(tmp_path / "t.usda"))
    data = reader.read_stage(stage)
    agent = next(iter(data.agents.values()))
    ranges = [(a, b) for _, a, b in agent.stationary]
    frames = agent.frame_count
    assert ranges, "the capture ends standing still"
    # The clip ends standing: the last range runs to the last frames.
    assert ranges[-1][1] >= frames - 10 and ranges[-1][1] - ranges[-1][0] >= 60
    # Nowhere during the walk (the middle third of the clip, where the hips travel at
    # walking speed) is tagged.
    middle = set(range(frames // 3, 2 * frames // 3))
    assert not any(middle & set(range(a, b + 1)) for a, b in ranges)
