"""Collision avoidance and avoid regions (issue: chapter 6 and section 4.3.2 of the deliverable).

Quality is measured on the composed stage: root positions by UsdSkel forward kinematics,
capsule clearance by mocapedit.inspect.metrics.
"""
from __future__ import annotations

import importlib.util
import io

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom

from mocapedit import _solver
from mocapedit.solve import avoidance, collisions
from mocapedit.data import examples, walker
from mocapedit.inspect import metrics
from mocapedit.tools import measure
from mocapedit.usd import evaluate
from mocapedit.model import report
from mocapedit.usd.report_io import read_report
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve
from mocapedit.model.progress import Progress

from conftest import CROSSROADS_MEET, REPO, run_cli, write_crossroads

FPS = 24.0


def _stage_module(name: str = "stages_collisions"):
    spec = importlib.util.spec_from_file_location(f"mocapedit_{name}", REPO / "example_stages" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


STAGES = _stage_module()


def _solve(tmp_path, stage_path, **kw):
    edits, composed = tmp_path / f"{stage_path.stem}.edits.usda", tmp_path / f"{stage_path.stem}.out.usda"
    result = solve(str(stage_path), output=str(edits), composed=str(composed), **kw)
    return result, Usd.Stage.Open(str(composed))


def _agents(stage):
    return sorted(str(p.GetPath()) for p in stage.Traverse() if "MocapAgentAPI" in p.GetAppliedSchemas())


def _ground_roots(stage, agents, times):
    """(A, T, 3) world root positions with the up coordinate set to the ground (capsule bases)."""
    pos = evaluate.agent_root_positions(stage, agents, times)
    pos[..., metrics.ground_axes(UsdGeom.GetStageUpAxis(stage))[0]] = 0.0
    return pos


def _shot_times(stage):
    return np.arange(stage.GetStartTimeCode(), stage.GetEndTimeCode() + 1.0)


def _separation(stage, agents, margin=0.0, radius=0.3, height=1.8):
    times = _shot_times(stage)
    sep = metrics.min_separation(_ground_roots(stage, agents, times), radius, height, UsdGeom.GetStageUpAxis(stage))
    return sep.clearance - margin, sep


def _walker_stage(path, specs, frames=120, settings=None, stationary=None):
    """A Y-up metre stage of walkers: specs are (name, clip, position, yaw, time offset)."""
    agents = [examples.AgentSpec(n, c, p, y, o) for n, c, p, y, o in specs]
    stage = examples.build_crowd_stage(path, agents, up_axis="Y", meters_per_unit=1.0, fps=FPS,
                                       clips_dir=path.parent / "clips", stationary=stationary)
    vt = Sdf.ValueTypeNames
    attrs = {"collisionAvoidance": (vt.Bool, True), "margin": (vt.Double, 0.05)}
    attrs.update(settings or {})
    examples.define_mocap_prim(stage, "/World/Settings", "MocapSolveSettings", attributes=attrs)
    stage.GetRootLayer().Save()
    return stage


def _walk(name="walk_t", frames=120, phase=0.0):
    return walker.walk(frames=frames, fps=FPS, speed=1.4, up="Y", meters_per_unit=1.0, phase=phase, name=name)


# ---- the two example scenes ------------------------------------------------------------------

def test_head_on_pair_ends_apart_within_ten_iterations(tmp_path):
    STAGES.head_on(tmp_path)
    src = Usd.Stage.Open(str(tmp_path / "collisions_head_on.usda"))
    agents = _agents(src)
    before, _ = _separation(src, agents)
    assert before < -0.5, "the walkers must meet head-on in the source"
    result, out = _solve(tmp_path, tmp_path / "collisions_head_on.usda")
    stats = result.report.stats
    assert stats["remainingOverlaps"] == 0 and stats["collisionIterations"] <= 10
    assert stats["collisionsPerIteration"][0] >= 1 and stats["collisionsPerIteration"][-1] == 0
    after, _ = _separation(out, agents, margin=0.05)
    assert after >= -1e-6
    # A sidestep, not a shove: each walker moves less than a metre and keeps its pace.
    for a in agents:
        figures = result.report.agents[a]
        assert figures["maxDisplacement"] < 1.0
        assert abs(figures["lengthRatio"] - 1.0) < 0.05
        assert figures["minSeparation"] >= 0.05 - 1e-6


def test_dense_crossing_of_128_walkers_ends_apart_and_keeps_the_marks(tmp_path):
    STAGES.crossing(tmp_path)
    stage_path = tmp_path / "collisions_crossing.usda"
    src = Usd.Stage.Open(str(stage_path))
    agents = _agents(src)
    assert len(agents) >= 100
    before, sep = _separation(src, agents)
    assert before < 0 and sep.overlaps > 100
    result, out = _solve(tmp_path, stage_path)
    assert result.report.stats["remainingOverlaps"] == 0
    assert result.report.stats["collisionIterations"] <= 10
    after, _ = _separation(out, agents, margin=0.05)
    assert after >= -1e-6
    # Every artist mark (hard position constraint) still holds on the composed stage.
    marks = [p for p in src.Traverse() if p.GetTypeName() == "MocapPositionConstraint"]
    assert len(marks) == 8
    for mark in marks:
        agent = str(mark.GetRelationship("agent").GetTargets()[0])
        frame = mark.GetAttribute("frame").Get()
        want = np.array(mark.GetAttribute("position").Get())
        got = evaluate.agent_root_positions(out, agent, [float(frame)])[0]
        was = evaluate.agent_root_positions(src, agent, [float(frame)])[0]
        assert np.linalg.norm((got - was)[[0, 2]]) < 1e-6, mark.GetPath()
        assert np.linalg.norm((got - want)[[0, 2]]) < 1e-6, mark.GetPath()
    assert result.report.stats["editedAgents"] > 50


@pytest.mark.parametrize("shape", ["circle", "box"])
@pytest.mark.parametrize("region_anchor", [None, 1.5e-7])
def test_a_walker_goes_round_a_region_no_further_than_its_clearance(shape, region_anchor):
    """A straight walk (24 fps, 1.4 m/s) through a circle 1.6 m in radius, or a box 3.2 m x 2 m
    turned 30 degrees, 10 cm off its centre: the path comes as close to the region as its
    clearance (0.4 m) allows, no closer and no more than 15 cm further. A frame inside went
    sideways by its path's tangent over two frames (12 cm) instead of by unit length: its row
    took a point part of the way out and held the walker 1.6 to 2.2 m further from the circle
    than its clearance, 0.7 to 1.2 m from the box."""
    if shape == "circle":
        footprint = _solver.GroundRegion.circle(np.array([0.0, 0.0]), 1.6)
    else:
        c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
        corners = np.array([[-1.6, -1.0], [1.6, -1.0], [1.6, 1.0], [-1.6, 1.0]]) @ np.array([[c, s], [-s, c]])
        footprint = _solver.GroundRegion.hull(np.ascontiguousarray(corners))
    frames = 120
    x = np.linspace(3.47, -3.47, frames)
    path = np.stack([x, np.full(frames, 0.1)], axis=1)
    problem = avoidance.Problem(names=["a"], paths=[path], frame_times=[np.arange(frames, dtype=np.float64)],
                                radius=np.array([0.3]), height=np.array([1.8]), margin=0.05,
                                regions=[avoidance.Region("r", footprint, np.array([0]), np.array([0.4]))])
    out = avoidance.resolve(problem, avoidance.Settings(region_anchor_weight=region_anchor))
    assert out.converged
    nearest = collisions.signed_distance(footprint, out.paths[0]).min()
    assert 0.4 - 1e-6 <= nearest <= 0.55, nearest


def test_avoid_regions_end_with_no_agent_inside(tmp_path):
    STAGES.avoid_regions(tmp_path)
    stage_path = tmp_path / "avoid_regions.usda"
    src = Usd.Stage.Open(str(stage_path))
    result, out = _solve(tmp_path, stage_path)
    data = result.data
    agents = _agents(src)
    times = _shot_times(out)
    roots = {}
    for a, pos in zip(agents, evaluate.agent_root_positions(out, agents, times)):
        roots[a] = metrics.to_ground(pos, "Y")
    src_roots = dict(zip(agents, (metrics.to_ground(p, "Y") for p in evaluate.agent_root_positions(src, agents, times))))
    entered = 0
    for region in data.avoid_regions:
        footprint = collisions.region_footprint(region, "Y")
        for a in agents:
            clearance = data.agents[a].collision_radius + region.margin
            d = collisions.signed_distance(footprint, roots[a])
            assert d.min() >= clearance - 1e-4, f"{a} inside {region.path} by {clearance - d.min():g}"
            entered += collisions.signed_distance(footprint, src_roots[a]).min() < clearance
    assert entered >= 6, "the source walks must cross the regions"
    stats = result.report.stats
    assert stats["regionFramesLeft"] == 0 and stats["remainingOverlaps"] == 0
    entries = [c for c in result.report.constraints if c["kind"] == "avoid-region"]
    assert len(entries) >= entered and all(c["met"] for c in entries)
    assert out.GetPrimAtPath("/MocapEdit/Guides/AvoidRegions")


def test_a_walker_going_round_a_fountain_keeps_its_feet_planted(tmp_path):
    """A walker whose 7 m walk heads 10 cm off the centre of a fountain 3.2 m wide (a circle
    region) in the middle of the shot goes round it with its feet planted: after foot locking,
    its skate over the source's contacts by UsdSkel FK is at most the source's plus 0.5 cm/s,
    and the detour alone (before locking) drags them at most 2.5 times the source's skate.
    A detour bent within 0.75 s each side dragged them 5 times the source's skate (+2.0 cm/s
    locked, when it also went 1.6 m too far); the detour round a static region is spread over
    the approach."""
    walk = walker.walk(frames=120, fps=FPS, speed=1.4, up="Y", meters_per_unit=1.0, name="walk_fountain")
    travel = 1.4 * 119 / FPS
    path = tmp_path / "fountain.usda"
    stage = _walker_stage(path, [("agent_0000", walk, (travel / 2, 0.0, 0.1), -90.0, 0.0)])
    vt = Sdf.ValueTypeNames
    fountain = examples.define_mocap_prim(stage, "/World/Regions/fountain", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "circle"), "radius": (vt.Double, 1.6), "margin": (vt.Double, 0.1)})
    UsdGeom.Xformable(fountain).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.0))
    stage.GetRootLayer().Save()
    src = Usd.Stage.Open(str(path))
    result, out = _solve(tmp_path, path, guides=False)
    agent = "/World/Crowd/agent_0000"
    ground = metrics.to_ground(evaluate.agent_root_positions(out, [agent], _shot_times(out))[0], "Y")
    radius = result.data.agents[agent].collision_radius
    assert np.linalg.norm(ground, axis=1).min() >= 1.6 + 0.1 + radius - 1e-4, "the walker must go round"
    p = measure.plausibility(src, out, agent)
    assert p.foot_skate_edited <= p.foot_skate_source + 0.005, (p.foot_skate_source, p.foot_skate_edited)
    entry = result.report.agents[agent]
    assert entry.foot_skate_edited <= entry.foot_skate_source + 0.005
    assert entry.foot_skate_unlocked <= 2.5 * entry.foot_skate_source
    assert p.length_ratio < 1.02 and p.max_direction_deviation < 45.0


