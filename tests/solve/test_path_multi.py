"""Several characters: relative constraints, groups, independent components (composed stage)."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from pxr import Sdf, Usd

from mocapedit.data import examples, walker
from mocapedit.geometry import ground, trajectory
from mocapedit.inspect import metrics
from mocapedit.tools import measure
from mocapedit.usd import evaluate
from mocapedit.solve import path_edit
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve

from conftest import REPO, world_joints

CROWD = "/World/Crowd"
FPS = 24.0


@pytest.fixture(scope="module")
def walk_clip():
    return walker.walk(frames=121, fps=FPS, speed=1.25, name="walk5")   # 6 m along +Z


def _stage(tmp_path, agents, name="shot.usda", **kw):
    return examples.build_crowd_stage(tmp_path / name, agents, up_axis="Y", fps=FPS, clips_dir=tmp_path / "clips", **kw)


def _solve(tmp_path, stage, **overrides):
    stage.GetRootLayer().Save()
    src = stage.GetRootLayer().realPath
    n = len(list(tmp_path.glob("out*.edits.usda")))
    edits, composed = tmp_path / f"out{n}.edits.usda", tmp_path / f"out{n}.edited.usda"
    result = solve(src, output=str(edits), composed=str(composed), **overrides)
    return result, Usd.Stage.Open(src), Usd.Stage.Open(str(composed))


def _root(stage, agent, frames):
    return ground.to_ground(world_joints(stage, f"{agent}/Skel", frames)[:, 0], "Y")


def _relative_residual(out, c_agent, frame, target, target_frame, offset_ground):
    a = _root(out, c_agent, [frame])[0]
    t = _root(out, target, [target_frame])[0]
    return float(np.linalg.norm(a - t - offset_ground))


def test_a_relative_constraint_holds_and_follows_later_edits(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip), examples.AgentSpec("b", walk_clip, (3.0, 0.0, 1.0))])
    a, b = f"{CROWD}/a", f"{CROWD}/b"
    examples.add_position_constraint(stage, "/Edits/a_start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/b_start", b, 0, (3.0, 0.0, 1.0))
    # B at frame 80 is 1 m to the +X side of A at frame 80 (world space).
    examples.add_relative_constraint(stage, "/Edits/side", b, 80, a, 80, (1.0, 0.0, 0.0))
    result, src, out = _solve(tmp_path, stage)
    assert _relative_residual(out, b, 80, a, 80, [1.0, 0.0]) < 1e-6
    entry = next(c for c in result.report.constraints if c["prim"] == "/Edits/side")
    assert entry["kind"] == "relative" and entry["met"] and entry["target"] == a and entry["targetFrame"] == 80
    assert result.layer.GetPrimAtPath("/MocapEdit/Guides/RelativeLinks")
    # Figure 5.7: the target is edited later; the agent follows and the constraint holds.
    examples.add_position_constraint(stage, "/Edits/a_drag", a, 120, (-2.0, 0.0, 5.5))
    result, _, out = _solve(tmp_path, stage)
    assert _relative_residual(out, b, 80, a, 80, [1.0, 0.0]) < 1e-6
    np.testing.assert_allclose(_root(out, a, [120])[0], [-2.0, -5.5], atol=1e-6)
    np.testing.assert_allclose(_root(out, b, [0])[0], [3.0, -1.0], atol=1e-6)
    moved = _root(out, b, [80])[0] - _root(src, b, [80])[0]
    assert np.linalg.norm(moved) > 0.5


def test_target_space_offsets_turn_with_the_target(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("host", walk_clip, (0, 0, 0), 30.0),
                              examples.AgentSpec("guest", walk_clip, (4.0, 0.0, 0.0), 0.0)])
    host, guest = f"{CROWD}/host", f"{CROWD}/guest"
    examples.add_position_constraint(stage, "/Edits/h0", host, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/h1", host, 120, (1.0, 0.0, 5.5))
    examples.add_position_constraint(stage, "/Edits/g0", guest, 0, (4.0, 0.0, 0.0))
    # 0.8 ahead of the host along its heading, 0.2 to its left (ground v is -z).
    examples.add_relative_constraint(stage, "/Edits/meet", guest, 100, host, 60, (0.8, 0.0, -0.2), space="target")
    result, src, out = _solve(tmp_path, stage)
    g = _root(out, host, np.arange(121))
    heading = trajectory.headings(g, [], 1.0)[60]
    c, s = np.cos(heading), np.sin(heading)
    offset = np.array([c * 0.8 - s * 0.2, s * 0.8 + c * 0.2])
    assert _relative_residual(out, guest, 100, host, 60, offset) < 1e-6
    # Not the world-space reading: the host's heading is far from zero.
    assert _relative_residual(out, guest, 100, host, 60, [0.8, 0.2]) > 0.3
    entry = next(c for c in result.report.constraints if c["prim"] == "/Edits/meet")
    assert entry["residual"] < 1e-6


def test_soft_relative_constraints_pull(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip), examples.AgentSpec("b", walk_clip, (3.0, 0.0, 0.0))])
    a, b = f"{CROWD}/a", f"{CROWD}/b"
    for agent, x in ((a, 0.0), (b, 3.0)):
        examples.add_position_constraint(stage, f"/Edits/{agent[-1]}0", agent, 0, (x, 0.0, 0.0))
        examples.add_position_constraint(stage, f"/Edits/{agent[-1]}1", agent, 120,
                                         (x, 0.0, float(walk_clip.translations[120, 0, 2])))
    examples.add_relative_constraint(stage, "/Edits/near", b, 60, a, 60, (1.0, 0.0, 0.0), strength="soft")
    result, src, out = _solve(tmp_path, stage)
    before = _relative_residual(src, b, 60, a, 60, [1.0, 0.0])
    after = _relative_residual(out, b, 60, a, 60, [1.0, 0.0])
    entry = next(c for c in result.report.constraints if c["prim"] == "/Edits/near")
    assert not entry["hard"] and entry["residual"] == pytest.approx(after, abs=1e-6)
    assert 1e-3 < after < 0.5 * before


def test_independent_components_solve_alone_and_together(tmp_path, walk_clip):
    """Agents in other components give exactly the result they give alone."""
    specs = [examples.AgentSpec(n, walk_clip, (x, 0.0, 0.0)) for n, x in (("a", 0.0), ("b", 2.0), ("c", 5.0),
                                                                             ("d", 8.0))]

    def edits(stage, with_others):
        examples.add_position_constraint(stage, "/Edits/a0", f"{CROWD}/a", 0, (0.0, 0.0, 0.0))
        examples.add_position_constraint(stage, "/Edits/a1", f"{CROWD}/a", 90, (1.0, 0.0, 4.0))
        examples.add_relative_constraint(stage, "/Edits/ab", f"{CROWD}/b", 60, f"{CROWD}/a", 60, (1.5, 0.0, 0.3))
        if with_others:
            examples.add_position_constraint(stage, "/Edits/c0", f"{CROWD}/c", 0, (5.0, 0.0, 0.0))
            examples.add_position_constraint(stage, "/Edits/c1", f"{CROWD}/c", 120, (7.0, 0.0, 5.0))
            examples.add_relative_constraint(stage, "/Edits/dc", f"{CROWD}/d", 30, f"{CROWD}/c", 40, (1.0, 0.0, 0.0))
    alone = _stage(tmp_path, specs, "alone.usda")
    edits(alone, False)
    together = _stage(tmp_path, specs, "together.usda")
    edits(together, True)
    r1, _, out1 = _solve(tmp_path, alone)
    r2, _, out2 = _solve(tmp_path, together)
    assert r2.report.stats["pathComponents"] == 2 and r1.report.stats["pathComponents"] == 1
    frames = np.arange(121)
    for agent in ("a", "b"):
        np.testing.assert_array_equal(world_joints(out1, f"{CROWD}/{agent}/Skel", frames),
                                      world_joints(out2, f"{CROWD}/{agent}/Skel", frames))
    assert r2.report.agents[f"{CROWD}/c"]["edited"]


def _load_stages():
    spec = importlib.util.spec_from_file_location("stages_path", REPO / "example_stages" / "stages_path.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_formation_turned_by_one_edit_keeps_its_neighbours(tmp_path):
    _load_stages().path_formation(tmp_path)
    result, src, out = _solve(tmp_path, Usd.Stage.Open(str(tmp_path / "path_formation.usda")))
    names = sorted(a for a in result.data.agents)
    assert len(names) == 14 and result.report.stats["pathComponents"] == 1
    frames = np.arange(0, 193, 4)
    s = np.array([_root(src, n, frames) for n in names])
    e = np.array([_root(out, n, frames) for n in names])
    # The leader's second half turned 90 degrees left...
    lead, half = names.index(f"{CROWD}/m00"), 24
    d0, d1 = s[lead, half] - s[lead, 0], e[lead, -1] - e[lead, half]
    turn = np.degrees(np.arctan2(d1[1], d1[0]) - np.arctan2(d0[1], d0[0])) % 360
    assert turn == pytest.approx(90.0, abs=1.0)
    # ... and so did its neighbour in the front row (the rows behind follow it round the
    # corner, the last ones reaching it after the clip ends).
    front = names.index(f"{CROWD}/m01")
    d2 = e[front, -1] - e[front, half]
    assert 60 < np.degrees(np.arctan2(d2[1], d2[0]) - np.arctan2(d0[1], d0[0])) % 360 < 120
    # ... and the neighbours stayed neighbours: distances change by under 5% on average (6% as
    # each member's body pivots on its own planted feet, a centimetre or two either way:
    # 4.4% -> 5.7%).
    change = metrics.neighbour_distance_change(s, e)
    assert np.nanmean(change) < 0.06
    assert all(result.report.agents[n]["edited"] for n in names)
    assert result.layer.GetPrimAtPath("/MocapEdit/Guides/GroupLinks")
    # The frames between key frames turn smoothly through the keys: the feet slide by
    # 0.075 m/s more than in the source on average (one similarity per interval, turning
    # at each key: 0.094 m/s).
    skate = [measure.foot_skate(out, n).mean - measure.foot_skate(src, n).mean for n in names]
    assert np.mean(skate) < 0.085
    # The turn is the artist's: no member walks back against it. Handles at the corner and at
    # the end level with it make the leader's rounded corner overshoot (its walk deviates by
    # more than 90 degrees from the unturned source), but against the turn the edit makes every
    # member's walk stays within 45 degrees, and none turns round (a loop).
    figures = measure.shot_plausibility(src, out, names)
    assert figures[lead].max_direction_deviation > 90.0
    assert max(f.max_turned_deviation for f in figures) < 45.0
    assert max(f.max_edit_turn for f in figures) < metrics.REVERSE_TURN_DEGREES
    assert not any(f.reverses for f in figures)
    assert result.report.stats["plausibility"]["reversingAgents"] == 0


def test_an_edit_that_sends_a_walker_back_is_a_reversal(tmp_path, walk_clip):
    # Held at its start and its middle, the end pinned 1 m behind the middle: the second half
    # has to walk back the way the first came, whatever the edit's own turn. The measure of
    # reversals against the edit's turn still calls that a reversal.
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    z = walk_clip.translations[:, 0, 2].astype(float)
    agent = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", agent, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/middle", agent, 60, (0.0, 0.0, z[60]))
    examples.add_position_constraint(stage, "/Edits/back", agent, 120, (0.5, 0.0, z[60] - 1.0))
    result, src, out = _solve(tmp_path, stage)
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    p = measure.plausibility(src, out, agent)
    assert p.reverses and p.max_direction_deviation > 150.0
    assert p.max_edit_turn > metrics.REVERSE_TURN_DEGREES   # sent back: turned by about 180 degrees
    assert result.report.stats["plausibility"]["reversingAgents"] == 1
    assert result.report.agents[agent]["plausibility"]["reverses"] is True


def test_a_large_formation_is_solved_end_to_end_in_a_dissection_order(tmp_path, monkeypatch):
    # 8 x 8 members of 480 frames: 2,600 key vertices, factored by CHOLMOD in the nested
    # dissection's order (mocapedit/nested_dissection.h), which here fills less than AMD's.
    # What is written is the same as in AMD's order.
    frames, rows, cols = 480, 8, 8
    clip = walker.walk(frames=frames, fps=FPS, speed=1.25, name="walk20")   # 20 m along +Z
    specs = [examples.AgentSpec(f"m{r}{c}", clip, (1.0 * c, 0.0, -1.2 * r)) for r in range(rows) for c in range(cols)]
    stage = _stage(tmp_path, specs)
    names = [f"{CROWD}/m{r}{c}" for r in range(rows) for c in range(cols)]
    examples.add_group(stage, "/Edits/block", names)
    z = clip.translations[:, 0, 2].astype(float)
    lead, half = names[0], frames // 2
    examples.add_position_constraint(stage, "/Edits/start", lead, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/half", lead, half, (0.0, 0.0, z[half]))
    examples.add_position_constraint(stage, "/Edits/turn", lead, frames - 1, (z[-1] - z[half], 0.0, z[half]))
    result, src, out = _solve(tmp_path, stage)
    assert {result.report.agents[n]["solver"] for n in names} == {
        "CHOLMOD supernodal (nested dissection); CHOLMOD supernodal"}
    positions = [c for c in result.report.constraints if c["kind"] == "position"]
    assert len(positions) == 3 and max(c["residual"] for c in positions) < 1e-6
    np.testing.assert_allclose(_root(out, lead, [frames - 1])[0], [z[-1] - z[half], -z[half]], atol=1e-6)
    monkeypatch.setattr(path_edit.ComponentProblem, "_vertex_times", lambda self: None)
    reference, _, amd = _solve(tmp_path, stage)
    assert result.report.agents[lead]["solver"] != reference.report.agents[lead]["solver"]
    sampled = np.arange(frames)
    for n in names[::7]:
        np.testing.assert_allclose(_root(out, n, sampled), _root(amd, n, sampled), rtol=0, atol=1e-5)  # float32 at 20 m


def test_a_group_in_two_blocks_and_a_member_of_another_time_solve_end_to_end(tmp_path, walk_clip):
    # Blocks 10 m apart: the group mesh joins them, so the far block follows the edit. A
    # second group pairs a far-block member with one whose clip plays after it (no shared
    # time): it joins nothing, and the later one, held by nothing, is left as it was.
    spots = [(0.0, 0.0), (1.0, 0.0), (0.0, -1.2), (1.0, -1.2), (10.0, 0.0), (11.0, 0.0), (10.0, -1.2), (11.0, -1.2)]
    specs = [examples.AgentSpec(f"m{i}", walk_clip, (x, 0.0, z)) for i, (x, z) in enumerate(spots)]
    specs.append(examples.AgentSpec("late", walk_clip, (5.0, 0.0, 0.0), time_offset=500.0))
    stage = _stage(tmp_path, specs)
    names = [f"{CROWD}/{s.name}" for s in specs]
    examples.add_group(stage, "/Edits/blocks", names[:8])
    examples.add_group(stage, "/Edits/apart_in_time", [names[4], names[8]])
    lead = names[0]
    examples.add_position_constraint(stage, "/Edits/start", lead, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/end", lead, 120, (-2.0, 0.0, 5.5))
    result, src, out = _solve(tmp_path, stage)
    assert max(c["residual"] for c in result.report.constraints if c["kind"] == "position") < 1e-6
    solvers = {result.report.agents[n]["solver"] for n in names[:8]}
    assert not any(s.startswith("SPQR") for s in solvers), solvers
    frames = np.arange(121)
    far = [np.abs(_root(out, n, frames) - _root(src, n, frames)).max() for n in names[4:8]]
    assert min(far) > 0.5
    np.testing.assert_allclose(_root(out, names[8], 500 + frames), _root(src, names[8], 500 + frames), atol=1e-6)


def test_the_relay_holds_every_hand_over(tmp_path):
    stages = _load_stages()
    stages.path_relay(tmp_path)
    result, src, out = _solve(tmp_path, Usd.Stage.Open(str(tmp_path / "path_relay.usda")))
    relative = [c for c in result.report.constraints if c["kind"] == "relative"]
    assert len(relative) == stages.RELAY_RUNNERS - 1 >= 50
    assert max(c["residual"] for c in relative) < 1e-6
    for k in (0, 25, 50):
        a, b = f"{CROWD}/r{k:02d}", f"{CROWD}/r{k + 1:02d}"
        ta, tb = (result.data.agents[x].sample_times for x in (a, b))   # frames play at offset times
        assert ta[95] == tb[0]
        hand = _root(out, a, [ta[95]])[0] - _root(out, b, [tb[0]])[0]
        np.testing.assert_allclose(hand, [0.4, 0.0], atol=1e-6)
    positions = [c for c in result.report.constraints if c["kind"] == "position"]
    assert len(positions) == 3 and all(c["met"] for c in positions)


def test_bad_multi_character_input(tmp_path, walk_clip):
    specs = [examples.AgentSpec(n, walk_clip, (x, 0.0, 0.0)) for n, x in (("a", 0.0), ("b", 2.0), ("c", 4.0))]
    a, b, c = (f"{CROWD}/{n}" for n in "abc")
    stage = _stage(tmp_path, specs)
    examples.add_relative_constraint(stage, "/Edits/self", a, 10, a, 10, (1.0, 0.0, 0.0))
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</Edits/self>\.target.*itself"):
        solve(stage.GetRootLayer().realPath)
    # The same agent at another frame is fine.
    stage.GetPrimAtPath("/Edits/self").GetAttribute("targetFrame").Set(20)
    stage.GetRootLayer().Save()
    solve(stage.GetRootLayer().realPath)
    stage.RemovePrim("/Edits/self")

    examples.add_group(stage, "/Edits/lonely", [a])
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</Edits/lonely>\.members.*two members"):
        solve(stage.GetRootLayer().realPath)
    stage.RemovePrim("/Edits/lonely")

    # A cycle of hard relative constraints whose offsets do not add up: named in full.
    examples.add_position_constraint(stage, "/Edits/pin", a, 0, (0.0, 0.0, 0.0))
    examples.add_relative_constraint(stage, "/Edits/ab", b, 50, a, 50, (1.0, 0.0, 0.0))
    examples.add_relative_constraint(stage, "/Edits/bc", c, 50, b, 50, (1.0, 0.0, 0.0))
    examples.add_relative_constraint(stage, "/Edits/ca", a, 50, c, 50, (-1.5, 0.0, 0.0))
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</Edits/ab>, </Edits/bc>, </Edits/ca>.*0\.5"):
        solve(stage.GetRootLayer().realPath)
    stage.GetPrimAtPath("/Edits/ca").GetAttribute("offset").Set((-2.0, 0.0, 0.0))   # now it closes
    stage.GetRootLayer().Save()
    result = solve(stage.GetRootLayer().realPath)
    assert max(e["residual"] for e in result.report.constraints if e["kind"] == "relative") < 1e-6


def test_free_motions_are_resolved_without_drifting():
    """Two agents tied by one relative constraint and nothing else: each moves half way,
    by a translation (the gauge), and nothing turns."""
    f = np.arange(50, dtype=float)
    a = np.stack([f * 0.05, np.zeros(50)], axis=1)
    b = a + [0.0, 3.0]
    inputs = [path_edit.AgentInput(p, r, r, np.zeros(50), []) for p, r in (("a", a), ("b", b))]
    link = path_edit.Link("b", 25, "a", 25, np.array([0.0, 1.0]), "world", np.inf, "/link")
    settings = path_edit.Settings(min_baseline=0.01, rigid_min_extent=0.02, still=1e-5)
    result = path_edit.ComponentProblem(inputs, [], [link], [], settings).solve()
    da, db = result.agents["a"].ground - a, result.agents["b"].ground - b
    np.testing.assert_allclose(da, np.tile([0.0, 1.0], (50, 1)), atol=1e-9)
    np.testing.assert_allclose(db, np.tile([0.0, -1.0], (50, 1)), atol=1e-9)
    assert result.agents["a"].translate_only


@pytest.mark.parametrize("builder, stage", [("path_edit", "path_edit.usda"), ("path_stationary", "path_stationary.usda"),
                                            ("path_handshake", "path_handshake.usda")])
def test_example_edits_keep_foot_skate_low(tmp_path, builder, stage):
    """Foot skate (mean horizontal foot speed in contact, m/s) on the composed stage, over
    the source's contact frames, rises by less than 4 cm/s for the example edits."""
    getattr(_load_stages(), builder)(tmp_path)
    result, src, out = _solve(tmp_path, Usd.Stage.Open(str(tmp_path / stage)))
    edited = [a for a, e in result.report.agents.items() if e.get("edited")]
    assert edited
    for agent in edited:
        before = measure.foot_skate(src, agent)
        after = measure.foot_skate(out, agent, times=before.times, contact=before.contact)
        assert after.mean - before.mean < 0.04, f"{agent}: {before.mean:.3f} -> {after.mean:.3f} m/s"


