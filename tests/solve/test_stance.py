"""The stance step: the edit's turn taken between steps and the body pivoting on its planted feet
(numpy, then on composed stages by UsdSkel FK against the same solve with pivotOnFeet off)."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd

from mocapedit.data import examples, walker
from mocapedit.pipeline.processor import solve
from mocapedit.solve import stance
from mocapedit.tools import measure
from mocapedit.usd import evaluate

from test_collisions import STAGES, _agents, _separation

FPS = 24.0


def _rotate(v, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def _gait(frames=97):
    """A straight walk along +u at 1.4 m/s: root, feet half a stride either side of it, planted in
    turn with double support between (frames are 1/24 s)."""
    t = np.arange(frames) / FPS
    root = np.stack([1.4 * t, np.zeros(frames)], axis=1)
    phase = (np.arange(frames) % 24) / 24.0
    planted = np.stack([phase < 0.6, (phase >= 0.5) | (phase < 0.1)], axis=1)
    feet = np.zeros((frames, 2, 2))
    for k, side in enumerate((0.1, -0.1)):
        # A planted foot stays where it landed; a free one swings to the next landing.
        landing = root[:, 0].copy()
        for i in range(1, frames):
            landing[i] = landing[i - 1] if planted[i, k] else root[i, 0] + 0.35
        feet[:, k] = np.stack([landing, np.full(frames, side)], axis=1)
    return root, feet, planted


def test_the_turn_waits_through_double_support_and_is_the_edits_at_each_free_stretchs_end():
    turn = np.linspace(0.0, 1.0, 50)
    double = np.zeros(50, dtype=bool)
    double[10:20] = double[30:35] = True
    fixed = np.zeros(50, dtype=bool)
    fixed[40] = True
    gated = stance.gated_turn(turn, double, fixed)
    assert np.all(gated[10:20] == gated[9]) and np.all(gated[30:35] == gated[29])
    for frame in (0, 9, 29, 40, 49):
        assert gated[frame] == pytest.approx(turn[frame])
    assert np.all(np.diff(gated) >= -1e-12)     # never turns back
    assert np.array_equal(stance.gated_turn(np.zeros(50), double, fixed), np.zeros(50))
    # A turn taken between steps already is taken so again, not later and faster each time (a
    # path that avoidance bent after a pivot pivots once more).
    np.testing.assert_allclose(stance.gated_turn(gated, double, fixed), gated, atol=1e-12)


def test_a_path_moved_and_turned_rigidly_is_left_exactly_as_it_is():
    """An unedited path, or one turned and carried as one rigid piece, moves the planted feet as
    the source does: nothing to pivot on."""
    root, feet, planted = _gait()
    fixed = np.zeros(len(root), dtype=bool)
    for angle, shift in ((0.0, (0.0, 0.0)), (0.7, (3.0, -2.0))):
        edited = _rotate(root, angle) + shift
        turn = np.full(len(root), angle)
        (uv, out_turn), = stance.pivot([root], [edited], [turn], [feet], [planted], [fixed], [1 / FPS])
        np.testing.assert_allclose(uv, edited, atol=1e-12)
        np.testing.assert_allclose(out_turn, turn, atol=1e-12)


def test_agents_pivoted_together_are_pivoted_as_one_by_one(monkeypatch):
    """Agents of two lengths, in batches of two (of the longer) or three (of the shorter): each
    gets what it gets alone."""
    monkeypatch.setattr(stance, "BATCH", 2 * 97)
    agents = []
    for k, frames in enumerate((97, 61, 97, 97, 61)):
        root, feet, planted = _gait(frames)
        turn = (0.3 + 0.1 * k) * np.clip((np.arange(frames) - 12) / 36.0, 0.0, 1.0)
        step = _rotate(np.diff(root, axis=0), turn[1:])
        edited = np.concatenate([root[:1], root[:1] + np.cumsum(step, axis=0)]) * (1.0 + 0.02 * k)
        fixed = np.zeros(frames, dtype=bool)
        fixed[[0, 30 + k]] = True
        agents.append((root, edited, turn, feet, planted, fixed, 1 / FPS))
    together = stance.pivot(*[list(column) for column in zip(*agents)])
    for agent, (uv, turn) in zip(agents, together):
        (alone_uv, alone_turn), = stance.pivot(*[[value] for value in agent])
        np.testing.assert_allclose(uv, alone_uv, atol=1e-12)
        np.testing.assert_allclose(turn, alone_turn, atol=1e-12)


def _planted_slide(root, feet, planted, uv, turn):
    """Mean speed of the planted feet beyond the source's, where the rigid motion of each frame
    (turn about the root, then onto ``uv``) puts them."""
    moved = _rotate(feet - root[:, None], turn[:, None]) + uv[:, None]
    wanted = _rotate(feet[1:] - feet[:-1], turn[1:, None])
    extra = np.linalg.norm((moved[1:] - moved[:-1]) - wanted, axis=-1) * FPS
    both = planted[1:] & planted[:-1]
    return extra[both].mean()


def test_a_bend_pivots_on_the_planted_feet_and_keeps_the_fixed_frames():
    """The walk bent by a turn that grows over two seconds: the planted feet slide a third as much
    beyond the source's, the fixed frames keep the edit's path and turn, and the shift stays
    a few centimetres."""
    root, feet, planted = _gait()
    frames = len(root)
    turn = 0.8 * np.clip((np.arange(frames) - 24) / 48.0, 0.0, 1.0)
    step = _rotate(np.diff(root, axis=0), turn[1:])
    edited = np.concatenate([root[:1], root[:1] + np.cumsum(step, axis=0)])
    fixed = np.zeros(frames, dtype=bool)
    fixed[[0, 60, frames - 1]] = True
    (uv, out_turn), = stance.pivot([root], [edited], [turn], [feet], [planted], [fixed], [1 / FPS])
    before = _planted_slide(root, feet, planted, edited, turn)
    after = _planted_slide(root, feet, planted, uv, out_turn)
    assert before > 0.04 and after < before / 3, (before, after)
    assert np.array_equal(uv[fixed], edited[fixed]) and np.array_equal(out_turn[fixed], turn[fixed])
    assert 0.005 < np.linalg.norm(uv - edited, axis=1).max() < 0.1


def test_a_shift_that_pays_itself_back_more_slowly_holds_the_feet_more_closely():
    """A walk carried 20 cm aside and back over 2 s without turning: with the shift paying
    itself back over 8 s instead of 2 (the last pivot after avoidance), the planted feet slide a
    tenth as much (1.8 -> 0.15 cm/s), the hips keeping more of their source's way."""
    root, feet, planted = _gait()
    frames = len(root)
    t = np.arange(frames) / FPS
    edited = root + np.stack([np.zeros(frames), 0.2 * np.sin(np.pi * np.clip((t - 0.5) / 2.0, 0.0, 1.0))], axis=1)
    turn = np.zeros(frames)
    fixed = np.zeros(frames, dtype=bool)
    fixed[[0, frames - 1]] = True
    slide, reach = {}, {}
    for ease in (stance.EASE_SECONDS, 8.0):
        (uv, out_turn), = stance.pivot([root], [edited], [turn], [feet], [planted], [fixed], [1 / FPS],
                                       ease_seconds=ease)
        slide[ease] = _planted_slide(root, feet, planted, uv, out_turn)
        reach[ease] = np.linalg.norm(uv - edited, axis=1).max()
    assert slide[8.0] < 0.5 * slide[stance.EASE_SECONDS], slide
    assert reach[8.0] > reach[stance.EASE_SECONDS], reach