def test_avoid_regions_keeps_every_walkers_feet_planted(tmp_path):
    """The example plaza (24 walkers, a fountain, ropes and a kiosk in their way): after foot
    locking, every moved walker's skate is at most its source's plus 0.5 cm/s, and so is the
    shot's mean (detours spread over 0.75 s each side left agents 0007 and 0018 at +17 cm/s)."""
    STAGES.avoid_regions(tmp_path)
    result, _ = _solve(tmp_path, tmp_path / "avoid_regions.usda", guides=False)
    stats = result.report.stats
    assert stats["footSkateEdited"] <= stats["footSkateSource"] + 0.005
    for name, entry in result.report.agents.items():
        if entry.edited:
            assert entry.foot_skate_edited <= entry.foot_skate_source + 0.005, name


def _walking_deviation(src_ground, out_ground, fps, chord_s=0.25, moving_m_s=0.2):
    """(A,) each agent's largest angle (degrees) between its edited walking direction and
    its source's, over chords of ``chord_s`` seconds, where the source moves faster than
    ``moving_m_s`` (ground positions (A, T, 2) in metres, one per time code). Each edited
    chord is compared with the source chord that starts nearest to it on the ground, so a
    walker that waited is compared with where it walks, not with where it was."""
    h = max(1, int(round(chord_s * fps)))
    c0, c1 = src_ground[:, h:] - src_ground[:, :-h], out_ground[:, h:] - out_ground[:, :-h]
    near = np.argmin(np.linalg.norm(out_ground[:, :-h, None] - src_ground[:, None, :-h], axis=3), axis=2)
    c0 = np.take_along_axis(c0, near[..., None], axis=1)
    n0, n1 = np.linalg.norm(c0, axis=2), np.linalg.norm(c1, axis=2)
    cos = np.sum(c0 * c1, axis=2) / np.maximum(n0 * n1, 1e-12)
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    # An edited chord that barely moves (a walker standing, or waiting) has no direction.
    return np.where((n0 > moving_m_s * h / fps) & (n1 > 0.05 * h / fps), angle, 0.0).max(axis=1)


@pytest.mark.parametrize("scene,length_change", [
    ("collisions_head_on", (0.02, 0.1)), ("collisions_crossing", (0.02, 0.1)), ("collisions_corridor", (0.02, 0.1)),
    ("collisions_counterflow", (0.02, 0.1)), ("collisions_bottleneck", (0.02, 0.1)), ("collisions_groups", (0.02, 0.1)),
    # Going round a fountain 2.4 m wide, a kiosk and ropes in the way adds length.
    ("avoid_regions", (0.04, 0.3))])
def test_scene_ends_apart_without_loops_or_detours(tmp_path, scene, length_change):
    """Measured on the composed stage by UsdSkel FK: no overlapping pair in the shot, no
    agent walking more than 90 degrees off its source direction, mean path length change
    under 2 % between agents (over the whole clip: a walker that waited finishes after the
    shot), under 4 % where regions stand in the way."""
    STAGES.STAGES[f"{scene}.usda"](tmp_path)
    stage_path = tmp_path / f"{scene}.usda"
    src = Usd.Stage.Open(str(stage_path))
    agents = _agents(src)
    before, _ = _separation(src, agents, margin=0.05)
    regions = [p for p in src.Traverse() if p.GetTypeName() == "MocapAvoidRegion"]
    assert before < 0 or regions, "the scene must need avoidance"
    result, out = _solve(tmp_path, stage_path, guides=False)
    after, sep = _separation(out, agents, margin=0.05)
    assert after >= -1e-4 and sep.overlaps == 0, (after, sep.agents, sep.time_index)
    assert result.report.stats["regionFramesLeft"] == 0
    wait = result.report.stats.get("largestDelay", 0.0)
    times = np.arange(src.GetStartTimeCode(), src.GetEndTimeCode() + np.ceil(wait * FPS) + 1.0)
    g0 = metrics.to_ground(evaluate.agent_root_positions(src, agents, times), "Y")
    g1 = metrics.to_ground(evaluate.agent_root_positions(out, agents, times), "Y")
    deviation = _walking_deviation(g0, g1, FPS)
    assert deviation.max() < 90.0, agents[int(np.argmax(deviation))]
    ratio = np.array([metrics.length_ratio(b, a) for a, b in zip(g0, g1)])
    assert np.abs(ratio - 1.0).mean() < length_change[0] and np.abs(ratio - 1.0).max() < length_change[1]


def test_a_dense_crowd_of_1000_crossing_at_random_ends_apart_without_loops():
    """1,000 walkers x 240 frames at 0.25 per square metre in random directions (the
    benchmark's crowd): no overlap left, nobody turned more than 90 degrees off its way
    (0.25 s chords, compared at the same source frame), mean path length change < 2 %."""
    agents, frames = 1000, 240
    paths = examples.dense_crowd_paths(agents, frames)
    t = np.arange(frames, dtype=np.float64)
    problem = avoidance.Problem(names=[f"a{i}" for i in range(agents)], paths=paths, frame_times=[t] * agents,
                                radius=np.full(agents, 0.3), height=np.full(agents, 1.8), margin=0.05)
    outcome = avoidance.resolve(problem)
    assert outcome.iterations[0].collisions > 1000 and outcome.converged
    assert outcome.delays.max() > 0
    # No interval shrinks, none grows past the slowest pace, however many waits overlap.
    step = np.diff(np.stack(outcome.frame_times), axis=1)
    assert np.all(step >= 1.0 - 1e-9) and np.all(step <= 1.0 / avoidance.SLOWEST_PACE + 1e-9)
    h = 6
    c0 = np.stack([p[h:] - p[:-h] for p in paths])
    c1 = np.stack([p[h:] - p[:-h] for p in outcome.paths])
    cos = np.sum(c0 * c1, axis=2) / np.maximum(np.linalg.norm(c0, axis=2) * np.linalg.norm(c1, axis=2), 1e-12)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 90.0
    ratio = np.array([metrics.length_ratio(b, a) for a, b in zip(paths, outcome.paths)])
    assert np.abs(ratio - 1.0).mean() < 0.02


def test_a_crowd_swept_in_two_halves_ends_apart_as_the_rows_in_time_order_do(budget):
    """A crowd big enough for the separation solve to sweep its two halves on two threads
    (``split_from_frames`` 0 here; by default from 1,000,000 frames) ends apart, without loops, in about as many iterations as with
    every row swept in time order on one thread; the split order is another one (other forces,
    within the tolerance), and the same on one thread as on two."""
    agents, frames = 160, 240
    paths = examples.dense_crowd_paths(agents, frames, seed=3)
    t = np.arange(frames, dtype=np.float64)
    problem = avoidance.Problem(names=[f"a{i}" for i in range(agents)], paths=paths, frame_times=[t] * agents,
                                radius=np.full(agents, 0.3), height=np.full(agents, 1.8), margin=0.05)
    budget(2)
    split = avoidance.resolve(problem, avoidance.Settings(split_from_frames=0))
    ordered = avoidance.resolve(problem, avoidance.Settings(split_from_frames=None))
    assert all(np.array_equal(a, b) for a, b in zip(ordered.paths, avoidance.resolve(problem).paths)), \
        "a crowd this small is swept in time order by default"
    budget(1)
    alone = avoidance.resolve(problem, avoidance.Settings(split_from_frames=0))
    assert split.iterations[0].collisions > 50
    # Enough agents move for the solve to take two threads (20,000 frames of moved agents).
    assert int(split.moved.sum()) * frames >= 20000
    for out in (split, ordered):
        assert out.converged and not out.kept_direction
        ratio = np.array([metrics.length_ratio(b, a) for a, b in zip(paths, out.paths)])
        assert np.abs(ratio - 1.0).mean() < 0.02
    assert abs(len(split.iterations) - len(ordered.iterations)) <= 1
    assert any(not np.array_equal(a, b) for a, b in zip(split.paths, ordered.paths))
    assert all(np.array_equal(a, b) for a, b in zip(split.paths, alone.paths))


