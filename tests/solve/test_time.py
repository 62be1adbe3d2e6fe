"""Time edits end to end: time and sync constraints, the minimum interval, speed matching.

Every figure is measured on the composed stage (edits layer over the input) by UsdSkel
forward kinematics: the time at which a source frame plays is found from the joint
transforms, not read from the solver's arrays.
"""
from __future__ import annotations

import hashlib

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdSkel

from mocapedit.geometry import animation
from mocapedit.data import examples, walker
from mocapedit.inspect import metrics
from mocapedit.tools import measure
from mocapedit.usd import evaluate
from mocapedit.pipeline import processor
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.passes import Pass, time as time_pass
from mocapedit.pipeline.processor import EditedPath, solve

from conftest import run_cli

CROWD = "/World/Crowd"
FRAMES = 96


def _stage(tmp_path, agents, up="Y", mpu=1.0, name="shot.usda"):
    """A walker crowd: ``agents`` is a list of (name, position, yaw, time offset)."""
    clip = walker.walk(frames=FRAMES, up=up, meters_per_unit=mpu, name="walk" if up == "Y" else "walk_z")
    specs = [examples.AgentSpec(n, clip, p, yaw, offset) for n, p, yaw, offset in agents]
    stage = examples.build_crowd_stage(tmp_path / name, specs, up_axis=up, meters_per_unit=mpu)
    return stage


def _solve(tmp_path, stage, **overrides):
    stage.GetRootLayer().Save()
    path = stage.GetRootLayer().realPath
    edits, composed = tmp_path / "edits.usda", tmp_path / "edited.usda"
    result = solve(path, output=str(edits), composed=str(composed), **overrides)
    return result, Usd.Stage.Open(str(composed)), Usd.Stage.Open(path)


def _world_transforms(stage, agent, times):
    """(T,J,4,4) joint world transforms of an agent by UsdSkel."""
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath(f"{agent}/Skel"))
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetPrimAtPath(agent)), Usd.PrimDefaultPredicate)
    query = cache.GetSkelQuery(skel)
    return np.array([np.array(query.ComputeJointWorldTransforms(UsdGeom.XformCache(Usd.TimeCode(float(t)))))
                     for t in times])


def _time_error(src, out, agent, frame, time, moved=None):
    """Time codes between ``time`` and when ``frame`` really plays on ``out``, from the joints.

    The difference of the joint transforms, divided by how fast they change around the
    frame in the source. ``moved(m)`` maps source world transforms to where the edits
    put them (a path edit).
    """
    src_times = np.asarray(src.GetPrimAtPath(f"{agent}/Skel/Anim").GetAttribute("translations")
                           .GetTimeSamples())
    around = _world_transforms(src, agent, src_times[[max(frame - 1, 0), frame, min(frame + 1, len(src_times) - 1)]])
    if moved is not None:
        around = moved(around)
    got = _world_transforms(out, agent, [time])[0]
    speed = np.abs(around[2] - around[0]).max() / (src_times[min(frame + 1, len(src_times) - 1)]
                                                   - src_times[max(frame - 1, 0)])
    return np.abs(got - around[1]).max() / speed


def _shift_error(src, out, agent, shift, shot_times):
    """Time codes by which ``out`` at ``shot_times`` differs from ``src`` ``shift`` earlier.

    (The baked clip holds float32 values between keys, as the source does: ~1e-6 time codes.)
    """
    got = _world_transforms(out, agent, shot_times)
    want = _world_transforms(src, agent, np.asarray(shot_times) - shift)
    src_times = np.asarray(src.GetPrimAtPath(f"{agent}/Skel/Anim").GetAttribute("translations").GetTimeSamples())
    speed = np.abs(np.diff(_world_transforms(src, agent, src_times), axis=0)).max()
    return np.abs(got - want).max() / speed


def _play_time(src, out, agent, frame):
    """(shot time, its error in time codes) at which a source frame plays on ``out``.

    The authored sample of the baked animation whose pose is the frame's.
    """
    anim = UsdSkel.Skeleton(out.GetPrimAtPath(f"{agent}/Skel")).GetPrim().GetRelationship(
        "skel:animationSource").GetTargets()[0]
    times = np.asarray(out.GetPrimAtPath(anim).GetAttribute("translations").GetTimeSamples())
    errors = np.array([_time_error(src, out, agent, frame, t) for t in times])
    best = int(np.argmin(errors))
    return float(times[best]), float(errors[best])