def _solved(tmp_path, stage_path, pivot: bool):
    name = "on" if pivot else "off"
    composed = tmp_path / f"{name}.usda"
    result = solve(str(stage_path), output=str(tmp_path / f"{name}.edits.usda"), composed=str(composed),
                   foot_locking=False, guides=False, pivot_on_feet=pivot)
    return result, Usd.Stage.Open(str(composed))


@pytest.mark.parametrize("scene,bar", [("collisions_head_on", 1.25), ("collisions_crossing", 1.25),
                                       ("collisions_counterflow", 1.25), ("collisions_groups", 1.3)])
def test_avoidance_pivots_on_the_feet_and_still_ends_apart(tmp_path, scene, bar):
    """By FK on the composed stages: the moved agents' feet skate (before foot locking) at most
    ``bar`` times their source's on average, where rigid frames skated 1.5-1.7 times; no overlap
    is left, nobody reverses."""
    STAGES.STAGES[f"{scene}.usda"](tmp_path)
    stage_path = tmp_path / f"{scene}.usda"
    src = Usd.Stage.Open(str(stage_path))
    agents = _agents(src)
    ratios = {}
    for pivot in (False, True):
        result, out = _solved(tmp_path, stage_path, pivot)
        moved = [a for a in agents if result.report.agents.get(a, {}).get("edited")]
        figures = [measure.plausibility(src, out, a) for a in moved]
        ratios[pivot] = np.mean([f.foot_skate_ratio for f in figures])
        after, sep = _separation(out, agents, margin=0.05)
        assert after >= -1e-4 and sep.overlaps == 0, (pivot, after, sep.agents, sep.time_index)
        assert max(f.max_direction_deviation for f in figures) < 90.0
    assert ratios[True] <= bar < ratios[False] and ratios[True] < ratios[False] - 0.2, ratios


