"""Editing a shot again: a second solve on the composed stage of a first (the shot with its
edits layer under a new shot layer that adds constraints). The first edits are part of the
second solve's input; the second layer's edits go on top of them, so every constraint of
both holds on the final composed stage."""
from __future__ import annotations

import numpy as np
from pxr import Sdf, Usd

from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.usd import evaluate

FRAMES = 72


def _over(folder, below: str, name: str) -> Usd.Stage:
    """A new shot layer over the stage file ``below``, with its metadata."""
    under = Sdf.Layer.FindOrOpen(str(folder / below))
    layer = Sdf.Layer.CreateNew(str(folder / name))
    layer.subLayerPaths.append(below)
    for key in ("upAxis", "metersPerUnit"):
        if under.pseudoRoot.HasInfo(key):
            layer.pseudoRoot.SetInfo(key, under.pseudoRoot.GetInfo(key))
    layer.timeCodesPerSecond = under.timeCodesPerSecond
    layer.startTimeCode, layer.endTimeCode = under.startTimeCode, under.endTimeCode
    layer.Save()
    stage = Usd.Stage.Open(layer)
    stage.SetEditTarget(layer)
    return stage


def test_a_second_solve_on_the_composed_stage_keeps_the_first_edits(tmp_path):
    clip = walker.walk(frames=FRAMES, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip, (0, 0, 0), 0.0),
                                                                 examples.AgentSpec("b", clip, (3, 0, 0), 0.0)])
    a, b = "/World/Crowd/a", "/World/Crowd/b"
    start, end = evaluate.agent_root_positions(stage, a, [0.0, FRAMES - 1.0])
    examples.add_position_constraint(stage, "/Edits/keep", a, 0, tuple(map(float, start)))
    examples.add_position_constraint(stage, "/Edits/aside", a, FRAMES - 1, tuple(map(float, end + [1.0, 0, 0])))
    # a is re-timed too: its first layer plays its clip through value clips, its locked legs
    # baked over them (two sets of sample times that differ by rounding).
    examples.add_time_constraint(stage, "/Edits/a_late", a, 40, 44.0)
    stage.GetRootLayer().Save()
    solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "first.usda"), composed=str(tmp_path / "first.composed.usda"),
          guides=False)

    again = _over(tmp_path, "first.composed.usda", "again.usda")
    # a's frames as the first solve plays them: its value clip's (shot time, clip time) pairs.
    first = Sdf.Layer.FindOrOpen(str(tmp_path / "first.usda"))
    frame_times = np.asarray(first.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_a").GetInfo("clips")["default"]["times"])[:, 0]
    middle = evaluate.agent_root_positions(again, a, [frame_times[35]])[0] + [0.5, 0, 0]
    examples.add_position_constraint(again, "/Edits/middle", a, 35, tuple(map(float, middle)))
    examples.add_time_constraint(again, "/Edits/late", b, 30, 36.0)
    again.GetRootLayer().Save()
    result = solve(str(tmp_path / "again.usda"), output=str(tmp_path / "second.usda"),
                   composed=str(tmp_path / "second.composed.usda"), guides=False)
    assert all(c.met for c in result.report.constraints)

    final = Usd.Stage.Open(str(tmp_path / "second.composed.usda"))
    got = evaluate.agent_root_positions(final, a, frame_times[[0, 35, FRAMES - 1]])[:, [0, 2]]
    want = np.array([start, middle, end + [1.0, 0, 0]])[:, [0, 2]]
    np.testing.assert_allclose(got, want, atol=1e-6)
    source = Usd.Stage.Open(str(tmp_path / "shot.usda"))

    def upper_body(stage, t):
        """Distances of the spine, head and arms from the hips: the pose, whatever carries it."""
        p = evaluate.joint_world_positions(stage, a, [t])[0]
        return np.linalg.norm(p[10:] - p[1], axis=1)

    # a's frame 40 still plays at shot time 44 (and a frame a few away would not pass).
    np.testing.assert_allclose(upper_body(final, 44.0), upper_body(source, 40.0), atol=1e-6)
    assert np.abs(upper_body(final, 44.0) - upper_body(source, 37.0)).max() > 1e-3
    np.testing.assert_allclose(evaluate.joint_world_positions(final, b, [36.0]),
                               evaluate.joint_world_positions(source, b, [30.0]), atol=1e-6)
    # The second layer's ops go on top of the first's, under names of their own.
    order = list(Sdf.Layer.FindOrOpen(str(tmp_path / "second.usda")).GetAttributeAtPath(f"{a}.xformOpOrder").default)
    assert order[:2] == ["xformOp:translate:mocapEdit2", "xformOp:rotateY:mocapEdit2"]
    assert order[2:4] == ["xformOp:translate:mocapEdit", "xformOp:rotateY:mocapEdit"]
    # Its animations take names the first layer does not use: a prim of the same name would
    # compose with the first layer's.
    names = [{c.name for c in (Sdf.Layer.FindOrOpen(str(tmp_path / f"{n}.usda")).GetPrimAtPath("/MocapEdit/Animations")
                               or Sdf.Layer.CreateAnonymous().pseudoRoot).nameChildren} for n in ("first", "second")]
    assert names[0] and names[1] and not names[0] & names[1], names


def test_a_second_solve_of_a_30_fps_clip_under_a_24_fps_shot_keeps_its_frames(tmp_path):
    """A 30 fps walk under a 24 fps shot (USD scales the reference), re-timed by a time constraint
    and bent by handles, so that its legs are locked: the first layer plays the clip through value
    clips at the clip's own times (0.8 shot frames apart) and bakes the locked rotations on the
    shot's whole frames. The second solve read the union of both as the clip's frames (144 of 90
    frames), put every constraint on another frame and moved the walker again, reporting them
    met. Its frames are the value clip's: a second solve with nothing new changes nothing."""
    frames = 90
    clip = walker.walk(frames=frames, fps=30.0, name="walk30")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], fps=30.0)
    layer = stage.GetRootLayer()
    layer.timeCodesPerSecond = layer.framesPerSecond = 24.0
    layer.startTimeCode, layer.endTimeCode = 0.0, 80.0
    layer.Save()
    stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    a = "/World/Crowd/a"
    ends = evaluate.agent_root_positions(stage, a, [0.0, (frames - 1) * 0.8])
    examples.add_position_constraint(stage, "/Edits/keep", a, 0, tuple(map(float, ends[0])))
    examples.add_position_constraint(stage, "/Edits/aside", a, frames - 1, tuple(map(float, ends[1] + [0.8, 0, 0])))
    examples.add_time_constraint(stage, "/Edits/late", a, 45, 40.0)
    stage.GetRootLayer().Save()
    first = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "first.usda"),
                  composed=str(tmp_path / "first.composed.usda"), guides=False)
    assert first.report.agents[a]["footContactsLocked"] > 0, "the legs are locked"
    edits = Sdf.Layer.FindOrOpen(str(tmp_path / "first.usda"))
    anim = edits.GetPrimAtPath("/MocapEdit/Animations/World_Crowd_a")
    assert anim and len(anim.GetInfo("clips")["default"]["times"]) == frames, "re-timed by a value clip"

    _over(tmp_path, "first.composed.usda", "again.usda")
    again = solve(str(tmp_path / "again.usda"), output=str(tmp_path / "second.usda"),
                  composed=str(tmp_path / "second.composed.usda"), guides=False)
    entry = again.report.agents[a]
    assert entry.frames == frames
    assert not entry.edited
    assert all(c.met for c in again.report.constraints)
    one, two = (Usd.Stage.Open(str(tmp_path / n)) for n in ("first.composed.usda", "second.composed.usda"))
    times = np.arange(0.0, 81.0)
    np.testing.assert_allclose(evaluate.joint_world_positions(two, a, times),
                               evaluate.joint_world_positions(one, a, times), atol=1e-6)