def test_the_walking_direction_guard_holds_chords_about_to_break_not_only_broken_ones():
    """The guard that keeps walkers going their way (0.25 s chords keep half their source
    length along the source's way) holds a chord from the iterate it comes within a quarter of
    its length of breaking: held before it breaks, it does not break in the next solve, and no
    iteration is spent on it alone. A chord well clear of breaking is left free."""
    fps, frames = 24.0, 48
    path = np.stack([np.linspace(0.0, 1.4 * (frames - 1) / fps, frames), np.zeros(frames)], axis=1)
    problem = avoidance.Problem(names=["a"], paths=[path], frame_times=[np.arange(frames, dtype=np.float64)],
                                radius=np.array([0.3]), height=np.array([1.8]))
    settings = avoidance.Settings(time_codes_per_second=fps)
    state = avoidance._State(problem, settings)
    guard = avoidance._Forward(state, settings.forward_keep, cone_degrees=settings.forward_cone_degrees,
                               watch=settings.forward_watch)
    h = int(guard.u[0] - guard.v[0])
    assert h == 6 and guard.watch(path) == 0 and not guard.on.any()
    # Frames 10..16 squeezed: their chord keeps 0.6 of its length (unbroken, within the watch);
    # frames 30..36 keep 0.9 (clear of it).
    squeezed = path.copy()
    squeezed[16:, 0] -= 0.4 * (path[16, 0] - path[10, 0])
    squeezed[36:, 0] -= 0.1 * (path[36, 0] - path[30, 0])
    assert guard.watch(squeezed) == 0
    held = {int(v) for v in guard.v[guard.on.any(axis=1)]}
    assert 10 in held and 30 not in held
    # A chord not held yet that breaks (it keeps 0.3) counts, so the iterations go on.
    squeezed[36:, 0] -= 0.6 * (path[36, 0] - path[30, 0])
    assert guard.watch(squeezed) > 0


def test_the_walking_direction_guard_of_a_big_crowd_holds_little_per_chord_and_watches_in_blocks():
    """A crowd of 10,000 walkers of 240 frames has millions of 0.25 s chords: the guard keeps
    each chord's ends, direction and length and which of its rows are held (at most 40 bytes a
    chord; three rows a chord held as arrays took 257 bytes, 600 MB for that crowd), and it
    finds the same rows to hold whether it measures the chords in blocks or all at once."""
    fps, frames, agents = 24.0, 60, 40
    rng = np.random.default_rng(3)
    paths, times = [], []
    for i in range(agents):
        heading = rng.uniform(0.0, 2.0 * np.pi)
        s = np.linspace(0.0, 1.4 * (frames - 1) / fps, frames)
        paths.append(np.stack([s * np.cos(heading), s * np.sin(heading)], axis=1) + rng.uniform(-5, 5, 2))
        times.append(np.arange(frames, dtype=np.float64))
    problem = avoidance.Problem(names=[f"a{i}" for i in range(agents)], paths=paths, frame_times=times,
                                radius=np.full(agents, 0.3), height=np.full(agents, 1.8))
    settings = avoidance.Settings(time_codes_per_second=fps)
    state = avoidance._State(problem, settings)

    def guard(block):
        g = avoidance._Forward(state, settings.forward_keep, cone_degrees=settings.forward_cone_degrees,
                               watch=settings.forward_watch)
        g.BLOCK = block
        return g

    whole, blocks = guard(1 << 20), guard(7)
    chords = len(whole.v)
    assert chords == agents * (frames - 6)
    held = sum(v.nbytes for v in vars(whole).values() if isinstance(v, np.ndarray))
    assert held <= 40 * chords
    # Every walker squeezed and turned in places: some chords break, some come near, some not.
    bent = np.concatenate(paths).copy()
    bent[:, 0] += 0.3 * np.sin(np.arange(len(bent)) * 0.7)
    bent[:, 1] -= 0.2 * np.cos(np.arange(len(bent)) * 1.3)
    assert whole.watch(bent) == blocks.watch(bent) > 0
    np.testing.assert_array_equal(whole.on, blocks.on)
    assert 0 < np.count_nonzero(whole.on) < whole.on.size
    # The held rows carry their forces from solve to solve.
    rows = avoidance._Rows()
    sent = whole.add(rows)
    assert len(sent) == np.count_nonzero(whole.on)
    whole.solved(np.arange(len(sent), dtype=np.float64), -np.arange(len(sent), dtype=np.float64))
    bent[:, 1] += 0.5 * np.sin(np.arange(len(bent)) * 0.3)
    whole.watch(bent)
    again = avoidance._Rows()
    whole.add(again)
    assert again.count == np.count_nonzero(whole.on) > len(sent)
    # A row held before starts from its force (here its index in the first solve), a new one from 0.
    before = {(int(u), int(v), float(n)): i for i, (u, v, n) in enumerate(zip(
        np.concatenate(rows.term_vertex)[0::2], np.concatenate(rows.term_vertex)[1::2],
        np.concatenate(rows.direction)[:, 0]))}
    keys = zip(np.concatenate(again.term_vertex)[0::2], np.concatenate(again.term_vertex)[1::2],
               np.concatenate(again.direction)[:, 0])
    expected = [float(before.get((int(u), int(v), float(n)), 0)) for u, v, n in keys]
    np.testing.assert_array_equal(np.concatenate(again.force), expected)
    np.testing.assert_array_equal(np.concatenate(again.force1), -np.array(expected))


def _winding_degrees(walker: np.ndarray, other: np.ndarray) -> float:
    """Degrees the line from ``other`` to ``walker`` sweeps round ``other`` over the paths
    (T, 2): about 360 for a walker that goes once round the other in a loop."""
    d = walker - other
    return float(np.degrees(np.abs(np.sum(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))))))


def _out_and_back(x: float, pause: float, fps: float = 24.0) -> np.ndarray:
    """(T, 2) a walk north at 1.4 m/s from (x, -3) to (x, 0), a pause of ``pause`` seconds,
    and the same way back."""
    there = np.linspace(-3.0, 0.0, int(round(3.0 / 1.4 * fps)) + 1)
    y = np.concatenate([there, np.full(int(round(pause * fps)), 0.0), there[::-1]])
    return np.stack([np.full(len(y), x), y], axis=1)


@pytest.mark.parametrize("x,pause", [(0.05, 0.25), (0.0, 0.5), (-0.03, 0.5)])
def test_a_walker_who_walks_up_to_a_stander_and_back_stays_on_one_side(x, pause):
    """A walker who walks up to where someone stands, pauses and walks back (a take that
    wanders and returns) goes up and back on the same side of the stander. Voted along their
    relative motion, the side flipped with it: pushed one way going up and the other coming
    back, the walker went once round the stander (320 degrees, path 12 to 16 % longer; CMU
    crowds: paths up to 1.75 times their length)."""
    walk = _out_and_back(x, pause)
    frames = len(walk)
    stand = np.zeros((frames, 2))
    t = np.arange(frames, dtype=np.float64)
    problem = avoidance.Problem(names=["stander", "walker"], paths=[stand, walk], frame_times=[t, t],
                                radius=np.full(2, 0.3), height=np.full(2, 1.8), margin=0.05)
    outcome = avoidance.resolve(problem, avoidance.Settings(max_wait_s=0.0))
    assert outcome.converged and not outcome.kept_direction
    stand1, walk1 = outcome.paths
    assert _winding_degrees(walk1, stand1) < 90.0
    assert metrics.length_ratio(walk1, walk) < 1.05


@pytest.mark.parametrize("sway,turns", [(0.02, 0.5), (0.04, 1.0)])
def test_a_walker_who_turns_back_where_another_stopped_stays_on_one_side(sway, turns):
    """One walks in and stops (its clip ends there: the rest of the shot holds that pose); the
    other walks up to that very spot, sways round a few centimetres as it turns back, and
    walks away. Where they barely move against each other the line between them is a few
    centimetres long and points anywhere: pushed along it, the turning samples were spread
    round the stopped one, and the walker went round it (229 and 323 degrees, path 15 and 19 %
    longer; on a CMU crowd 500 degrees and 57 %)."""
    t = np.arange(200, dtype=np.float64)
    keys = [(0, (0, -1.2)), (20, (0, -1.2)), (60, (0, 0)), (80, (0, 0)), (120, (0, -1.0)), (160, (1.5, -1.1)),
            (200, (2.0, -1.1))]
    walk = np.stack([np.interp(t, [k for k, _ in keys], [p[c] for _, p in keys]) for c in (0, 1)], axis=1)
    turning = (t >= 60) & (t <= 80)
    phase = 2.0 * np.pi * turns * (t[turning] - 60) / 20.0
    walk[turning] += sway * np.stack([np.sin(phase), 1.0 - np.cos(phase)], axis=1)
    t_stop = np.arange(41, dtype=np.float64)
    stop = np.stack([np.linspace(-3.0, 0.0, 41), np.zeros(41)], axis=1)
    problem = avoidance.Problem(names=["walker", "stopper"], paths=[walk, stop], frame_times=[t, t_stop],
                                radius=np.full(2, 0.3), height=np.full(2, 1.8), margin=0.05, span=(0.0, 199.0))
    outcome = avoidance.resolve(problem, avoidance.Settings(max_wait_s=0.0))
    assert outcome.converged
    walk1, stop1 = outcome.paths
    assert _winding_degrees(walk1, stop1[-1]) < 90.0
    assert metrics.length_ratio(walk1, walk) < 1.05


def test_walkers_side_by_side_who_drift_back_and_forth_are_pushed_apart_one_way():
    """Two walkers side by side, 0.4 m apart (closer than their clearance), one drifting a
    little ahead and back: each is pushed away from the other on its own side all along,
    not left and right in turn as their relative motion turns forward and back."""
    fps, frames = 24.0, 96
    t = np.arange(frames, dtype=np.float64)
    y = 1.4 * t / fps
    left = np.stack([np.full(frames, -0.2), y], axis=1)
    right = np.stack([np.full(frames, 0.2), y + 0.3 * np.sin(2.0 * np.pi * t / 48.0)], axis=1)
    problem = avoidance.Problem(names=["left", "right"], paths=[left, right], frame_times=[t, t],
                                radius=np.full(2, 0.3), height=np.full(2, 1.8), margin=0.05)
    outcome = avoidance.resolve(problem, avoidance.Settings(max_wait_s=0.0))
    assert outcome.converged
    left1, right1 = outcome.paths
    assert np.all(right1[:, 0] - left1[:, 0] > 0.5)
    # Each keeps its line: nobody is thrown across the other and back.
    assert np.all(left1[:, 0] < -0.2 + 1e-6) and np.all(right1[:, 0] > 0.2 - 1e-6)