def test_what_the_clearing_solve_moves_pivots_on_the_feet_too(tmp_path, monkeypatch):
    """Two groups crossing: the solve that clears what the pivot moved into others bends paths
    again; the moved agents pivot once more on what it left. By FK: their feet skate less than
    with that last pivot left out, and still nobody overlaps."""
    from mocapedit.pipeline.passes import collisions as collisions_pass
    STAGES.STAGES["collisions_groups.usda"](tmp_path)
    stage_path = tmp_path / "collisions_groups.usda"
    src = Usd.Stage.Open(str(stage_path))
    agents = _agents(src)
    ratio = {}
    for last_pivot in (True, False):
        if not last_pivot:
            monkeypatch.setattr(collisions_pass, "_pivot_where_clear", lambda *args: None)
        (tmp_path / str(last_pivot)).mkdir()     # a layer of its own: USD keeps the first one open
        result, out = _solved(tmp_path / str(last_pivot), stage_path, True)
        moved = [a for a in agents if result.report.agents.get(a, {}).get("edited")]
        ratio[last_pivot] = np.mean([measure.plausibility(src, out, a).foot_skate_ratio for a in moved])
        after, sep = _separation(out, agents, margin=0.05)
        assert after >= -1e-4 and sep.overlaps == 0, (last_pivot, after, sep.agents)
    assert ratio[True] < ratio[False] - 0.02, ratio


def test_a_last_pivot_that_would_meet_another_agent_is_given_up(tmp_path, monkeypatch):
    """Head-on walkers whose last pivot (made to, here) would put one onto the other's path: it
    gives up that pivot, by halves, until nothing new overlaps: by FK nobody overlaps."""
    from mocapedit.pipeline.context import EditedPath
    from mocapedit.pipeline.passes import collisions as collisions_pass
    STAGES.STAGES["collisions_head_on.usda"](tmp_path)
    stage_path = tmp_path / "collisions_head_on.usda"
    src = Usd.Stage.Open(str(stage_path))
    agents = _agents(src)
    pivot_moved = collisions_pass.stance.pivot_moved
    calls = []

    def onto_the_other(ctx, keep=frozenset(), **kwargs):
        pivot_moved(ctx, keep, **kwargs)
        calls.append(dict(ctx.paths))
        if len(calls) == 2:   # the last pivot: agent_0000 walks where agent_0001 does
            a, b = ctx.paths[agents[0]], ctx.paths[agents[1]]
            ctx.paths[agents[0]] = EditedPath(ground=b.ground.copy(), heading=a.heading)

    monkeypatch.setattr(collisions_pass.stance, "pivot_moved", onto_the_other)
    result, out = _solved(tmp_path, stage_path, True)
    assert len(calls) == 2
    after, sep = _separation(out, agents, margin=0.05)
    assert after >= -1e-4 and sep.overlaps == 0, (after, sep.agents)
    assert result.report.stats["remainingOverlaps"] == 0


def test_pinned_frames_and_stationary_ranges_keep_the_edit(tmp_path):
    """A walker pinned at its start and end and bent at its middle, with a stationary range: the
    pins still hold to 1e-6 by FK, the range moves rigidly, and the feet slide less."""
    clip = walker.walk(frames=193, fps=FPS, speed=1.25, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=FPS, clips_dir=tmp_path / "clips", stationary={"walk": {"stand": (120, 140)}})
    a = "/World/Crowd/a"
    ends = evaluate.agent_root_positions(stage, a, [0.0, 96.0, 192.0])
    examples.add_position_constraint(stage, "/Edits/start", a, 0, tuple(map(float, ends[0])))
    examples.add_position_constraint(stage, "/Edits/middle", a, 96, tuple(map(float, ends[1] + [1.2, 0.0, 0.0])))
    examples.add_position_constraint(stage, "/Edits/end", a, 192, tuple(map(float, ends[2])))
    stage.GetRootLayer().Save()
    src = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    skate = {}
    for pivot in (False, True):
        result, out = _solved(tmp_path, tmp_path / "shot.usda", pivot)
        assert all(c["met"] and c["residual"] < 1e-6 for c in result.report.constraints)
        got = evaluate.agent_root_positions(out, a, [0.0, 96.0, 192.0])
        np.testing.assert_allclose(got[:, [0, 2]], (ends + [[0, 0, 0], [1.2, 0, 0], [0, 0, 0]])[:, [0, 2]], atol=1e-6)
        # The stationary range: every joint at every frame of it moved by one rigid motion.
        times = np.arange(120.0, 141.0)
        x = evaluate.joint_world_positions(src, a, times).reshape(-1, 3)
        y = evaluate.joint_world_positions(out, a, times).reshape(-1, 3)
        u, _, vt = np.linalg.svd((x - x.mean(0)).T @ (y - y.mean(0)))
        fitted = (x - x.mean(0)) @ (u @ vt) + y.mean(0)
        assert np.abs(fitted - y).max() < 1e-5
        skate[pivot] = measure.plausibility(src, out, a).foot_skate_ratio
    assert skate[True] <= skate[False] + 0.01, skate