def test_a_long_stand_bent_by_handles_turns_the_body_smoothly(tmp_path):
    """A 60 fps, Z-up centimetre walk with a 4 s untagged stand whose root jitters, bent by
    three handles (one inside the stand moved 0.8 m aside, the end as much): the body turns with
    the bend, never spins, and the handles hold. With the heading taken from the edited path's
    tangent, the stand spins by up to 177 degrees in one frame. Before foot locking the feet
    slide 1.01 times as fast as the source's (#16's bar: 1.25), the path as long as it was."""
    stages = _load_stages()
    stages.path_long_stand(tmp_path)
    # Plausibility is the edit's, before foot locking plants the feet again: measured without it.
    result, src, out = _solve(tmp_path, Usd.Stage.Open(str(tmp_path / "path_long_stand.usda")),
                              foot_locking=False)
    agent = f"{CROWD}/stander"
    for c in result.report.constraints:
        assert c["residual"] < 1e-6, c
    p = measure.plausibility(src, out, agent)
    # The solve reports the same figures as UsdSkel FK on the composed stage gives.
    reported = result.report.agents[agent]["plausibility"]
    assert reported["maxExtraFacingRate"] == pytest.approx(p.max_extra_facing_rate, abs=0.5)
    assert reported["maxDirectionDeviation"] == pytest.approx(p.max_direction_deviation, abs=0.01)
    assert reported["lengthRatio"] == pytest.approx(p.length_ratio, rel=1e-4)
    assert reported["footSkateRatio"] == pytest.approx(p.foot_skate_ratio, rel=1e-3)
    assert reported["spinFrames"] == 0 and result.report.stats["plausibility"]["spinningAgents"] == 0
    assert "largest extra turn" in result.report.summary()
    assert p.spin_frames == 0
    assert p.max_extra_facing_rate < 60.0                    # under 1 degree per frame at 60 fps
    assert p.max_direction_deviation < 20.0 and not p.reverses
    assert p.foot_skate_ratio <= 1.25 and abs(p.length_ratio - 1.0) < 0.02
    # The stand turns with the handles: from the first walk's turn towards the second's, in one
    # smooth sweep.
    _, (first, last) = stages.long_stand_clip()
    t, ms = evaluate.joint_world_matrices(src, agent)
    _, me = evaluate.joint_world_matrices(out, agent)
    turn = np.degrees(metrics.body_facing(me, "Z") - metrics.body_facing(ms, "Z"))
    assert np.abs(np.diff(turn[first:last + 1])).max() < 0.2
    # The first walk turns by about 10 degrees, the second by about 1.5; the stand turns between.
    before, after = turn[first - 60:first].mean(), turn[last + 1:last + 61].mean()
    assert before > 8.0 and after < 3.0
    assert turn[first:last + 1].max() - turn[first:last + 1].min() > 5.0
    assert min(before, after) - 1.0 < turn[first:last + 1].min() <= turn[first:last + 1].max() < max(before, after) + 1.0


