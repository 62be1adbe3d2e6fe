"""A clip sampled faster than the stage (a 120 fps take referenced into a 24 fps shot) is edited
as the same take on a 120 fps stage: the windows that turn the body by the edit are in seconds
of the clip's own samples, not in stage frames. Measured by UsdSkel FK on the composed stage."""
from __future__ import annotations

import numpy as np
from pxr import Usd, UsdGeom

from bvhgen import walk_idle_walk, write_bvh
from mocapedit.data import examples, walker
from mocapedit.inspect import metrics
from mocapedit.pipeline.processor import solve
from mocapedit.tools import measure
from mocapedit.usd import bvh_usd, evaluate


def _take_shot(folder, stage_fps: float, after: float = 0.0):
    """(stage, agent): a 120 fps walk, stand and walk, referenced into a centimetre Y-up stage at
    ``stage_fps`` whose time range covers it and ``after`` more stage frames."""
    folder.mkdir(parents=True, exist_ok=True)
    rig, values, _ = walk_idle_walk(fps=120.0, walk1=2.0, idle=1.0, walk2=2.0)
    write_bvh(folder / "take.bvh", rig, values, frame_time="0.00833333")
    bvh_usd.import_bvh(str(folder / "take.bvh"), str(folder / "clip.usda"),
                       bvh_usd.ImportSettings(scale=1.0, up_axis="Y", agent=True))
    clip = Usd.Stage.Open(str(folder / "clip.usda"))
    stage = Usd.Stage.CreateNew(str(folder / "shot.usda"))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(stage_fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(clip.GetEndTimeCode() * stage_fps / 120.0 + after)
    agent = "/World/take"
    stage.DefinePrim(agent).GetReferences().AddReference("./clip.usda")
    return stage, agent


def _edit_turn(folder, stage_fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(seconds, degrees the edit turns the body) of a 120 fps walk, stand and walk, referenced
    into a stage at ``stage_fps`` and bent by four hard handles at 0, 1, 2.5 and 4 s."""
    stage, agent = _take_shot(folder, stage_fps)
    times, hips = evaluate.joint_world_matrices(stage, agent)
    for k, (second, move) in enumerate(((0.0, (0, 0)), (1.0, (40, 0)), (2.5, (-40, 30)), (4.0, (30, -20)))):
        frame = int(np.argmin(np.abs(times - second * stage_fps)))     # the clip's sample index
        at = metrics.to_ground(hips[frame, 3, :3], "Y") + np.array(move, dtype=float)
        examples.add_position_constraint(stage, f"/Edits/handle{k}", agent, frame,
                                         tuple(map(float, metrics.from_ground(at, hips[frame, 3, 1], "Y"))))
    stage.GetRootLayer().Save()
    solve(str(folder / "shot.usda"), output=str(folder / "e.usda"), composed=str(folder / "c.usda"))
    _, before = evaluate.joint_world_matrices(stage, agent, times)
    _, after = evaluate.joint_world_matrices(Usd.Stage.Open(str(folder / "c.usda")), agent, times)
    turn = np.degrees(np.unwrap(metrics.body_facing(after, "Y") - metrics.body_facing(before, "Y")))
    return times / stage_fps, turn


def test_a_fast_clip_on_a_slow_stage_turns_as_on_a_stage_at_its_own_rate(tmp_path):
    seconds, turn = _edit_turn(tmp_path / "at120", 120.0)
    seconds24, turn24 = _edit_turn(tmp_path / "at24", 24.0)
    # Windows counted in stage frames were five times too short at 24 fps: up to 17 degrees apart.
    assert np.abs(np.interp(seconds, seconds24, turn24) - turn).max() < 0.01


def test_a_fast_clip_retimed_and_locked_on_a_slow_stage_is_measured_as_the_report_measures_it(tmp_path):
    """The 120 fps take on a 24 fps stage, bent by handles and played later by a time constraint:
    a value clip re-times it and its locked legs are baked on the shot's frames. Its composed
    samples mix the clip's own (five per frame, through the new timing) with those frames, each
    attribute interpolated between its own, so its planted feet moved between frames. Measured
    by UsdSkel FK at every composed sample, the feet slid 36.1 cm/s where the report says 27.8;
    judged at the shot's frames, as the report judges them, the two agree."""
    stage, agent = _take_shot(tmp_path, 24.0, after=12.0)
    times, hips = evaluate.joint_world_matrices(stage, agent)
    for k, (second, move) in enumerate(((0.0, (0, 0)), (2.0, (40, 0)), (4.5, (0, 0)))):
        frame = int(np.argmin(np.abs(times - second * 24.0)))
        at = metrics.to_ground(hips[frame, 3, :3], "Y") + np.array(move, dtype=float)
        examples.add_position_constraint(stage, f"/Edits/handle{k}", agent, frame,
                                         tuple(map(float, metrics.from_ground(at, hips[frame, 3, 1], "Y"))))
    examples.add_time_constraint(stage, "/Edits/later", agent, 360, 3.0 * 24.0 + 8.0)
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    entry = result.report.agents[agent]
    assert entry.foot_contacts_locked > 0
    edited = Usd.Stage.Open(str(tmp_path / "c.usda"))
    assert evaluate.played_frames(edited, agent, np.array([10.0])) is not None     # a value clip
    fk = measure.plausibility(stage, edited, agent)
    assert abs(fk.foot_skate_edited - entry.foot_skate_edited) < 0.1, (fk.foot_skate_edited, entry.foot_skate_edited)


def test_a_crowd_at_24_fps_under_a_shot_counted_in_240_ticks_a_second(tmp_path):
    """A shot's root layer counts 240 time codes a second (24 frames a second) over a sublayer
    crowd at 24: USD plays the sublayer rescaled, and so does the solve. A pin at frame 95 holds
    at time code 950, and frame 48 of a walker re-timed to 600 plays there as its source plays
    it at 480. Before, the reader refused the sublayer's rate."""
    walk = walker.walk(frames=96, fps=24.0, name="walk")
    examples.build_crowd_stage(tmp_path / "crowd.usda", [examples.AgentSpec("a", walk),
                                                         examples.AgentSpec("b", walk, (2.0, 0.0, 0.0))], fps=24.0)
    stage = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    stage.GetRootLayer().subLayerPaths.append("./crowd.usda")
    stage.SetTimeCodesPerSecond(240.0)
    stage.SetFramesPerSecond(24.0)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(950)
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    a, b = "/World/Crowd/a", "/World/Crowd/b"
    ends = evaluate.agent_root_positions(stage, a, [0.0, 950.0])
    examples.add_position_constraint(stage, "/Edits/a0", a, 0, tuple(map(float, ends[0])))
    examples.add_position_constraint(stage, "/Edits/a1", a, 95, tuple(map(float, ends[1] + (0.5, 0.0, 0.0))))
    examples.add_time_constraint(stage, "/Edits/later", b, 48, 600.0)
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert all(c.met for c in result.report.constraints)
    edited = Usd.Stage.Open(str(tmp_path / "c.usda"))
    assert np.abs(evaluate.agent_root_positions(edited, a, [950.0])[0] - (ends[1] + (0.5, 0.0, 0.0)))[[0, 2]].max() < 1e-6
    played = evaluate.agent_root_positions(edited, b, [600.0])[0]
    assert np.abs(played - evaluate.agent_root_positions(stage, b, [480.0])[0]).max() < 1e-6