@pytest.mark.parametrize("up,mpu", [("Y", 1.0), ("Z", 0.01)])
def test_three_beats_play_exactly_at_their_times(tmp_path, up, mpu):
    stage = _stage(tmp_path, [("dancer", (0, 0, 0), 0.0, 0.0)], up, mpu)
    beats = {20: 30.5, 50: 52.0, 80: 90.25}
    for i, (frame, t) in enumerate(beats.items()):
        examples.add_time_constraint(stage, f"/Edits/beat{i}", f"{CROWD}/dancer", frame, t)
    result, out, src = _solve(tmp_path, stage)
    for frame, t in beats.items():
        assert _time_error(src, out, f"{CROWD}/dancer", frame, t) < 1e-6
        # The measure tells a quarter of a frame apart.
        assert _time_error(src, out, f"{CROWD}/dancer", frame, t + 0.25) > 0.1
    entries = [c for c in result.report.constraints if c["kind"] == "time"]
    assert len(entries) == 3 and all(c["met"] and c["residual"] <= 1e-6 and c["hard"] for c in entries)
    agent = result.report.agents[f"{CROWD}/dancer"]
    assert agent["solver"] == "LDLT"
    assert 0.1 <= agent["minInterval"] < 1.0
    # The re-timed clip plays each source frame at its time on the map, the beats among them.
    anim = out.GetPrimAtPath("/MocapEdit/Animations").GetChildren()[0]
    samples = np.asarray(anim.GetAttribute("rotations").GetTimeSamples())
    assert 30.5 in samples and 90.25 in samples and 52.0 in samples
    assert np.all(np.diff(samples) > 0) and len(samples) == FRAMES


def test_one_time_constraint_shifts_the_clip_without_stretching_it(tmp_path):
    stage = _stage(tmp_path, [("walker", (0, 0, 0), 0.0, 3.0)])
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/walker", 30, 50.25)
    result, out, src = _solve(tmp_path, stage)
    shift = 50.25 - (30 + 3.0)
    for frame in (0, 30, FRAMES - 1):   # the constrained frame and the clip's ends are keyed exactly
        assert _time_error(src, out, f"{CROWD}/walker", frame, 3.0 + frame + shift) < 1e-6
    # Every whole shot frame plays the source a constant 17.25 time codes earlier.
    assert _shift_error(src, out, f"{CROWD}/walker", shift, np.arange(21.0, 115.0, 7.0)) < 1e-5
    assert result.report.agents[f"{CROWD}/walker"]["minInterval"] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("retimed", ["lead", "follow"])
def test_sync_offsets_hold_whichever_agent_is_retimed(tmp_path, retimed):
    stage = _stage(tmp_path, [("lead", (0, 0, 0), 0.0, 0.0), ("follow", (3, 0, 0), 0.0, 10.0)])
    lead, follow = f"{CROWD}/lead", f"{CROWD}/follow"
    examples.add_sync_constraint(stage, "/Edits/together", follow, 30, lead, 40, offset=2.5)
    agent = lead if retimed == "lead" else follow
    examples.add_time_constraint(stage, "/Edits/start", agent, 10, 5.0)
    examples.add_time_constraint(stage, "/Edits/end", agent, 70, 95.0)   # 60 frames in 90 time codes
    result, out, src = _solve(tmp_path, stage)
    t_follow, e_follow = _play_time(src, out, follow, 30)
    t_lead, e_lead = _play_time(src, out, lead, 40)
    assert e_follow < 1e-6 and e_lead < 1e-6
    assert abs(t_follow - t_lead - 2.5) < 1e-6
    # The other agent keeps its timing: it only shifts.
    other, frame, t = (follow, 30, t_follow) if agent == lead else (lead, 40, t_lead)
    rest = 10.0 + frame if other == follow else float(frame)
    assert _shift_error(src, out, other, t - rest, np.arange(np.ceil(t - rest), 90.0, 6.0)) < 1e-5
    sync = next(c for c in result.report.constraints if c["kind"] == "sync")
    assert sync["met"] and sync["residual"] <= 1e-6 and sync["target"] == lead and sync["targetFrame"] == 40