def test_a_long_stand_whose_second_walk_handles_stretch_keeps_its_feet_once_locked(tmp_path):
    """The same stand with handles that ask more than a bend: the stand 0.8 m aside, the end 1.5 m
    aside and 0.5 m further on, so the walk after the stand must be a fifth longer. No motion of
    the whole body lengthens strides: before foot locking the feet slide 1.27 times as fast as the
    source's; locked, no faster than the source's (within #17's 0.5 cm/s)."""
    stages = _load_stages()
    stages.path_long_stand(tmp_path, handles={"start": (0, (0.0, 0.0)), "stand": (320, (80.0, 0.0)),
                                              "end": (599, (150.0, -50.0))})
    agent = f"{CROWD}/stander"
    src = Usd.Stage.Open(str(tmp_path / "path_long_stand.usda"))
    result, _, free = _solve(tmp_path, src, foot_locking=False)
    result, _, out = _solve(tmp_path, src)
    assert all(c["residual"] < 1e-6 for c in result.report.constraints)
    unlocked, locked = measure.plausibility(src, free, agent), measure.plausibility(src, out, agent)
    assert unlocked.length_ratio > 1.05 and unlocked.foot_skate_ratio > 1.25
    assert locked.foot_skate_edited <= locked.foot_skate_source + 0.5        # cm/s