# ---- waiting -----------------------------------------------------------------------------------

def _crossing_pair(tmp_path, settings=None):
    """agent_0000 walks along +Z through the origin at frame 60; agent_0001 walks along +X
    and reaches it 0.3 m later."""
    walk = _walk()
    specs = [("agent_0000", walk, (0.0, 0.0, -3.5), 0.0, 0.0), ("agent_0001", walk, (-3.8, 0.0, 0.0), 90.0, 0.0)]
    _walker_stage(tmp_path / "s.usda", specs, settings=settings)
    return tmp_path / "s.usda"


def _foot_skate_ratio(src, out, agent):
    return measure.foot_skate(out, agent).mean / measure.foot_skate(src, agent).mean


def test_the_later_walker_waits_instead_of_stepping_aside(tmp_path):
    stage_path = _crossing_pair(tmp_path)
    src = Usd.Stage.Open(str(stage_path))
    agents = _agents(src)
    assert _separation(src, agents)[0] < -0.3
    result, out = _solve(tmp_path, stage_path)
    stats = result.report.stats
    assert stats["delayedAgents"] == 1 and 0.2 < stats["largestDelay"] <= 3.0
    assert stats["remainingOverlaps"] == 0 and _separation(out, agents, margin=0.05)[0] >= -1e-4
    waiter = result.report.agents["/World/Crowd/agent_0001"]
    assert waiter["delay"] == stats["largestDelay"]
    assert "delay" not in result.report.agents.get("/World/Crowd/agent_0000", {})
    # Its path is the source's (a wait moves nobody sideways), played later: every ground
    # point it passes lies on the source path, and it reaches the end of it after the shot.
    times = np.arange(0.0, 120.0 + 24.0 * 3)
    for agent in agents:
        g0 = metrics.to_ground(evaluate.agent_root_positions(src, agent, times), "Y")
        g1 = metrics.to_ground(evaluate.agent_root_positions(out, agent, times), "Y")
        off_path = np.min(np.linalg.norm(g1[:, None] - g0[None], axis=2), axis=1)
        assert off_path.max() < 0.03, agent
        assert abs(metrics.length_ratio(g1, g0) - 1.0) < 1e-3, agent
    # Planted feet stay planted: the pose plays slower, it does not slide (what is left is
    # the pose interpolated between source frames: 1.10 measured).
    assert _foot_skate_ratio(src, out, "/World/Crowd/agent_0001") < 1.25


def test_without_waiting_the_walkers_step_aside(tmp_path):
    stage_path = _crossing_pair(tmp_path, settings={"maxWait": (Sdf.ValueTypeNames.Double, 0.0)})
    result, out = _solve(tmp_path, stage_path)
    stats = result.report.stats
    assert "delayedAgents" not in stats and stats["remainingOverlaps"] == 0
    assert max(a.get("maxDisplacement", 0.0) for a in result.report.agents.values()) > 0.1


def test_a_time_constraint_keeps_the_later_walker_from_waiting(tmp_path):
    stage_path = _crossing_pair(tmp_path)
    stage = Usd.Stage.Open(str(stage_path))
    examples.add_time_constraint(stage, "/World/Cue", "/World/Crowd/agent_0001", 0, 0.0)
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path, stage_path)
    assert "delay" not in result.report.agents["/World/Crowd/agent_0001"]
    assert result.report.stats["remainingOverlaps"] == 0


@pytest.mark.parametrize("pinned", [0, 24])
def test_a_walker_pinned_before_the_crossing_waits_after_its_pin(tmp_path, pinned):
    """The later walker must be where it was at an earlier frame (a hard position constraint):
    that frame still plays when it did if the walker slows down only after it, so the walker
    waits 0.5 s instead of stepping aside (when any pin kept it from waiting, it stepped aside
    0.19 m and the other walker 0.33 m). Its pin holds, at its frame's moment of the shot."""
    stage_path = _crossing_pair(tmp_path)
    stage = Usd.Stage.Open(str(stage_path))
    waiter = "/World/Crowd/agent_0001"
    held = evaluate.agent_root_positions(stage, waiter, [float(pinned)])[0]
    examples.add_position_constraint(stage, "/World/Mark", waiter, pinned, tuple(map(float, held)))
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path, stage_path)
    stats = result.report.stats
    assert stats["remainingOverlaps"] == 0
    assert result.report.agents[waiter]["delay"] > 0.2
    assert result.report.agents[waiter].get("maxDisplacement", 0.0) < 0.05
    assert all(c["residual"] < 1e-6 for c in result.report.constraints)
    # At the pinned frame's moment the walker is where the mark holds it, before the wait.
    on_ground = evaluate.agent_root_positions(out, waiter, [float(pinned)])[0]
    np.testing.assert_allclose(metrics.to_ground(on_ground, "Y"), metrics.to_ground(held, "Y"), atol=1e-6)


def test_a_walker_pinned_after_the_crossing_steps_aside_instead_of_waiting(tmp_path):
    """Pinned where it is after the crossing, the walker cannot wait (its pinned frame would
    play later): it steps aside."""
    stage_path = _crossing_pair(tmp_path)
    stage = Usd.Stage.Open(str(stage_path))
    waiter = "/World/Crowd/agent_0001"
    held = evaluate.agent_root_positions(stage, waiter, [96.0])[0]
    examples.add_position_constraint(stage, "/World/Mark", waiter, 96, tuple(map(float, held)))
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path, stage_path)
    assert result.report.stats["remainingOverlaps"] == 0
    assert "delay" not in result.report.agents[waiter]
    assert all(c["residual"] < 1e-6 for c in result.report.constraints)
    on_ground = evaluate.agent_root_positions(out, waiter, [96.0])[0]
    np.testing.assert_allclose(metrics.to_ground(on_ground, "Y"), metrics.to_ground(held, "Y"), atol=1e-6)


def _crossroads(tmp_path, marks=True, cues=True, settings=None, sync=False):
    stage_path = write_crossroads(tmp_path / "s.usda", marks=marks)
    stage = Usd.Stage.Open(str(stage_path))
    if sync:
        examples.add_sync_constraint(stage, "/World/Cues/cue0", "/World/Crowd/agent_0001", CROSSROADS_MEET,
                                     "/World/Crowd/agent_0000", CROSSROADS_MEET)
    for k in range(2 if cues and not sync else 0):
        examples.add_time_constraint(stage, f"/World/Cues/cue{k}", f"/World/Crowd/agent_000{k}",
                                     CROSSROADS_MEET, float(CROSSROADS_MEET))
    if settings:
        examples.define_mocap_prim(stage, "/World/Settings", "MocapSolveSettings", attributes=settings)
    stage.GetRootLayer().Save()
    return stage_path


@pytest.mark.parametrize("sync", [False, True], ids=["time", "sync"])
def test_time_constraints_that_leave_no_room_for_a_needed_delay_are_an_error_naming_them(tmp_path, sync):
    """Both walkers are timed to reach the crossroads at frame 60 (two time constraints, or
    one sync constraint) and held where they are half a second either side of it: one must
    wait, neither may, stepping aside cannot part them."""
    stage_path = _crossroads(tmp_path, sync=sync)
    with pytest.raises(MocapEditError) as err:
        _solve(tmp_path, stage_path)
    message = str(err.value)
    cues = ("/World/Cues/cue0",) if sync else ("/World/Cues/cue0", "/World/Cues/cue1")
    for name in ("/World/Crowd/agent_0000", "/World/Crowd/agent_0001", *cues):
        assert f"<{name}>" in message
    assert "frame 60" in message and "wait" in message and "soft" in message and "move a constraint's time" in message
    assert "steer" in message
    assert not (tmp_path / "s.edits.usda").exists()


def test_a_soft_time_constraint_gives_way_to_a_wait_and_says_so(tmp_path):
    """No marks: with hard cues the walkers slide along their lanes (below); with soft ones
    the later walker waits, and its cue's entry and a note give what the wait cost it."""
    stage_path = write_crossroads(tmp_path / "s.usda", marks=False)
    stage = Usd.Stage.Open(str(stage_path))
    for k in range(2):
        examples.add_time_constraint(stage, f"/World/Cues/cue{k}", f"/World/Crowd/agent_000{k}",
                                     CROSSROADS_MEET, float(CROSSROADS_MEET), strength="soft")
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, stage_path)
    stats = result.report.stats
    assert stats["delayedAgents"] == 1 and stats["remainingOverlaps"] == 0
    (waiter,) = [a for a, e in result.report.agents.items() if e.get("delay")]
    cue = f"/World/Cues/cue{waiter[-1]}"
    (entry,) = [c for c in result.report.constraints if c.get("prim") == cue]
    assert not entry["met"] and entry["residual"] == pytest.approx(result.report.agents[waiter]["delay"] * FPS, abs=0.5)
    (other,) = [c for c in result.report.constraints if c["kind"] == "time" and c["prim"] != cue]
    assert other["met"]
    notes = [n for n in result.report.notes if f"<{cue}> is soft" in n]
    assert len(notes) == 1 and waiter in notes[0]


@pytest.mark.parametrize("case", ["steering slides them apart", "no time constraint", "waiting off"])
def test_a_delay_the_constraints_refuse_is_no_error_when_nothing_needs_it(tmp_path, case):
    """Without the marks the walkers slide along their lanes; without the time constraints
    only position marks fix the timing (a note, as before); without waiting nobody wants a delay."""
    if case == "steering slides them apart":
        result, _ = _solve(tmp_path, _crossroads(tmp_path, marks=False))
        assert result.report.stats["remainingOverlaps"] == 0
        cues = [c for c in result.report.constraints if c["kind"] == "time"]
        assert len(cues) == 2 and all(c["met"] for c in cues)
    else:
        settings = {"maxWait": (Sdf.ValueTypeNames.Double, 0.0)} if case == "waiting off" else None
        result, _ = _solve(tmp_path, _crossroads(tmp_path, cues=case == "waiting off", settings=settings))
        assert result.report.stats["remainingOverlaps"] >= 1
        assert any("see the collision entries" in n for n in result.report.notes)