def test_the_setting_and_the_cli_flag_turn_it_off(tmp_path):
    from conftest import run_cli
    STAGES.STAGES["collisions_head_on.usda"](tmp_path)
    stage_path = tmp_path / "collisions_head_on.usda"
    flag = run_cli("solve", stage_path, "-o", tmp_path / "flag.usda", "--no-pivot-on-feet", "--no-foot-locking")
    assert flag.returncode == 0, flag.stderr
    stage = Usd.Stage.Open(str(stage_path))
    settings = next(p for p in stage.Traverse() if p.GetTypeName() == "MocapSolveSettings")
    settings.CreateAttribute("pivotOnFeet", Sdf.ValueTypeNames.Bool, False, Sdf.VariabilityUniform).Set(False)
    stage.GetRootLayer().Save()
    solve(str(stage_path), output=str(tmp_path / "setting.usda"), foot_locking=False)
    on = solve(str(stage_path), output=str(tmp_path / "on.usda"), foot_locking=False, pivot_on_feet=True)
    layers = [Sdf.Layer.FindOrOpen(str(tmp_path / f"{n}.usda")) for n in ("flag", "setting", "on")]
    ops = [layer.GetAttributeAtPath("/World/Crowd/agent_0000.xformOp:translate:mocapEdit") for layer in layers]
    samples = [np.array([layer.QueryTimeSample(op.path, t) for t in (40.0, 60.0)]) for layer, op in zip(layers, ops)]
    np.testing.assert_allclose(samples[0], samples[1], atol=1e-12)
    assert np.abs(samples[2] - samples[0]).max() > 1e-3
    assert on.report.stats["remainingOverlaps"] == 0


def test_a_solve_resumed_from_an_earlier_result_keeps_the_sources_way():
    """Avoidance solved again after the pivot starts from paths the first solve bent: the rows that
    keep walkers going their way, and the check that sends a walker back to its path, take the way
    from the paths the first solve was given (``Problem.way``), not from the bent ones, so that two
    detours cannot add up to a walker turned round."""
    from mocapedit.solve import avoidance
    frames = 48
    straight = np.stack([np.linspace(0.0, 1.4 * (frames - 1) / FPS, frames), np.zeros(frames)], axis=1)
    bent = _rotate(straight, np.radians(70.0))
    problem = avoidance.Problem(names=["a"], paths=[bent], frame_times=[np.arange(frames, dtype=np.float64)],
                                radius=np.array([0.3]), height=np.array([1.8]), way=[straight])
    state = avoidance._State(problem, avoidance.Settings(time_codes_per_second=FPS))
    guard = avoidance._Forward(state)
    np.testing.assert_allclose(guard.normal[:, 0], np.broadcast_to([1.0, 0.0], guard.normal[:, 0].shape), atol=1e-12)
    # Turned 110 degrees from the way (70 from the bent path it was given): sent back.
    turned = _rotate(straight, np.radians(110.0))
    assert avoidance._walks_backward(state, turned)[0]