def test_a_handshake_without_time_constraints_meets_half_way(tmp_path):
    stage = _stage(tmp_path, [("a", (0, 0, 0), 0.0, 0.0), ("b", (1.2, 0, 6), 180.0, 0.0)])
    examples.add_sync_constraint(stage, "/Edits/handshake", f"{CROWD}/a", 50, f"{CROWD}/b", 40)
    result, out, src = _solve(tmp_path, stage)
    t_a, e_a = _play_time(src, out, f"{CROWD}/a", 50)
    t_b, e_b = _play_time(src, out, f"{CROWD}/b", 40)
    assert e_a < 1e-6 and e_b < 1e-6
    assert t_a == pytest.approx(t_b, abs=1e-6)
    assert t_a == pytest.approx(45.0, abs=1e-6)   # a plays 5 earlier, b 5 later


def test_space_and_time_edits_combine(tmp_path, monkeypatch):
    stage = _stage(tmp_path, [("walker", (0, 0, 0), 0.0, 0.0)])
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/walker", 40, 47.5)
    examples.add_time_constraint(stage, "/Edits/later", f"{CROWD}/walker", 80, 97.0)
    angle, shift = 0.6, np.array([2.0, -1.5])
    rot = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])

    def move(ctx):
        traj = ctx.trajectories[f"{CROWD}/walker"]
        ctx.paths[f"{CROWD}/walker"] = EditedPath(ground=traj.ground @ rot + shift, heading=traj.heading + angle)

    monkeypatch.setattr(processor, "PASSES", (Pass("move", move), Pass("time", time_pass.run)))
    result, out, src = _solve(tmp_path, stage)

    # Y-up: ground (x, -z). The edit turns the ground by `rot` and shifts it.
    turn = np.eye(4)
    turn[np.ix_([0, 2], [0, 2])] = np.array([[1, 0], [0, -1]]) @ rot @ np.array([[1, 0], [0, -1]])
    turn[3, [0, 2]] = shift * [1, -1]

    def moved(m):
        return m @ turn

    for frame, t in ((40, 47.5), (80, 97.0)):
        assert _time_error(src, out, f"{CROWD}/walker", frame, t, moved) < 1e-6
    assert result.report.agents[f"{CROWD}/walker"]["lengthRatio"] == pytest.approx(1.0, abs=1e-6)


def _stretch_path(ctx):
    for path, traj in ctx.trajectories.items():
        start = traj.ground[0]
        ctx.paths[path] = EditedPath(ground=start + 1.5 * (traj.ground - start), heading=traj.heading.copy())


def test_match_speed_lowers_foot_skate_on_a_stretched_path(tmp_path, monkeypatch):
    stage = _stage(tmp_path, [("walker", (0, 0, 0), 0.0, 0.0)])
    stage.GetRootLayer().Save()
    monkeypatch.setattr(processor, "PASSES", (Pass("stretch", _stretch_path), Pass("time", time_pass.run)))
    src = Usd.Stage.Open(stage.GetRootLayer().realPath)
    skate, speed = {}, {}
    for match in (False, True):
        sub = tmp_path / str(match)
        sub.mkdir()
        result, out, _ = _solve(sub, Usd.Stage.Open(stage.GetRootLayer().realPath), match_speed=match)
        skate[match] = measure.foot_skate(out, f"{CROWD}/walker").mean
        times = np.arange(0.0, 140.0)
        root = evaluate.agent_root_positions(out, f"{CROWD}/walker", times)
        steps = np.linalg.norm(np.diff(metrics.to_ground(root, "Y"), axis=0), axis=1)
        speed[match] = np.median(steps[steps > 1e-6])
        entry = result.report.agents[f"{CROWD}/walker"]
        assert ("matchSpeed" in " ".join(entry.get("notes", []))) == match
    source_skate = measure.foot_skate(src, f"{CROWD}/walker").mean
    src_root = evaluate.agent_root_positions(src, f"{CROWD}/walker", np.arange(0.0, FRAMES))
    source_speed = np.median(np.linalg.norm(np.diff(metrics.to_ground(src_root, "Y"), axis=0), axis=1))
    # Stretching the path without re-timing makes the walker hurry (figure 4.1)...
    assert speed[False] == pytest.approx(1.5 * source_speed, rel=0.03)
    # ... matchSpeed gives it back its source speed and its feet slide slower.
    assert speed[True] == pytest.approx(source_speed, rel=0.03)
    assert skate[True] < 0.75 * skate[False]
    assert source_skate < skate[True]