def test_a_wait_slows_the_pace_smoothly_and_never_reverses_time():
    t = np.arange(200.0)
    for delay in (6.0, 24.0, 72.0):
        end = 150.0
        start = end - max(1.5 * delay / (1.0 / avoidance.SLOWEST_PACE - 1.0), 24.0)
        warped = avoidance.smooth_delay(t, start, end, delay)
        step = np.diff(warped)
        assert np.all(step >= 1.0 - 1e-12) and np.all(1.0 / step >= avoidance.SLOWEST_PACE - 1e-9)
        np.testing.assert_allclose(warped[t <= start], t[t <= start])
        np.testing.assert_allclose(warped[t >= end], t[t >= end] + delay)
        assert np.abs(np.diff(step)).max() <= 6.0 * delay / (end - start) ** 2 + 1e-12   # a smoothstep: gentle


def test_a_negative_max_wait_is_an_error_naming_the_settings(tmp_path):
    stage_path = _crossing_pair(tmp_path, settings={"maxWait": (Sdf.ValueTypeNames.Double, -1.0)})
    with pytest.raises(MocapEditError, match=r"</World/Settings>\.maxWait"):
        solve(str(stage_path))


# ---- artist constraints, stationary tags, what cannot be separated ---------------------------

def test_stationary_range_moves_rigidly_and_pins_hold(tmp_path):
    """A walker standing still in the path of another is nudged as one piece."""
    stop_go, pause = walker.walk_idle_walk(frames=160, fps=FPS, speed=1.4, stop_frame=50, idle_frames=50,
                                           up="Y", meters_per_unit=1.0, name="stop_go_t")
    walk = _walk(frames=160)
    # agent_0001 crosses agent_0000's standing spot while it stands (frames 50..99).
    stand = stop_go.translations[75, 0].astype(np.float64)
    specs = [("agent_0000", stop_go, (0.0, 0.0, 0.0), 0.0, 0.0),
             ("agent_0001", walk, (stand[0] - 1.4 * 75 / FPS, 0.0, stand[2] + 0.1), 90.0, 0.0)]
    stage = _walker_stage(tmp_path / "s.usda", specs, stationary={"stop_go_t": {"pause": pause}})
    examples.add_position_constraint(stage, "/World/Marks/start", "/World/Crowd/agent_0000", 0, (0.0, 0.0, 0.0))
    first = walk.translations[0, 0].astype(np.float64)
    examples.add_position_constraint(stage, "/World/Marks/walker", "/World/Crowd/agent_0001", 10,
                                     (float(stand[0] - 1.4 * 75 / FPS + walk.translations[10, 0, 2]), 0.0,
                                      float(stand[2] + 0.1 - walk.translations[10, 0, 0])))
    stage.GetRootLayer().Save()
    del first
    result, out = _solve(tmp_path, tmp_path / "s.usda")
    assert result.report.stats["remainingOverlaps"] == 0
    src = Usd.Stage.Open(str(tmp_path / "s.usda"))
    frames = np.arange(160.0)
    a_src = metrics.to_ground(evaluate.agent_root_positions(src, "/World/Crowd/agent_0000", frames), "Y")
    a_out = metrics.to_ground(evaluate.agent_root_positions(out, "/World/Crowd/agent_0000", frames), "Y")
    assert metrics.rigidity_error(a_src, a_out, [pause])[0] < 1e-6
    for c in result.data.position_constraints:
        root = evaluate.agent_root_positions(out, c.agent, [float(c.frame)])[0]
        assert np.linalg.norm((root - c.position)[[0, 2]]) < 1e-6, c.path
    moved = np.abs(a_out - a_src).max() + np.abs(
        evaluate.agent_root_positions(out, "/World/Crowd/agent_0001", frames) -
        evaluate.agent_root_positions(src, "/World/Crowd/agent_0001", frames)).max()
    assert moved > 0.1


def test_agents_held_together_by_hard_constraints_are_named_not_looped(tmp_path):
    walk = _walk()
    specs = [("agent_0000", walk, (0.0, 0.0, -4.0), 0.0, 0.0), ("agent_0001", walk, (0.0, 0.0, 4.0), 180.0, 0.0)]
    stage = _walker_stage(tmp_path / "s.usda", specs)
    data = None
    from mocapedit.usd import reader
    data = reader.read_stage(stage)
    from mocapedit.geometry import trajectory
    traj = {a: trajectory.extract(data.agents[a], data.clip_of(data.agents[a]), "Y", 1.0) for a in data.agents}
    # Both are pinned where they are at the frame they meet: they cannot be separated then.
    g0, g1 = traj["/World/Crowd/agent_0000"].ground, traj["/World/Crowd/agent_0001"].ground
    k = int(np.argmin(np.linalg.norm(g0 - g1, axis=1)))
    for name, g in (("agent_0000", g0), ("agent_0001", g1)):
        examples.add_position_constraint(stage, f"/World/Marks/{name}", f"/World/Crowd/{name}", k,
                                         (float(g[k, 0]), 0.0, float(-g[k, 1])))
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, tmp_path / "s.usda")
    stats = result.report.stats
    assert stats["remainingOverlaps"] >= 1
    assert stats["collisionIterations"] < 10, "stops once only held pairs are left"
    notes = " ".join(result.report.notes)
    assert "/World/Crowd/agent_0000" in notes and "/World/Crowd/agent_0001" in notes and "cannot be separated" in notes
    held = [c for c in result.report.constraints if c["kind"] == "collision"]
    assert held and all(c["heldByConstraints"] for c in held)
    assert all(c["agent"] == "/World/Crowd/agent_0000" and c["target"] == "/World/Crowd/agent_0001" for c in held)


def test_a_pair_a_link_holds_closer_than_their_clearance_is_left_there_and_named_once(tmp_path):
    """A handshake: two walkers pass 0.56 m apart (capsules need 0.65) and a hard relative
    constraint holds them so. Avoidance leaves them there, says so once naming the
    constraint, and still clears a third walker who crosses one of them later."""
    walk = _walk(frames=140)
    specs = [("agent_0000", walk, (0.0, 0.0, -4.0), 0.0, 0.0), ("agent_0001", walk, (0.56, 0.0, 4.0), 180.0, 0.0),
             ("agent_0002", walk, (-3.3, 0.0, 3.9), 90.0, 40.0)]
    stage = _walker_stage(tmp_path / "s.usda", specs, frames=140)
    meet = 68
    a0 = evaluate.agent_root_positions(stage, "/World/Crowd/agent_0000", [float(meet)])[0]
    a1 = evaluate.agent_root_positions(stage, "/World/Crowd/agent_0001", [float(meet)])[0]
    examples.add_relative_constraint(stage, "/World/Handshake", "/World/Crowd/agent_0000", meet,
                                     "/World/Crowd/agent_0001", meet, tuple(float(v) for v in a0 - a1))
    stage.GetRootLayer().Save()
    src = Usd.Stage.Open(str(tmp_path / "s.usda"))
    agents = _agents(src)
    result, out = _solve(tmp_path, tmp_path / "s.usda")
    notes = [n for n in result.report.notes if "/World/Handshake" in n]
    assert len(notes) == 1 and "agent_0000" in notes[0] and "agent_0001" in notes[0]
    assert not any("cannot be separated" in n for n in result.report.notes)
    left = [c for c in result.report.constraints if c["kind"] == "collision"]
    assert left and all(c["heldByConstraints"] for c in left)
    assert {(c["agent"], c["target"]) for c in left} == {("/World/Crowd/agent_0000", "/World/Crowd/agent_0001")}
    # The third walker is cleared from both.
    times = _shot_times(src)
    roots = _ground_roots(out, agents, times)
    sep = metrics.min_separation(roots[[0, 2]], 0.3, 1.8, "Y")
    assert sep.clearance >= 0.05 - 1e-4
    sep = metrics.min_separation(roots[[1, 2]], 0.3, 1.8, "Y")
    assert sep.clearance >= 0.05 - 1e-4
    # The held pair is not pushed around the hold: the handshake stays where it was and
    # neither walker turns off its way.
    g0 = metrics.to_ground(evaluate.agent_root_positions(src, agents, times), "Y")
    g1 = metrics.to_ground(evaluate.agent_root_positions(out, agents, times), "Y")
    assert _walking_deviation(g0[:2], g1[:2], FPS).max() < 45.0
    k = int(np.searchsorted(times, meet))
    assert np.abs(g1[:2, k - 12:k + 13] - g0[:2, k - 12:k + 13]).max() < 0.05
    handshake = [c for c in result.report.constraints if c["prim"] == "/World/Handshake"]
    assert handshake and handshake[0]["met"]


def test_a_pair_that_walks_into_each_other_after_a_close_handshake_is_still_parted(tmp_path):
    """path_handshake with the handshake 0.52 m apart (capsules need 0.6): the two stand that
    close, then walk off through each other's spot (0.15 m apart at frame 142). The hold covers
    the standing only; the walk-off is parted (before, the hold ran on to the end of the shot
    and left a 0.45 m overlap there, marked as held by the handshake)."""
    _stage_module("stages_path").path_handshake(tmp_path)
    stage = Usd.Stage.Open(str(tmp_path / "path_handshake.usda"))
    stage.GetPrimAtPath("/Edits/handshake").GetAttribute("offset").Set(Gf.Vec3d(0.5, 0.0, 0.15))
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path, tmp_path / "path_handshake.usda", collisions=True)
    notes = [n for n in result.report.notes if "/Edits/handshake" in n]
    assert len(notes) == 1 and "not pushed apart" in notes[0]
    held = float(notes[0].split(" to ")[1].split(";")[0])
    assert held < 140.0
    left = [c for c in result.report.constraints if c["kind"] == "collision"]
    assert all(c["heldByConstraints"] and c["time"] <= held for c in left)
    assert all(c["met"] for c in result.report.constraints if c.get("prim") == "/Edits/handshake")
    agents = ["/World/Crowd/host", "/World/Crowd/guest"]
    times = np.arange(held + 1.0, 150.0)
    sep = metrics.min_separation(_ground_roots(out, agents, times), 0.3, 1.8, "Y")
    assert sep.clearance >= -1e-3
    # Parted by stepping aside as they walk off, not by walking sideways: where the source
    # starts to walk, the push must not turn a chord more than 90 degrees off the source's way
    # (a projection on the way alone let a big lateral push count as progress: 94 degrees).
    source = Usd.Stage.Open(str(tmp_path / "path_handshake.usda"))
    for agent in agents:
        assert measure.plausibility(source, out, agent).max_direction_deviation < 90.0, agent


