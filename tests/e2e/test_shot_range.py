"""Only what plays in the shot is parted and counted: clips longer than the stage's time range.

A crowd is often built from takes longer than the shot, referenced with time offsets. What a
take plays before the stage's start time code or after its end time code is never seen, so
collision avoidance leaves it alone (a push there would bend what is seen), and the report does
not count overlaps there. Without a time range, the whole of every clip counts.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom

from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.tools import measure
from mocapedit.usd import evaluate

FRAMES, FPS, SPEED = 240, 24.0, 1.4
#: The two walkers meet head-on around this frame (each has walked half of the 14 m between them).
MEET = 120


def _head_on(path, start: float | None, end: float | None, regions: bool = False) -> None:
    clip = walker.walk(frames=FRAMES, fps=FPS, speed=SPEED, name="walk")
    length = SPEED * MEET / FPS           # each walker's way to the meeting
    specs = [examples.AgentSpec("a", clip, (0.0, 0.0, 0.0), 0.0),
             examples.AgentSpec("b", clip, (0.1, 0.0, 2 * length), 180.0)]
    stage = examples.build_crowd_stage(path, specs, fps=FPS)
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings",
                               attributes={"collisionAvoidance": (Sdf.ValueTypeNames.Bool, True)})
    if start is not None:
        stage.SetStartTimeCode(start)
    if end is not None:
        stage.SetEndTimeCode(end)
    stage.GetRootLayer().Save()


def _moved(shot, edits, times, agents=("/World/Crowd/a", "/World/Crowd/b")) -> float:
    """Largest distance between the source's and the edit's root positions at ``times``."""
    src = Usd.Stage.Open(str(shot))
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.subLayerPaths.append(str(edits))
    layer.subLayerPaths.append(str(shot))
    out = Usd.Stage.Open(layer)
    return max(float(np.abs(evaluate.agent_root_positions(out, p, times)
                            - evaluate.agent_root_positions(src, p, times)).max())
               for p in agents)


@pytest.mark.parametrize("start, end", [(0.0, 90.0), (150.0, 239.0)])
def test_walkers_who_meet_outside_the_shot_are_not_pushed_apart(tmp_path, start, end):
    shot, edits = tmp_path / "shot.usda", tmp_path / "shot.edits.usda"
    _head_on(shot, start, end)
    stats = solve(str(shot), output=str(edits), guides=False).report.stats
    assert stats["collisionsPerIteration"][0] == 0, "their meeting plays outside the shot"
    assert stats["remainingOverlaps"] == 0
    assert _moved(shot, edits, list(np.arange(start, end + 1))) < 1e-6


def test_walkers_who_meet_in_the_shot_are_pushed_apart(tmp_path):
    shot, edits = tmp_path / "shot.usda", tmp_path / "shot.edits.usda"
    _head_on(shot, 60.0, 180.0)
    stats = solve(str(shot), output=str(edits), guides=False).report.stats
    assert stats["collisionsPerIteration"][0] > 0
    assert stats["remainingOverlaps"] == 0
    assert _moved(shot, edits, [float(MEET)]) > 0.1


def test_overlaps_outside_the_shot_are_not_counted(tmp_path):
    """Without avoidance, the report counts the overlap only when the meeting plays in the shot."""
    counts = {}
    for start in (0.0, 150.0):
        shot = tmp_path / f"shot_{start:g}.usda"
        _head_on(shot, start, 239.0)
        result = solve(str(shot), output=str(tmp_path / f"shot_{start:g}.edits.usda"), guides=False,
                       collisions=False)
        counts[start] = result.report.stats["remainingOverlaps"]
    assert counts == {0.0: 1, 150.0: 0}


def test_an_avoid_region_reached_after_the_shot_bends_nothing(tmp_path):
    """A walker reaches a fountain 2 s after the shot ends: it walks its source path in the shot."""
    clip = walker.walk(frames=FRAMES, fps=FPS, speed=SPEED, name="walk")
    shot, edits = tmp_path / "shot.usda", tmp_path / "shot.edits.usda"
    stage = examples.build_crowd_stage(shot, [examples.AgentSpec("a", clip, (0.0, 0.0, 0.0), 0.0)], fps=FPS)
    vt = Sdf.ValueTypeNames
    region = examples.define_mocap_prim(stage, "/Edits/fountain", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(2.0, 2.0, 2.0)), "margin": (vt.Double, 0.05)})
    reach = SPEED * 180 / FPS       # where the walker is at frame 180
    UsdGeom.Xformable(region).AddTranslateOp().Set(Gf.Vec3d(0.2, 0.0, reach))
    stage.SetEndTimeCode(130.0)
    stage.GetRootLayer().Save()
    solve(str(shot), output=str(edits), guides=False)
    assert _moved(shot, edits, list(np.arange(0.0, 131.0)), ("/World/Crowd/a",)) < 1e-6
    # With the fountain in the shot, the walker goes round it.
    stage.SetEndTimeCode(239.0)
    stage.GetRootLayer().Save()
    solve(str(shot), output=str(edits), guides=False)
    assert _moved(shot, edits, [180.0], ("/World/Crowd/a",)) > 0.5


def _bent(path, end: float) -> None:
    """One walker of a 10 s take dragged 1 m sideways 2.5 s in, its ends held; the stage plays
    frames 0 to ``end``."""
    clip = walker.walk(frames=FRAMES, fps=FPS, speed=SPEED, name="walk")
    stage = examples.build_crowd_stage(path, [examples.AgentSpec("a", clip, (0.0, 0.0, 0.0), 0.0)], fps=FPS)
    agent = "/World/Crowd/a"
    examples.add_position_constraint(stage, "/Edits/start", agent, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/drag", agent, 60, (1.0, 0.0, SPEED * 60 / FPS))
    examples.add_position_constraint(stage, "/Edits/end", agent, FRAMES - 1, (0.0, 0.0, SPEED * (FRAMES - 1) / FPS))
    stage.SetEndTimeCode(end)
    stage.GetRootLayer().Save()


def test_the_plausibility_figures_are_of_what_plays_in_the_shot(tmp_path):
    """The same bend in a shot of the first 5 s of the take and in one of all of it: the report's
    figures are measured over the shot, so the short shot's path grows more (the bend is most of
    it), and they are what UsdSkel FK on the composed stage measures over the shot."""
    ratios = {}
    for end in (120.0, 239.0):
        shot, edits = tmp_path / f"bent_{end:g}.usda", tmp_path / f"bent_{end:g}.edits.usda"
        _bent(shot, end)
        composed = tmp_path / f"bent_{end:g}.edited.usda"
        result = solve(str(shot), output=str(edits), composed=str(composed), guides=False, foot_locking=False)
        figures = result.report.agent("/World/Crowd/a").plausibility
        fk = measure.plausibility(Usd.Stage.Open(str(shot)), Usd.Stage.Open(str(composed)), "/World/Crowd/a")
        assert figures.length_ratio == pytest.approx(fk.length_ratio, abs=1e-6)
        assert figures.max_direction_deviation == pytest.approx(fk.max_direction_deviation, abs=1e-6)
        assert figures.worst_direction_frame <= end
        ratios[end] = figures.length_ratio
    assert ratios[120.0] > ratios[239.0] + 0.005


def _stander_in_a_walkers_way(path, pin: bool) -> None:
    """``a`` walks 2 s and its clip ends: it holds its last pose to the end of the shot. ``b``
    walks across, through that spot, 6 s in; unless ``a`` is pinned, hard position constraints
    hold ``b`` to its way there, so that ``a`` must give way (a held pose is anchored for the
    time it is held: pushed by a free walker, it stays and the walker goes round it)."""
    short = walker.walk(frames=48, fps=FPS, speed=SPEED, name="short")
    long = walker.walk(frames=FRAMES, fps=FPS, speed=SPEED, name="walk")
    end = float(short.translations[-1, 0, 2])
    across = SPEED * 144 / FPS
    specs = [examples.AgentSpec("a", short, (0.0, 0.0, 0.0), 0.0),
             examples.AgentSpec("b", long, (-across, 0.0, end + 0.1), 90.0)]
    stage = examples.build_crowd_stage(path, specs, fps=FPS)
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings",
                               attributes={"collisionAvoidance": (Sdf.ValueTypeNames.Bool, True)})
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(FRAMES - 1.0)
    if pin:
        where = evaluate.agent_root_positions(stage, "/World/Crowd/a", [47.0])[0]
        examples.add_position_constraint(stage, "/Edits/a_stays", "/World/Crowd/a", 47, tuple(map(float, where)))
    else:
        for frame in (132, 156):
            where = evaluate.agent_root_positions(stage, "/World/Crowd/b", [float(frame)])[0]
            examples.add_position_constraint(stage, f"/Edits/b_keeps_{frame}", "/World/Crowd/b", frame,
                                             tuple(map(float, where)))
    stage.GetRootLayer().Save()


def test_a_pose_held_after_its_clip_that_avoidance_moves_gets_a_note_saying_how_to_keep_it(tmp_path):
    """Pushed aside while it holds its last pose (by a walker held to its way), a stander has
    its last steps turn into the new place (one frame of its path stands for all the time it
    holds). The report says so and how to keep the pose where it is: pin it. Pinned, it stays,
    and the walker goes round it."""
    shot, edits = tmp_path / "shot.usda", tmp_path / "shot.edits.usda"
    _stander_in_a_walkers_way(shot, pin=False)
    report = solve(str(shot), output=str(edits), guides=False).report
    assert report.stats["remainingOverlaps"] == 0
    moved = _moved(shot, edits, [47.0, 200.0], agents=("/World/Crowd/a",))
    assert moved > 0.1
    notes = " ".join(report.agents["/World/Crowd/a"]["notes"])
    assert "holds after its clip ends" in notes and "MocapPositionConstraint at frame 47" in notes
    assert any("moved the pose 1 agent holds" in n and "</World/Crowd/a>" in n for n in report.notes)
    assert not report.agents["/World/Crowd/b"].get("notes")

    pinned, pinned_edits = tmp_path / "pinned.usda", tmp_path / "pinned.edits.usda"
    _stander_in_a_walkers_way(pinned, pin=True)
    report = solve(str(pinned), output=str(pinned_edits), guides=False).report
    assert report.stats["remainingOverlaps"] == 0
    assert _moved(pinned, pinned_edits, [47.0, 200.0], agents=("/World/Crowd/a",)) < 1e-6
    assert not report.agents["/World/Crowd/a"].get("notes")
    assert not any("moved the pose" in n for n in report.notes)


def test_two_poses_held_in_one_spot_get_notes_saying_to_pin_only_one(tmp_path):
    """Two walkers whose clips end in the same spot are pushed apart while they hold their last
    poses: pinned both, neither could give way, so each note says to pin one of the two."""
    shot, edits = tmp_path / "shot.usda", tmp_path / "shot.edits.usda"
    short = walker.walk(frames=48, fps=FPS, speed=SPEED, name="short")
    end = float(short.translations[-1, 0, 2])
    specs = [examples.AgentSpec("a", short, (0.0, 0.0, 0.0), 0.0),
             examples.AgentSpec("c", short, (-end, 0.0, end), 90.0)]
    stage = examples.build_crowd_stage(shot, specs, fps=FPS)
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings",
                               attributes={"collisionAvoidance": (Sdf.ValueTypeNames.Bool, True)})
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(FRAMES - 1.0)
    stage.GetRootLayer().Save()
    ends = evaluate.agent_root_positions(stage, ["/World/Crowd/a", "/World/Crowd/c"], [47.0])[:, 0]
    assert np.linalg.norm((ends[0] - ends[1])[[0, 2]]) < 0.05
    report = solve(str(shot), output=str(edits), guides=False).report
    assert report.stats["remainingOverlaps"] == 0
    for me, other in (("a", "c"), ("c", "a")):
        notes = " ".join(report.agents[f"/World/Crowd/{me}"]["notes"])
        assert "MocapPositionConstraint at frame 47" in notes
        assert f"not together with </World/Crowd/{other}>" in notes


def test_a_held_pose_an_avoid_region_pushes_gets_a_note_saying_why_no_pin_can_keep_it(tmp_path):
    """A stander whose clip ends inside a fountain's clearance is pushed out of it: a pin there
    would contradict the region, so the note names the region instead of advising a pin."""
    shot, edits = tmp_path / "shot.usda", tmp_path / "shot.edits.usda"
    short = walker.walk(frames=48, fps=FPS, speed=SPEED, name="short")
    end = float(short.translations[-1, 0, 2])
    stage = examples.build_crowd_stage(shot, [examples.AgentSpec("a", short, (0.0, 0.0, 0.0), 0.0)], fps=FPS)
    vt = Sdf.ValueTypeNames
    region = examples.define_mocap_prim(stage, "/Edits/fountain", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(1.0, 2.0, 1.0)), "margin": (vt.Double, 0.05)})
    UsdGeom.Xformable(region).AddTranslateOp().Set(Gf.Vec3d(0.45, 0.0, end))
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(FRAMES - 1.0)
    stage.GetRootLayer().Save()
    report = solve(str(shot), output=str(edits), guides=False).report
    assert _moved(shot, edits, [200.0], agents=("/World/Crowd/a",)) > 0.25
    notes = " ".join(report.agents["/World/Crowd/a"]["notes"])
    assert "avoid region </Edits/fountain>'s clearance" in notes and "MocapPositionConstraint" not in notes


def test_a_constraint_at_a_frame_that_plays_before_the_shot_gets_a_note(tmp_path):
    """A take referenced 100 frames early into a 100-frame shot: a pin at its frame 5 holds at
    time code -95, where nobody sees it; the solve says so, naming the constraint and the time
    (before, nothing said why the walker moved). A pin at a frame the shot plays gets no note."""
    clip = walker.walk(frames=FRAMES, fps=FPS, speed=SPEED, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip, time_offset=-100.0)],
                                       fps=FPS)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(100)
    a = "/World/Crowd/a"
    for name, frame in (("early", 5), ("seen", 150)):
        p = evaluate.agent_root_positions(stage, a, [frame - 100.0])[0] + (0.5, 0.0, 0.0)
        examples.add_position_constraint(stage, f"/Edits/{name}", a, frame, tuple(map(float, p)))
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"))
    notes = [n for n in result.report.notes if "outside the shot" in n]
    assert len(notes) == 1 and "</Edits/early>: frame 5 of </World/Crowd/a> plays at time code -95" in notes[0], notes
    assert "seen" not in notes[0]