def test_backward_walks_and_turns_on_the_spot_keep_their_facing(tmp_path):
    """A walk played backwards (the body faces +Z while the root goes -Z) bent 1 m sideways keeps
    facing +Z, turned only by the bend; a slow turn on the spot dragged 1 m keeps its own turn."""
    import dataclasses
    walk = walker.walk(frames=97, fps=24.0, speed=1.25, name="forward")
    back = dataclasses.replace(walk, name="backward", translations=walk.translations[::-1].copy(),
                               rotations=walk.rotations[::-1].copy(), foot_contacts=walk.foot_contacts[::-1].copy())
    spot = walker.turn(frames=96, fps=24.0, speed=0.02, turn_rate=90.0, name="spot")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("back", back),
                                                                examples.AgentSpec("spot", spot, (3.0, 0.0, 0.0))],
                                       fps=24.0, clips_dir=tmp_path / "clips")
    b, s = f"{CROWD}/back", f"{CROWD}/spot"
    for f in (0, 48, 96):
        x, _, z = (float(v) for v in back.translations[f, 0])
        examples.add_position_constraint(stage, f"/Edits/back{f}", b, f, (x + (1.0 if f == 48 else 0.0), 0.0, z))
    x, _, z = (float(v) for v in spot.translations[0, 0])
    examples.add_position_constraint(stage, "/Edits/spot", s, 0, (x + 4.0, 0.0, z + 1.0))
    result, src, out = _solve(tmp_path, stage)
    for agent, most in ((b, 35.0), (s, 1e-6)):
        p = measure.plausibility(src, out, agent)
        assert p.spin_frames == 0
        _, ms = evaluate.joint_world_matrices(src, agent)
        _, me = evaluate.joint_world_matrices(out, agent)
        turn = np.degrees(metrics.body_facing(me, "Y") - metrics.body_facing(ms, "Y"))
        assert np.abs(turn).max() < most, agent      # never turned round to face its path
        if agent == b:                               # the bend turns the two halves both ways
            assert abs(turn[48]) < 2.0 and turn[0] * turn[-1] < 0
    assert p.source_max_facing_rate > 80.0             # the spot turn is there, and kept