def test_collide_false_agents_are_neither_moved_nor_obstacles(tmp_path):
    STAGES.head_on(tmp_path)
    stage = Usd.Stage.Open(str(tmp_path / "collisions_head_on.usda"))
    stage.GetPrimAtPath("/World/Crowd/agent_0001").CreateAttribute(
        "mocap:collide", Sdf.ValueTypeNames.Bool, False, Sdf.VariabilityUniform).Set(False)
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, tmp_path / "collisions_head_on.usda")
    assert result.report.stats["editedAgents"] == 0
    assert "remainingOverlaps" not in result.report.stats or result.report.stats["remainingOverlaps"] == 0


# ---- strategies, switches, progress, report, guides ------------------------------------------

def test_both_strategies_run_and_relinearize_does_better(tmp_path):
    STAGES.crossing(tmp_path)
    stage_path = tmp_path / "collisions_crossing.usda"
    figures = {}
    for strategy in ("relinearize", "accumulate"):
        result, _ = _solve(tmp_path, stage_path, collision_strategy=strategy, guides=False)
        stats = result.report.stats
        assert stats["collisionStrategy"] == strategy
        per = stats["collisionsPerIteration"]
        assert per[-1] < per[0] / 4, strategy
        moved = [a for a in result.report.agents.values() if a.get("edited")]
        figures[strategy] = (per, np.mean([a["meanDisplacement"] for a in moved if "meanDisplacement" in a]))
    # The deliverable's scheme re-solves from its last result and needs more iterations.
    assert figures["relinearize"][0][-1] == 0
    assert len(figures["relinearize"][0]) < len(figures["accumulate"][0]) or figures["accumulate"][0][-1] > 0


def test_switches_and_progress(tmp_path):
    STAGES.head_on(tmp_path)
    stage = tmp_path / "collisions_head_on.usda"
    off, _ = _solve(tmp_path, stage, collisions=False)
    assert off.report.stats["editedAgents"] == 0 and "collisionIterations" not in off.report.stats
    layer = Sdf.Layer.FindOrOpen(str(stage))
    layer.GetPrimAtPath("/World/MocapSettings").attributes["collisionAvoidance"].default = False
    layer.Save()
    assert _solve(tmp_path, stage)[0].report.stats["editedAgents"] == 0
    stream = io.StringIO()
    on = solve(str(stage), collisions=True, progress=Progress(stream=stream, interval=0.0))
    assert on.report.stats["remainingOverlaps"] == 0
    text = stream.getvalue()
    assert "collision avoidance" in text and "collision intervals left" in text
    # The command line flag does the same.
    proc = run_cli("solve", stage, "-o", tmp_path / "cli.usda", "--collisions", "--report", tmp_path / "r.json")
    assert proc.returncode == 0, proc.stderr
    assert "collision intervals left" in proc.stderr


def test_progress_notes_summary_and_report_give_the_same_figures(tmp_path):
    STAGES.crossing(tmp_path)
    stream = io.StringIO()
    edits = tmp_path / "e.usda"
    result = solve(str(tmp_path / "collisions_crossing.usda"), output=str(edits), collisions=True,
                   progress=Progress(stream=stream, interval=0.0), max_iterations=1)
    stats = result.report.stats
    assert stats["collisionIterations"] == 1 and stats["remainingOverlaps"] > 0
    left = report.describe_left(stats["remainingOverlaps"], stats["regionFramesLeft"])
    # Progress stops at the iteration it reached (not the maxIterations it was given).
    assert "collision avoidance: 1 iteration in" in stream.getvalue()
    assert f", {left}\n" in stream.getvalue()
    assert any(left + " after 1 iteration" in n for n in result.report.notes)
    summary = result.report.summary()
    shared = report.overview(stats, result.report.constraints)
    assert f"collision avoidance: {left} after 1 iteration" in shared
    text = report.format_text(read_report(str(edits)))
    for line in shared:
        assert line in summary.splitlines() and line in text.splitlines()
    # The worst residual printed is that of the hard constraints, never a soft collision row.
    hard = [c["residual"] for c in result.report.constraints if c.get("hard") and c.get("kind") != "collision"]
    assert f"worst hard residual {report._num(max(hard))}" in summary
    assert "worst constraint residual" not in summary


def test_detection_only_reports_overlaps_pairs_times_and_guides(tmp_path):
    STAGES.head_on(tmp_path)
    result, out = _solve(tmp_path, tmp_path / "collisions_head_on.usda", max_iterations=0)
    stats = result.report.stats
    assert stats["collisionIterations"] == 0 and stats["remainingOverlaps"] == 1
    assert stats["minSeparation"] < 0
    (entry,) = [c for c in result.report.constraints if c["kind"] == "collision"]
    assert (entry["agent"], entry["target"]) == ("/World/Crowd/agent_0000", "/World/Crowd/agent_0001")
    assert 60 <= entry["time"] <= 76 and not entry["met"] and entry["residual"] > 0.5
    points = out.GetPrimAtPath("/MocapEdit/Guides/Collisions").GetAttribute("points").Get()
    assert len(points) == 1
    np.testing.assert_allclose(np.array(points[0])[[0, 2]], np.array(entry["position"])[[0, 2]], atol=1e-5)
    assert result.report.agents["/World/Crowd/agent_0000"]["minSeparation"] < 0


def test_detection_samples_after_the_time_warp(tmp_path):
    """A time constraint that delays one walker moves the meeting point: sampling follows it."""
    STAGES.head_on(tmp_path)
    stage_path = tmp_path / "collisions_head_on.usda"
    stage = Usd.Stage.Open(str(stage_path))
    vt = Sdf.ValueTypeNames
    examples.define_mocap_prim(stage, "/World/Later", "MocapTimeConstraint", attributes={
        "frame": (vt.Int, 0), "time": (vt.Double, 30.0)}, relationships={"agent": ["/World/Crowd/agent_0001"]})
    examples.define_mocap_prim(stage, "/World/Later2", "MocapTimeConstraint", attributes={
        "frame": (vt.Int, 119), "time": (vt.Double, 149.0)}, relationships={"agent": ["/World/Crowd/agent_0001"]})
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, stage_path, max_iterations=0)
    (entry,) = [c for c in result.report.constraints if c["kind"] == "collision"]
    # Unwarped they meet at frame 68 of both; agent_0001 now starts 30 later, so they meet
    # 15 frames later in shot time, agent_0001 at an earlier frame of its clip.
    assert 80 <= entry["time"] <= 86
    assert entry["targetFrame"] < entry["frame"] - 20


# ---- bad input -------------------------------------------------------------------------------

@pytest.mark.parametrize("radius,match", [
    (0.0, "collision radius must be positive, got 0"),
    # A slip of the keyboard (1e6 for 0.3) must not push the crowd kilometres without a word.
    (1e6, r"collision radius 1e\+06 is more than 10 m"),
])
def test_a_radius_no_character_has_is_an_error_naming_the_agent(tmp_path, radius, match):
    STAGES.head_on(tmp_path)
    stage_path = tmp_path / "collisions_head_on.usda"
    stage = Usd.Stage.Open(str(stage_path))
    stage.GetPrimAtPath("/World/Crowd/agent_0001").CreateAttribute(
        "mocap:collisionRadius", Sdf.ValueTypeNames.Float, False, Sdf.VariabilityUniform).Set(radius)
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</World/Crowd/agent_0001>\.mocap:collisionRadius: " + match):
        solve(str(stage_path))
    out = tmp_path / "never.usda"
    proc = run_cli("solve", stage_path, "-o", out)
    assert proc.returncode == 1 and "agent_0001" in proc.stderr and not out.exists()
    assert "Traceback" not in proc.stderr


def _pin_in_fountain(tmp_path, strength="hard"):
    """The head-on pair with a fountain where they meet, and agent_0000 pinned in it."""
    STAGES.head_on(tmp_path)
    stage_path = tmp_path / "collisions_head_on.usda"
    stage = Usd.Stage.Open(str(stage_path))
    vt = Sdf.ValueTypeNames
    examples.define_mocap_prim(stage, "/World/Regions/fountain", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "circle"), "radius": (vt.Double, 1.0), "margin": (vt.Double, 0.1)})
    where = evaluate.agent_root_positions(stage, "/World/Crowd/agent_0000", [60.0])[0]
    examples.add_position_constraint(stage, "/World/Marks/in_fountain", "/World/Crowd/agent_0000", 60,
                                     (float(where[0]), 0.0, float(where[2])), strength=strength)
    stage.GetRootLayer().Save()
    return stage_path


def test_a_hard_pin_inside_an_avoid_region_is_an_error_naming_both(tmp_path):
    stage_path = _pin_in_fountain(tmp_path)
    with pytest.raises(MocapEditError, match="inside avoid region") as err:
        solve(str(stage_path), max_iterations=1000)
    assert "</World/Marks/in_fountain>" in str(err.value) and "</World/Regions/fountain>" in str(err.value)
    assert "agent_0000" in str(err.value)
    out = tmp_path / "never.usda"
    proc = run_cli("solve", stage_path, "-o", out)
    assert proc.returncode == 1 and "/World/Regions/fountain" in proc.stderr and not out.exists()
    assert "Traceback" not in proc.stderr