def test_the_minimum_interval_holds_and_is_reported(tmp_path):
    stage = _stage(tmp_path, [("walker", (0, 0, 0), 0.0, 0.0)])
    # Soft constraints that ask for frame 60 to play before frame 30.
    examples.add_time_constraint(stage, "/Edits/a", f"{CROWD}/walker", 30, 40.0, strength="soft", weight=10.0)
    examples.add_time_constraint(stage, "/Edits/b", f"{CROWD}/walker", 60, 35.0, strength="soft", weight=10.0)
    examples.define_mocap_prim(stage, "/Settings", "MocapSolveSettings")
    stage.GetPrimAtPath("/Settings").GetAttribute("minTimeInterval").Set(0.25)
    result, out, src = _solve(tmp_path, stage)
    agent = result.report.agents[f"{CROWD}/walker"]
    assert agent["minInterval"] == pytest.approx(0.25, abs=1e-9)
    assert any("minimum" in n for n in agent["notes"])
    assert any("minTimeInterval 0.25" in n for n in result.report.notes)
    soft = [c for c in result.report.constraints if c["kind"] == "time"]
    assert all(not c["hard"] and not c["met"] for c in soft)
    # Time never runs backwards on the composed stage: the walker, walking straight ahead,
    # never steps back, and where time is squeezed to the minimum it covers 4 times the ground.
    anim = out.GetPrimAtPath("/MocapEdit/Animations").GetChildren()[0]
    times = np.asarray(anim.GetAttribute("translations").GetTimeSamples())
    src_z = evaluate.agent_root_positions(src, f"{CROWD}/walker", np.arange(FRAMES))[:, 2]
    ahead = np.sign(src_z[-1] - src_z[0])       # the walker walks straight along z
    src_step = np.diff(ahead * src_z)
    step = np.diff(ahead * evaluate.agent_root_positions(out, f"{CROWD}/walker", times)[:, 2]) / np.diff(times)
    assert step.min() > 0.5 * src_step.min()
    assert step.max() == pytest.approx(4 * src_step.max(), rel=0.02)


def _two_agents(tmp_path):
    return _stage(tmp_path, [("a", (0, 0, 0), 0.0, 0.0), ("b", (3, 0, 0), 0.0, 0.0), ("c", (6, 0, 0), 0.0, 0.0)])


def _same_frame_twice(stage):
    examples.add_time_constraint(stage, "/Edits/first", f"{CROWD}/a", 12, 20.0)
    examples.add_time_constraint(stage, "/Edits/second", f"{CROWD}/a", 12, 24.0)
    return ["/Edits/first", "/Edits/second"], "different times"


def _sync_cycle(stage):
    examples.add_sync_constraint(stage, "/Edits/ab", f"{CROWD}/a", 10, f"{CROWD}/b", 10, 1.0)
    examples.add_sync_constraint(stage, "/Edits/bc", f"{CROWD}/b", 10, f"{CROWD}/c", 10, 1.0)
    examples.add_sync_constraint(stage, "/Edits/ca", f"{CROWD}/c", 10, f"{CROWD}/a", 10, 0.5)
    return ["/Edits/ab", "/Edits/bc", "/Edits/ca"], "do not sum to zero"


def _backwards(stage):
    examples.add_time_constraint(stage, "/Edits/early", f"{CROWD}/a", 20, 40.0)
    examples.add_time_constraint(stage, "/Edits/late", f"{CROWD}/a", 50, 30.0)
    return ["/Edits/early", "/Edits/late"], "run backwards"


def _crossed_syncs(stage):
    examples.add_sync_constraint(stage, "/Edits/x1", f"{CROWD}/a", 10, f"{CROWD}/b", 60)
    examples.add_sync_constraint(stage, "/Edits/x2", f"{CROWD}/a", 30, f"{CROWD}/b", 40)
    return ["/Edits/x1", "/Edits/x2"], "backwards"