def test_a_pair_held_together_by_the_artist_does_not_keep_the_rest_from_pivoting(tmp_path):
    """Head-on walkers, and far from them two walkers that a hard relative constraint holds 40 cm
    apart (closer than their clearance: an overlap avoidance must leave): the walkers still pivot
    on their feet; the held pair keeps its paths."""
    (walk,) = STAGES._walks(1)
    agents = [examples.AgentSpec("agent_0000", walk, (0.0, 0.0, -4.0), 0.0),
              examples.AgentSpec("agent_0001", walk, (0.0, 0.0, 4.0), 180.0),
              examples.AgentSpec("host", walk, (20.0, 0.0, 0.0), 0.0),
              examples.AgentSpec("guest", walk, (22.0, 0.0, 0.0), 0.0)]
    stage = STAGES._stage(tmp_path, "held.usda", agents)
    examples.add_relative_constraint(stage, "/Edits/hold", "/World/Crowd/guest", 40, "/World/Crowd/host", 40,
                                     (0.4, 0.0, 0.0))
    stage.GetRootLayer().Save()
    src = Usd.Stage.Open(str(tmp_path / "held.usda"))
    ratio = {}
    for pivot in (False, True):
        result, out = _solved(tmp_path, tmp_path / "held.usda", pivot)
        assert any("/Edits/hold" in n for n in result.report.notes)
        ratio[pivot] = measure.plausibility(src, out, "/World/Crowd/agent_0000").foot_skate_ratio
    assert ratio[True] < ratio[False] - 0.2, ratio


def test_a_gait_that_hands_over_from_foot_to_foot_keeps_the_shift_smooth():
    """A walk whose feet hand over with no frame of double support (as real takes often read):
    the frames between two contacts are not a flight to pay the shift back in (it moved the hips
    5-16 cm in one frame there, once a step)."""
    root, feet, _ = _gait()
    frames = len(root)
    phase = (np.arange(frames) % 24) / 24.0
    planted = np.stack([phase < 0.5, phase >= 0.5], axis=1)
    turn = 0.8 * np.clip((np.arange(frames) - 24) / 48.0, 0.0, 1.0)
    step = _rotate(np.diff(root, axis=0), turn[1:])
    edited = np.concatenate([root[:1], root[:1] + np.cumsum(step, axis=0)]) * 1.1   # and 10% longer
    fixed = np.zeros(frames, dtype=bool)
    fixed[[0, frames - 1]] = True
    (uv, _), = stance.pivot([root], [edited], [turn], [feet], [planted], [fixed], [1 / FPS])
    jumps = np.linalg.norm(np.diff(uv - edited, axis=0), axis=1)
    assert jumps.max() < 0.02, jumps.max()     # 4.3 cm in the last frame, before


def test_the_turn_between_steps_eases_in_and_out():
    """The turn taken over a free stretch starts and stops gradually: its rate changes from frame
    to frame by no more than the edit's whole rate (it stepped from 0 to twice the edit's rate,
    and back, in one frame: a visible jerk at 24 fps)."""
    _, _, planted = _gait()
    frames = len(planted)
    turn = np.linspace(0.0, 1.0, frames)
    gated = stance.gated_turn(turn, planted.all(axis=1), np.zeros(frames, dtype=bool))
    rate = np.diff(gated)
    assert np.abs(np.diff(rate)).max() <= np.abs(np.diff(turn)).max() + 1e-12
    assert gated[0] == turn[0] and gated[-1] == pytest.approx(turn[-1])


def test_a_turn_on_the_way_off_a_fixed_range_waits_for_the_steps_and_is_shared_by_them():
    """A body leaves a stationary range on both feet while the edit turns it 40 degrees: it stands
    until a foot is free, then each of its next steps takes part of the turn, no step all of it."""
    fps = 30.0
    frames = 60
    t = np.arange(frames)
    turn = np.radians(40.0) * np.clip((t - 10) / 14.0, 0.0, 1.0)
    double = np.zeros(frames, dtype=bool)
    double[:20] = double[28:36] = double[44:] = True          # free: 20-27 and 36-43
    fixed = t <= 10                                             # the stationary range
    gated = stance.gated_turn(turn, double, fixed, 1.0 / fps)
    assert np.all(gated[:20] == 0.0)                            # no turn on both feet
    assert gated[43] == pytest.approx(turn[43])
    first, second = gated[27] - gated[19], gated[43] - gated[35]
    assert first > np.radians(10.0) and second > np.radians(10.0)
    assert np.all(np.diff(gated) >= -1e-12)
    assert np.abs(np.diff(gated)).max() * fps < stance.STEP_TURN_RATE * np.pi / 2 + 1e-9
    # Without a frame rate only the stretch up to the next free one's end counts: 17 frames
    # with 8 free ones, a little over MAX_SPEEDUP, so the turn waits a little less than fully.
    plain = stance.gated_turn(turn, double, fixed)
    wait = 2.0 - (17 / 8) / stance.MAX_SPEEDUP
    np.testing.assert_allclose(plain[:20], (1.0 - wait) * turn[:20], atol=1e-12)