def test_a_soft_pin_inside_an_avoid_region_gives_way_to_it(tmp_path):
    stage_path = _pin_in_fountain(tmp_path, strength="soft")
    result, _ = _solve(tmp_path, stage_path)
    assert result.report.stats["regionFramesLeft"] == 0


def test_constraints_that_cannot_all_hold_stop_without_progress_not_at_max_iterations(tmp_path):
    """A corridor narrower than a walker: the walls' rows trade frames inside for frames
    inside; the iterations stop once they make no progress, and the report says so."""
    walk = _walk()
    specs = [("agent_0000", walk, (-7.0, 0.0, 0.0), 90.0, 0.0)]
    _walker_stage(tmp_path / "s.usda", specs)
    stage = Usd.Stage.Open(str(tmp_path / "s.usda"))
    vt = Sdf.ValueTypeNames
    for name, z in (("north", -0.75), ("south", 0.75)):
        prim = examples.define_mocap_prim(stage, f"/World/Regions/{name}", "MocapAvoidRegion", attributes={
            "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(40.0, 1.0, 1.0))})
        UsdGeom.Xformable(prim).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.5, z))
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, tmp_path / "s.usda", max_iterations=1000)
    stats = result.report.stats
    assert stats["regionFramesLeft"] > 0 and stats.get("collisionStalled") is True
    assert stats["collisionIterations"] < 30
    assert any("without progress" in n for n in result.report.notes)


@pytest.mark.parametrize("prop,value,match", [
    ("radius", 0.0, "radius must be positive"),
    ("radius", -2.0, "radius must be positive"),
    ("size", (1.0, 0.0, 1.0), "size must be positive"),
    ("margin", -0.1, "margin must not be negative"),
])
def test_a_degenerate_region_is_an_error_naming_it(tmp_path, prop, value, match):
    STAGES.head_on(tmp_path)
    stage_path = tmp_path / "collisions_head_on.usda"
    stage = Usd.Stage.Open(str(stage_path))
    vt = Sdf.ValueTypeNames
    attrs = {"shape": (vt.Token, "box" if prop == "size" else "circle")}
    attrs[prop] = (vt.Double3, Gf.Vec3d(*value)) if prop == "size" else (vt.Double, value)
    examples.define_mocap_prim(stage, "/World/Regions/bad", "MocapAvoidRegion", attributes=attrs)
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=match) as err:
        solve(str(stage_path))
    assert "</World/Regions/bad>" in str(err.value) and f".{prop}" in str(err.value)


def test_an_unknown_strategy_is_an_error(tmp_path):
    STAGES.head_on(tmp_path)
    with pytest.raises(MocapEditError, match="collisionStrategy"):
        solve(str(tmp_path / "collisions_head_on.usda"), collision_strategy="shove")


# ---- the numeric pieces ----------------------------------------------------------------------

def test_grid_detection_equals_all_pairs_and_sampling_interpolates():
    rng = np.random.default_rng(4)
    paths = {i: rng.uniform(0, 10, (1, 2)) + np.cumsum(rng.normal(0, 0.05, (60, 2)), axis=0) for i in range(80)}
    times = {i: np.arange(60.0) * (0.5 if i % 2 else 1.0) + i % 5 for i in range(80)}
    s = collisions.sample(list(range(80)), times, paths, 1.0)
    assert s.times[0] == 0.0 and s.times[-1] == pytest.approx(63.0)
    # Agent 1 plays twice as fast from time 1: at shot time 11 it is at frame 20.
    k = int(np.searchsorted(s.times, 11.0))
    np.testing.assert_allclose(s.positions[k, 1], paths[1][20], atol=1e-12)
    radius, height = rng.uniform(0.2, 0.4, 80), np.full(80, 1.8)
    grid = collisions.detect(s, radius, height, 0.05, report_distance=0.5)
    brute = collisions.detect(s, radius, height, 0.05, report_distance=0.5, brute_force=True)
    assert len(grid) == len(brute) > 5
    for name in ("agent_a", "agent_b", "first", "last", "deepest", "depth", "min_clearance"):
        np.testing.assert_array_equal(getattr(grid, name), getattr(brute, name))
    # Near misses gathered in the same pass are the collisions at the watch distance.
    watched = collisions.detect(s, radius, height, 0.05, report_distance=0.5, watch=0.3)
    wide = collisions.detect(s, radius, height, 0.3, report_distance=0.5, brute_force=True)
    assert len(watched.near) > len(watched) == len(grid)
    for name in ("agent_a", "agent_b", "first", "last", "deepest", "depth"):
        np.testing.assert_array_equal(getattr(watched, name), getattr(grid, name))
        np.testing.assert_array_equal(getattr(watched.near, name), getattr(wide, name))
    # Re-reading new paths through the precomputed gathers interpolates as sampling does.
    order = list(range(80))
    starts = np.concatenate([[0], np.cumsum([len(paths[i]) for i in order])])
    moved = {i: paths[i] + rng.normal(0, 0.1, paths[i].shape) for i in order}
    collisions.Resampler(s, starts)(np.concatenate([moved[i] for i in order]))
    np.testing.assert_allclose(s.positions, collisions.sample(order, times, moved, 1.0).positions, atol=1e-12)


def test_region_footprints_follow_the_transform(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "r.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    vt = Sdf.ValueTypeNames
    circle = examples.define_mocap_prim(stage, "/C", "MocapAvoidRegion", attributes={"radius": (vt.Double, 2.0)})
    xf = UsdGeom.Xformable(circle)
    xf.AddTranslateOp().Set(Gf.Vec3d(5, 1, 0))
    xf.AddScaleOp().Set(Gf.Vec3f(3, 3, 1))
    ellipse = examples.define_mocap_prim(stage, "/E", "MocapAvoidRegion", attributes={"radius": (vt.Double, 1.0)})
    UsdGeom.Xformable(ellipse).AddScaleOp().Set(Gf.Vec3f(2, 1, 1))
    box = examples.define_mocap_prim(stage, "/B", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(2, 4, 1))})
    UsdGeom.Xformable(box).AddRotateZOp().Set(90.0)
    from mocapedit.usd import reader
    data = reader.read_stage(stage)
    regions = {r.path: collisions.region_footprint(r, "Z") for r in data.avoid_regions}
    c = regions["/C"]
    assert c.is_circle and c.radius == pytest.approx(6.0) and np.allclose(c.center, (5, 1))
    e = regions["/E"]
    assert not e.is_circle
    d = collisions.signed_distance(e, np.array([[2.0, 0.0], [0.0, 1.0], [1.9, 0.0], [0.0, 1.1]]))
    assert d[0] == pytest.approx(0.0, abs=0.01) and d[1] == pytest.approx(0.0, abs=0.01)
    assert d[2] < 0 < d[3]
    b = regions["/B"]
    d = collisions.signed_distance(b, np.array([[2.0, 0.0], [0.0, 1.0], [2.1, 0.0], [0.0, 1.1]]))
    np.testing.assert_allclose(d[:2], 0.0, atol=1e-9)
    assert d[2] > 0 and d[3] > 0
    assert isinstance(c, _solver.GroundRegion)


def test_a_standing_agent_pushed_aside_does_not_spin(tmp_path):
    """A walker crosses the spot where another stands for 4 s with a jittering root (60 fps, Z-up,
    cm; no waiting, so the stander is pushed). The stander's body turns with the push, never by
    the tangent of its jitter: with the tangent rule it turned 28 degrees in one frame, 14 times.
    Its shape terms are framed by frames at least path_edit.MIN_BASELINE_M apart, as the path
    editor's: framed by its jittering neighbours, it turned 2.3 degrees in one frame beyond its
    source."""
    clip, (first, last) = _stage_module("stages_path").long_stand_clip()
    middle = (first + last) // 2
    spot = clip.translations[middle, 0].astype(np.float64)
    crosser = walker.walk(frames=600, fps=60.0, up="Z", meters_per_unit=0.01, name="crosser")
    turn = np.radians(90.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    there = rot @ crosser.translations[middle, 0, :2].astype(np.float64)
    place = (float(spot[0] - there[0] + 20.0), float(spot[1] - there[1]), 0.0)
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("stander", clip),
                                                                 examples.AgentSpec("crosser", crosser, place, 90.0)],
                                       up_axis="Z", meters_per_unit=0.01, fps=60.0, clips_dir=tmp_path / "clips")
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (Sdf.ValueTypeNames.Bool, True), "maxWait": (Sdf.ValueTypeNames.Double, 0.0)})
    stage.GetRootLayer().Save()
    result, out = _solve(tmp_path, tmp_path / "shot.usda", foot_locking=False)
    assert result.report.stats["remainingOverlaps"] == 0
    stander = "/World/Crowd/stander"
    assert result.report.agents[stander]["edited"]
    measured = measure.plausibility(Usd.Stage.Open(str(tmp_path / "shot.usda")), out, stander)
    assert measured.spin_frames == 0
    assert measured.max_extra_facing_rate < 1.0 * 60.0     # under 1 degree per frame at 60 fps


def test_an_agent_stepping_aside_sends_back_against_its_walk_keeps_its_path(monkeypatch):
    """Whatever the separation does, no agent leaves avoidance walking back against the path it
    came in with (a hook, a loop): it keeps that path, and the overlap it leaves is reported."""
    frames = 60
    t = np.arange(frames, dtype=np.float64)
    a = np.stack([np.linspace(0.0, 3.0, frames), np.zeros(frames)], axis=1)
    b = np.stack([np.linspace(3.0, 0.0, frames), np.full(frames, 0.2)], axis=1)   # head on, 20 cm apart
    problem = avoidance.Problem(names=["a", "b"], paths=[a, b], frame_times=[t, t],
                                radius=np.full(2, 0.3), height=np.full(2, 1.8), fixed_timing=np.ones(2, bool))
    hooked = a.copy()
    hooked[20:40] = a[20] - (a[20:40] - a[20])           # walks back for a third of a second, twice
    hooked[40:] = hooked[39] + (a[40:] - a[39])
    parted = b + (0.0, 1.0)

    def sideways(state, run):
        run.observe(np.concatenate([a, b]), 0)
        return np.concatenate([hooked, parted]), np.zeros(0)

    monkeypatch.setattr(avoidance, "_relinearize", sideways)
    out = avoidance.resolve(problem)
    assert out.kept_direction == [0]
    np.testing.assert_array_equal(out.paths[0], a)
    np.testing.assert_array_equal(out.paths[1], parted)
    assert len(out.remaining) == 0        # b stepped a metre aside: nothing left between them
    # Without the hook, the separation's paths stand.
    def aside(state, run):
        run.observe(np.concatenate([a, b]), 0)
        return np.concatenate([a + (0.0, -1.0), b]), np.zeros(0)

    monkeypatch.setattr(avoidance, "_relinearize", aside)
    out = avoidance.resolve(problem)
    assert out.kept_direction == [] and out.paths[0][0, 1] == -1.0