def _outside(stage):
    examples.add_time_constraint(stage, "/Edits/far", f"{CROWD}/a", FRAMES, 20.0)
    return ["/Edits/far"], "outside the clip"


def _itself(stage):
    examples.add_sync_constraint(stage, "/Edits/self", f"{CROWD}/a", 10, f"{CROWD}/a", 20)
    return ["/Edits/self"], "its own agent"


def _bad_minimum(stage):
    examples.define_mocap_prim(stage, "/Settings", "MocapSolveSettings")
    stage.GetPrimAtPath("/Settings").GetAttribute("minTimeInterval").Set(0.0)
    examples.add_time_constraint(stage, "/Edits/t", f"{CROWD}/a", 10, 20.0)
    return ["/Settings"], "minTimeInterval"


@pytest.mark.parametrize("make", [_same_frame_twice, _sync_cycle, _backwards, _crossed_syncs, _outside, _itself,
                                  _bad_minimum])
def test_contradicting_constraints_stop_with_an_error_naming_them(tmp_path, make):
    stage = _two_agents(tmp_path)
    prims, words = make(stage)
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError) as err:
        solve(stage.GetRootLayer().realPath)
    message = str(err.value)
    assert words in message
    for prim in prims:
        assert f"<{prim}>" in message
    # The command line exits 1 and writes nothing.
    edits = tmp_path / "edits.usda"
    proc = run_cli("solve", stage.GetRootLayer().realPath, "-o", edits)
    assert proc.returncode == 1 and prims[0] in proc.stderr
    assert not edits.exists()


def test_solve_command_retimes_and_gives_the_same_bytes_twice(tmp_path):
    stage = _stage(tmp_path, [("a", (0, 0, 0), 0.0, 0.0), ("b", (2, 0, 0), 0.0, 0.0)])
    examples.add_time_constraint(stage, "/Edits/t", f"{CROWD}/a", 40, 52.5)
    examples.add_sync_constraint(stage, "/Edits/s", f"{CROWD}/b", 20, f"{CROWD}/a", 40, 1.0)
    stage.GetRootLayer().Save()
    digests = []
    for name in ("one.usda", "two.usda"):
        proc = run_cli("solve", stage.GetRootLayer().realPath, "-o", tmp_path / name)
        assert proc.returncode == 0, proc.stderr
        digests.append(hashlib.sha256((tmp_path / name).read_bytes()).hexdigest())
    assert digests[0] == digests[1]


def test_the_solver_samples_clips_like_the_numpy_reference():
    clip = walker.walk(frames=40)
    from mocapedit.model.data import Clip
    c = Clip(key=("walk",), source="walk", joints=list(clip.joints), times=np.arange(40.0),
             translations=clip.translations, rotations=clip.rotations,
             scales=np.ones_like(clip.translations))
    rng = np.random.default_rng(3)
    frames = np.concatenate([rng.uniform(-2, 42, 200), np.arange(40.0)])
    a, b = animation.sample_pose(c, frames), animation.sample_pose_numpy(c, frames)
    for x, y in ((a.translations, b.translations), (a.rotations, b.rotations), (a.scales, b.scales)):
        assert x.dtype == np.float32 and x.shape == y.shape
        np.testing.assert_allclose(x, y, atol=2e-7)
    whole = slice(200, None)
    assert np.array_equal(a.rotations[whole], clip.rotations) and np.array_equal(a.translations[whole],
                                                                                 clip.translations)
    np.testing.assert_allclose(np.linalg.norm(a.rotations, axis=-1), 1.0, atol=1e-6)
    q = Gf.Quatf(*map(float, (a.rotations[0, 1, 3], *a.rotations[0, 1, :3])))
    assert abs(q.GetLength() - 1.0) < 1e-6


