"""Clips that stay about one spot (a boxer's bounce, an idle's shuffle, a dance), moved by an
edit: the path solve turns their wiggles to keep their lengths, and that rotation is not the
body's. A boxer moved 40 cm aside faced 45 degrees away from its source, from its first frame
(pinned where it was) to its last. Measured by UsdSkel FK on the composed stage."""
from __future__ import annotations

import dataclasses

import numpy as np
from pxr import Sdf, Usd

from mocapedit.data import examples, walker
from mocapedit.geometry import ground
from mocapedit.pipeline.processor import solve
from mocapedit.usd import evaluate

FPS = 60.0
FRAMES = 720


def _wandering(name: str, phase: float) -> walker.Clip:
    """An idle whose root moves about one spot: within 8 cm of where it starts, 10-30 cm/s."""
    clip = walker.idle(frames=FRAMES, fps=FPS, phase=phase, name=name)
    t = np.arange(FRAMES) / FPS + 7.0 * phase
    u = 0.08 * (0.6 * np.sin(1.3 * t) + 0.4 * np.sin(3.1 * t + 1.0))
    v = 0.08 * (0.6 * np.sin(1.7 * t + 0.5) + 0.4 * np.sin(2.3 * t + 2.0))
    translations = clip.translations.copy()
    translations[:, 0, 0] += (u - u[0]).astype(np.float32)
    translations[:, 0, 2] += (v - v[0]).astype(np.float32)
    return dataclasses.replace(clip, translations=translations)


def _facing(stage, agent, times):
    _, m = evaluate.joint_world_matrices(stage, agent, times)
    forward = ground.to_ground(m[:, 2, :3], "Y")
    return np.arctan2(forward[:, 1], forward[:, 0])


def _offset_degrees(source, edited, agent, times):
    d = _facing(edited, agent, times) - _facing(source, agent, times)
    return np.degrees(np.angle(np.exp(1j * d)))


def _moved_and_turned(source, edited, agent):
    """How far the edit moved the agent's root at most (m), and its facing's offset from the
    source's at every frame (degrees)."""
    times = np.arange(FRAMES, dtype=np.float64)
    moved = np.linalg.norm(evaluate.agent_root_positions(edited, agent, times)
                           - evaluate.agent_root_positions(source, agent, times), axis=1)
    return float(moved.max()), np.abs(_offset_degrees(source, edited, agent, times))


def _shot(folder, agents):
    stage = examples.build_crowd_stage(folder / "shot.usda", agents, fps=FPS)
    return stage, Usd.Stage.Open(stage.GetRootLayer())