def test_agents_placed_inside_each_other_are_named_with_what_to_do(tmp_path):
    """Two walkers start 10 cm apart (capsules of 0.3 m): the report names the pair and says to
    place them apart. Walkers placed 2 m apart get no such note."""
    for gap, named in ((0.1, True), (2.0, False)):
        shot = tmp_path / f"gap_{gap:g}" / "shot.usda"
        shot.parent.mkdir()
        clip = _walk()
        _walker_stage(shot, [("a", clip, (0.0, 0.0, 0.0), 0.0, 0.0), ("b", clip, (gap, 0.0, 0.0), 0.0, 0.0),
                             ("far", clip, (20.0, 0.0, 0.0), 0.0, 0.0)])
        result, _ = _solve(shot.parent, shot, guides=False)
        notes = [n for n in result.report.notes if "already overlap" in n]
        if named:
            assert len(notes) == 1 and "1 agent pair already overlaps where the shot starts" in notes[0]
            assert "</World/Crowd/a> and </World/Crowd/b>" in notes[0] and "place them apart" in notes[0]
            assert "far" not in notes[0]
        else:
            assert notes == []


def test_avoidance_stopped_while_still_parting_says_to_raise_max_iterations(tmp_path):
    """The 128-walker crossing clears in 3 iterations; stopped after 2 with the count still
    falling, the note says to raise maxIterations on the settings prim."""
    STAGES.crossing(tmp_path)
    stage_path = tmp_path / "collisions_crossing.usda"
    stage = Usd.Stage.Open(str(stage_path))
    settings = next(p for p in stage.Traverse() if p.GetTypeName() == "MocapSolveSettings")
    settings.GetAttribute("maxIterations").Set(2)
    stage.GetRootLayer().Save()
    result, _ = _solve(tmp_path, stage_path, guides=False, foot_locking=False)
    its = result.report.stats["collisionsPerIteration"]
    assert len(its) == 3 and its[-1] > 0 and its[-1] < its[0]
    notes = [n for n in result.report.notes if "raise maxIterations" in n]
    assert len(notes) == 1 and f"<{settings.GetPath()}>" in notes[0]
    assert ", ".join(map(str, its)) in notes[0]


def test_overlaps_left_by_the_guard_against_walking_back_do_not_ask_for_more_iterations(tmp_path, monkeypatch):
    """The crossing clears in 3 iterations; when the guard against walking back then hands an
    agent its incoming path, the overlaps it leaves are not for more iterations to part."""
    STAGES.crossing(tmp_path)
    stage_path = tmp_path / "collisions_crossing.usda"

    def first_walks_back(state, flat):
        out = np.zeros(len(state.p.names), dtype=bool)
        out[0] = True
        return out

    monkeypatch.setattr(avoidance, "_walks_backward", first_walks_back)
    result, _ = _solve(tmp_path, stage_path, guides=False, foot_locking=False)
    its = result.report.stats["collisionsPerIteration"]
    assert len(its) >= 3 and its[-1] == 0 and result.report.stats["remainingOverlaps"] > 0
    assert not any("raise maxIterations" in n or "stopped at maxIterations" in n for n in result.report.notes)
    assert any("back against the way they walk" in n for n in result.report.notes)


def _crossing_sampled_at(fps: float):
    """(seconds, agent 0's edited and source paths) of two walkers passing head-on 10 cm apart
    at 1.25 m/s, their paths sampled ``fps`` times a second on a 24 fps shot, parted without
    waiting."""
    t = np.arange(int(8 * fps) + 1) / fps
    a = np.stack([-5.0 + 1.25 * t, np.zeros(len(t))], axis=1)
    b = np.stack([5.0 - 1.25 * t, np.full(len(t), 0.1)], axis=1)
    problem = avoidance.Problem(names=["a", "b"], paths=[a, b], frame_times=[t * 24.0, t * 24.0],
                                radius=np.array([0.3, 0.3]), height=np.array([1.8, 1.8]))
    out = avoidance.resolve(problem, avoidance.Settings(max_wait_s=0.0, time_codes_per_second=24.0, meters_per_unit=1.0))
    assert not len(out.remaining)
    return t, out.paths[0], a


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
def test_a_detour_lasts_as_many_seconds_at_any_frame_rate(fps):
    """The same crossing, its clips sampled at 24, 30, 60 or 120 fps, steps aside over the same
    seconds at the same speed. Weighted per frame as at 24 fps, the 60 and 120 fps walkers
    stepped aside at 0.54 and 0.87 m/s where the 24 fps one does at 0.23: CMU takes in a crowd
    swerved 30 cm in a quarter of a second, and their feet slid."""
    t24, e24, s24 = _crossing_sampled_at(24.0)
    t, edited, source = _crossing_sampled_at(fps)
    aside = edited[:, 1] - source[:, 1]
    aside24 = np.interp(t, t24, e24[:, 1] - s24[:, 1])
    assert np.abs(aside - aside24).max() < 0.01, np.abs(aside - aside24).max()      # metres
    speed = np.abs(np.diff(aside)).max() * fps
    speed24 = np.abs(np.diff(e24[:, 1] - s24[:, 1])).max() * 24.0
    assert speed < 1.05 * speed24, (speed, speed24)


def test_a_pose_held_after_its_clip_ends_is_anchored_for_as_long_as_it_stands():
    """A walker's clip ends after 2 s and it holds its last pose for 6 s; another walks through
    that spot 10 cm aside at 5 s. The one who walks steps round the one who stands. Anchored as
    one frame, the held pose took the push: it slid 0.37 m (and turned the steps before it)
    while the walker kept to 0.16 m of its way."""
    fps = 24.0
    ta = np.arange(0, 2 * fps + 1)
    a = np.stack([ta / fps * 1.25, np.zeros(len(ta))], axis=1)
    tb = np.arange(0, 8 * fps + 1)
    b = np.stack([np.full(len(tb), 2.6), (tb / fps - 5.0) * 1.25], axis=1)
    problem = avoidance.Problem(names=["a", "b"], paths=[a, b], frame_times=[ta, tb], radius=np.array([0.3, 0.3]),
                                height=np.array([1.8, 1.8]), span=(0.0, 8 * fps))
    out = avoidance.resolve(problem, avoidance.Settings(max_wait_s=0.0, time_codes_per_second=fps, meters_per_unit=1.0))
    assert not len(out.remaining)
    held = np.linalg.norm(out.paths[0][-1] - a[-1])
    detour = np.linalg.norm(out.paths[1] - b, axis=1).max()
    assert held < 0.15 and detour > 0.4, (held, detour)


def _head_on_stage_detour(tmp_path, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(seconds, sideways move in metres) of a generated walker passing another head-on, 10 cm
    aside, on a stage whose clips and time codes run at ``fps``, by UsdSkel FK on the composed
    stage."""
    folder = tmp_path / f"fps{int(fps)}"
    folder.mkdir()
    frames = int(6 * fps) + 1
    walk = walker.walk(frames=frames, fps=fps, speed=1.25, up="Y", meters_per_unit=1.0, name="walk_x")
    specs = [examples.AgentSpec("agent_0000", walk, (-3.75, 0.0, 0.0), 90.0),
             examples.AgentSpec("agent_0001", walk, (3.75, 0.0, 0.1), -90.0)]
    stage = examples.build_crowd_stage(folder / "shot.usda", specs, up_axis="Y", meters_per_unit=1.0, fps=fps,
                                       clips_dir=folder / "clips")
    examples.define_mocap_prim(stage, "/World/Settings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (Sdf.ValueTypeNames.Bool, True), "maxWait": (Sdf.ValueTypeNames.Double, 0.0)})
    stage.GetRootLayer().Save()
    solve(str(folder / "shot.usda"), output=str(folder / "e.usda"), composed=str(folder / "c.usda"), foot_locking=False)
    times = np.arange(frames, dtype=np.float64)
    agent = "/World/Crowd/agent_0000"
    before = evaluate.agent_root_positions(Usd.Stage.Open(str(folder / "shot.usda")), agent, times)
    after = evaluate.agent_root_positions(Usd.Stage.Open(str(folder / "c.usda")), agent, times)
    return times / fps, after[:, 2] - before[:, 2]


def test_a_stage_at_60_fps_steps_aside_as_one_at_24_does(tmp_path):
    """The same two generated walkers passing head-on, on a 24 and on a 60 fps stage: the one
    steps aside over the same seconds, as fast (FK on the composed stages). The 60 fps one
    used to step aside within half the time, at 0.52 m/s against 0.24, 15 cm off the other's
    path over time."""
    t24, aside24 = _head_on_stage_detour(tmp_path, 24.0)
    t60, aside60 = _head_on_stage_detour(tmp_path, 60.0)
    assert np.abs(aside24).max() > 0.2
    assert np.abs(np.interp(t60, t24, aside24) - aside60).max() < 0.04, np.abs(np.interp(t60, t24, aside24) - aside60).max()
    speed24 = np.abs(np.diff(aside24)).max() * 24.0
    speed60 = np.abs(np.diff(aside60)).max() * 60.0
    assert speed60 < 1.15 * speed24, (speed60, speed24)