def test_the_example_stages_do_what_they_say(tmp_path):
    import importlib.util
    from conftest import REPO
    spec = importlib.util.spec_from_file_location("stages_time", REPO / "example_stages" / "stages_time.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name, build in module.STAGES.items():
        build(tmp_path)
    (tmp_path / "handshake").mkdir()
    result, out, src = _solve(tmp_path / "handshake", Usd.Stage.Open(str(tmp_path / "time_handshake.usda")))
    t_host, e_host = _play_time(src, out, f"{CROWD}/host", 50)
    t_guest, e_guest = _play_time(src, out, f"{CROWD}/guest", 50)
    assert max(e_host, e_guest) < 1e-6
    assert t_host == pytest.approx(58.0, abs=1e-6) and t_guest == pytest.approx(58.0, abs=1e-6)

    (tmp_path / "beats").mkdir()
    result, out, src = _solve(tmp_path / "beats", Usd.Stage.Open(str(tmp_path / "time_beats.usda")))
    beats = [c for c in result.report.constraints if c["kind"] == "time"]
    assert len(beats) == 3 and all(c["met"] for c in beats)
    for prim, t in zip(("/Edits/beat1", "/Edits/beat2", "/Edits/beat3"), (24.0, 44.0, 72.0)):
        frame = src.GetPrimAtPath(prim).GetAttribute("frame").Get()
        assert _time_error(src, out, f"{CROWD}/dancer", frame, t) < 1e-6


def test_match_speed_from_the_settings_prim_and_the_command_line(tmp_path, monkeypatch):
    import json

    from mocapedit.cli import main as cli
    stage = _stage(tmp_path, [("walker", (0, 0, 0), 0.0, 0.0)])
    examples.define_mocap_prim(stage, "/Settings", "MocapSolveSettings")
    stage.GetPrimAtPath("/Settings").GetAttribute("matchSpeed").Set(True)
    stage.GetRootLayer().Save()
    monkeypatch.setattr(processor, "PASSES", (Pass("stretch", _stretch_path), Pass("time", time_pass.run)))
    matched = {}
    for flag in (None, "--no-match-speed", "--match-speed"):
        report = tmp_path / f"{flag}.json"
        args = ["solve", stage.GetRootLayer().realPath, "-o", str(tmp_path / f"{flag}.usda"), "--report",
                str(report), "-q"] + ([flag] if flag else [])
        assert cli.main(args) == 0
        entry = json.loads(report.read_text())["agents"][f"{CROWD}/walker"]
        matched[flag] = any("matchSpeed" in n for n in entry.get("notes", []))
    assert matched == {None: True, "--no-match-speed": False, "--match-speed": True}


def test_the_report_measures_a_retimed_agent_as_forward_kinematics_does(tmp_path):
    """Plausibility of a time-warped agent: the solve's figures (from the motions it writes)
    agree with UsdSkel FK on the composed stage, and the time-warp range is the time map's."""
    stage = _stage(tmp_path, [("dancer", (0, 0, 0), 0.0, 0.0)])
    for i, (frame, t) in enumerate({20: 30.5, 50: 52.0, 80: 90.25}.items()):
        examples.add_time_constraint(stage, f"/Edits/beat{i}", f"{CROWD}/dancer", frame, t)
    result, out, src = _solve(tmp_path, stage)
    agent = f"{CROWD}/dancer"
    reported = result.report.agents[agent]["plausibility"]
    measured = measure.plausibility(src, out, agent)
    # The edited body's own turning is the same; against the source, the solve pairs each shot
    # frame with the source frame it plays, FK on the stage (which cannot know it) by fraction.
    # The solve interpolates the hip's world matrix between source frames; UsdSkel plays the
    # re-timed clip by interpolating each joint's local rotation: the rates agree to 0.5%.
    assert reported["maxFacingRate"] == pytest.approx(measured.max_facing_rate, rel=5e-3)
    assert reported["maxExtraFacingRate"] < 60.0 and measured.max_extra_facing_rate < 60.0
    assert reported["maxDirectionDeviation"] < 15.0 and measured.max_direction_deviation < 15.0
    assert reported["lengthRatio"] == pytest.approx(1.0, abs=1e-3)
    # The beats squeeze frames 20..50 into 21.5 time codes and stretch 50..80 over 38.25: the
    # report's warp is the time map's (FK on the stage sees shot frames, not source frames).
    lo, hi = reported["timeWarp"]
    assert lo < 21.5 / 30 < 38.25 / 30 < hi and lo > 0
    assert reported["spinFrames"] == 0 and not measured.spins