def test_an_in_place_clip_moved_aside_by_handles_keeps_its_facing(tmp_path):
    stage, source = _shot(tmp_path, [examples.AgentSpec("boxer", _wandering("bounce", 0.0))])
    agent = "/World/Crowd/boxer"
    for k, f in enumerate((0, FRAMES // 2, FRAMES - 1)):
        p = evaluate.agent_root_positions(source, agent, [float(f)])[0] + (0.4 * (k == 1), 0.0, 0.0)
        examples.add_position_constraint(stage, f"/Edits/handle{k}", agent, f, tuple(map(float, p)))
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert all(c.met for c in result.report.constraints)
    moved, offset = _moved_and_turned(source, Usd.Stage.Open(str(tmp_path / "c.usda")), agent)
    assert moved > 0.35                                    # it was moved aside
    assert offset.max() < 15.0 and offset.mean() < 4.0, (offset.max(), offset.mean())


def test_an_in_place_clip_moved_aside_by_handles_slides_as_a_whole(tmp_path):
    """The bounce (within 10 cm) moved 40 cm aside at its middle, its ends held: it slides aside
    and back as a whole and bounces as its source does, its root within 2 cm of the source's
    carried by the handles' displacement (eased from one to the next). The shape terms alone
    turned each wiggle its own way, unfolding the tangle into swings up to 12 cm off that."""
    stage, source = _shot(tmp_path, [examples.AgentSpec("boxer", _wandering("bounce", 0.0))])
    agent = "/World/Crowd/boxer"
    frames = (0, FRAMES // 2, FRAMES - 1)
    for k, f in enumerate(frames):
        p = evaluate.agent_root_positions(source, agent, [float(f)])[0] + (0.4 * (k == 1), 0.0, 0.0)
        examples.add_position_constraint(stage, f"/Edits/handle{k}", agent, f, tuple(map(float, p)))
    stage.GetRootLayer().Save()
    solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    times = np.arange(FRAMES, dtype=np.float64)
    moved = (evaluate.agent_root_positions(Usd.Stage.Open(str(tmp_path / "c.usda")), agent, times)
             - evaluate.agent_root_positions(source, agent, times))
    carried = np.interp(times, frames, [0.0, 0.4, 0.0])
    off = np.hypot(moved[:, 0] - carried, moved[:, 2])
    assert off.max() < 0.02, (off.max(), off.mean())


def test_in_place_agents_in_a_group_turn_with_their_formation(tmp_path):
    """A group turned by a handle turns its members' bodies, those about one spot too."""
    specs = [examples.AgentSpec("a", _wandering("bounce_a", 0.0)),
             examples.AgentSpec("b", _wandering("bounce_b", 0.3), position=(2.0, 0.0, 0.0))]
    stage, source = _shot(tmp_path, specs)
    a, b = "/World/Crowd/a", "/World/Crowd/b"
    last = float(FRAMES - 1)
    pa = evaluate.agent_root_positions(source, a, [0.0, last])
    pb = evaluate.agent_root_positions(source, b, [last])[0]
    examples.add_position_constraint(stage, "/Edits/a_start", a, 0, tuple(map(float, pa[0])))
    examples.add_position_constraint(stage, "/Edits/a_end", a, FRAMES - 1, tuple(map(float, pa[1])))
    # b's last frame a quarter turn round a's (counter-clockwise seen from above, Y up).
    rel = pb - pa[1]
    turned = pa[1] + np.array([rel[2], 0.0, -rel[0]])
    examples.add_position_constraint(stage, "/Edits/b_end", b, FRAMES - 1, tuple(map(float, turned)))
    examples.add_group(stage, "/Edits/pair", [a, b])
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert all(c.met for c in result.report.constraints)
    edited = Usd.Stage.Open(str(tmp_path / "c.usda"))
    end = _offset_degrees(source, edited, b, [last])[0]
    assert end > 45.0, end


def test_an_idler_that_avoidance_pushes_aside_keeps_its_facing(tmp_path):
    """Three walkers head through the spot where someone bounces on the spot: avoidance moves
    the idler aside (26 cm), and it faced up to 23 degrees away (6 on average); it is a push,
    not a turn of the body."""
    walk = walker.walk(frames=FRAMES, fps=FPS, name="walk")
    specs = [examples.AgentSpec("idler", _wandering("bounce", 0.0))]
    specs += [examples.AgentSpec(f"w{k}", walk, position=(0.05 * (k - 1), 0.0, -4.0 - 3.0 * k)) for k in range(3)]
    stage, source = _shot(tmp_path, specs)
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (Sdf.ValueTypeNames.Bool, True)})
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert result.report.stats["remainingOverlaps"] == 0
    moved, offset = _moved_and_turned(source, Usd.Stage.Open(str(tmp_path / "c.usda")), "/World/Crowd/idler")
    assert moved > 0.15                                    # it was pushed aside
    assert offset.max() < 10.0 and offset.mean() < 2.0, (offset.max(), offset.mean())


def _reaching(name: str) -> walker.Clip:
    """The wandering idle, reaching out three times: 30 cm away and back within a second
    (fast enough for its path to say which way it turns there)."""
    clip = _wandering(name, 0.3)
    t = np.arange(FRAMES) / FPS
    translations = clip.translations.copy()
    for k, (centre, angle) in enumerate(((2.0, 0.3), (5.0, 2.0), (8.0, 4.0))):
        bump = 0.3 * np.exp(-0.5 * ((t - centre) / 0.2) ** 2)
        translations[:, 0, 0] += (bump * np.cos(angle)).astype(np.float32)
        translations[:, 0, 2] += (bump * np.sin(angle)).astype(np.float32)
    return dataclasses.replace(clip, translations=translations)


def test_an_in_place_clip_dragged_by_two_handles_drifts_without_turning(tmp_path):
    """Its first frame held where it was and its last pinned 1 m away (aside, or back): the idle
    drifts there and faces as its source does. Its source's first and last frames are a few
    centimetres apart, and their direction is its sway's: the turn from that direction onto
    the 1 m drag turned the whole clip 90 or 180 degrees (a CMU idle that reaches out, 22 s)."""
    for k, drag in enumerate(((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (-0.7, 0.0, 0.7))):
        folder = tmp_path / f"drag{k}"
        folder.mkdir()
        stage, source = _shot(folder, [examples.AgentSpec("idle", _reaching("idle"))])
        agent = "/World/Crowd/idle"
        first, last = evaluate.agent_root_positions(source, agent, [0.0, float(FRAMES - 1)])
        examples.add_position_constraint(stage, "/Edits/held", agent, 0, tuple(map(float, first)))
        examples.add_position_constraint(stage, "/Edits/dragged", agent, FRAMES - 1,
                                         tuple(map(float, last + np.array(drag))))
        stage.GetRootLayer().Save()
        result = solve(str(folder / "shot.usda"), output=str(folder / "e.usda"), composed=str(folder / "c.usda"))
        assert all(c.met for c in result.report.constraints)
        moved, offset = _moved_and_turned(source, Usd.Stage.Open(str(folder / "c.usda")), agent)
        assert moved > 0.9
        assert offset.max() < 2.0, (drag, offset.max(), offset.mean())
