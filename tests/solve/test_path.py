"""Path edits end to end: position constraints, stationary tags, path curves, the editor.

Quality is measured on the composed stage (edits over input) with UsdSkel forward
kinematics, not on the solver's arrays.
"""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from mocapedit.geometry import curves, ground
from mocapedit.data import examples, walker
from mocapedit.inspect import metrics
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.passes import path
from mocapedit.solve import path_edit
from mocapedit.solve.path_editor import PathEditor
from mocapedit.tools import measure
from mocapedit.pipeline.processor import solve
from mocapedit.usd import reader

from conftest import run_cli, world_joints, write_toy_stage

CROWD = "/World/Crowd"
FPS = 24.0


@pytest.fixture(scope="module")
def walk_clip():
    return walker.walk(frames=193, fps=FPS, speed=1.25, name="ten_metres")   # 10 m along +Z


@pytest.fixture(scope="module")
def stop_clip():
    return walker.walk_idle_walk(frames=150, fps=FPS, stop_frame=60, idle_frames=36, name="stop_go")


def _stage(tmp_path, agents, **kw):
    return examples.build_crowd_stage(tmp_path / "shot.usda", agents, up_axis="Y", fps=FPS,
                                      clips_dir=tmp_path / "clips", **kw)


def _standing_agent(tmp_path, stop_clip):
    """A stage with one agent "a" playing `stop_clip`, its stand tagged stationary."""
    clip, (first, last) = stop_clip
    stage = _stage(tmp_path, [examples.AgentSpec("a", clip)], stationary={clip.name: {"stand": (first, last)}})
    return stage, f"{CROWD}/a", clip, (first, last)


def _solve(tmp_path, stage, **kw):
    """Solves the stage's saved root layer; returns (result, input stage, composed stage).
    Each call writes new files: layers stay cached while stages that use them are alive."""
    stage.GetRootLayer().Save()
    src = stage.GetRootLayer().realPath
    n = len(list(tmp_path.glob("out*.edits.usda")))
    edits, composed = tmp_path / f"out{n}.edits.usda", tmp_path / f"out{n}.edited.usda"
    result = solve(src, output=str(edits), composed=str(composed), **kw)
    return result, Usd.Stage.Open(src), Usd.Stage.Open(str(composed))


def _root_ground(stage, agent, frames, up="Y"):
    return ground.to_ground(world_joints(stage, f"{agent}/Skel", frames)[:, 0], up)


def _to_polyline(points, poly):
    """Distance of each point to a polyline (its segments, not only its vertices)."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    t = np.clip(np.einsum("pkc,kc->pk", points[:, None] - a, d) / np.einsum("kc,kc->k", d, d), 0, 1)
    return np.linalg.norm(points[:, None] - (a + t[..., None] * d), axis=2).min(axis=1)


def _entry(result, prim):
    return next(c for c in result.report.constraints if c["prim"] == prim)


def test_hard_constraints_hold_on_the_composed_stage(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip), examples.AgentSpec("b", walk_clip, (2, 0, 0))])
    a = f"{CROWD}/a"
    targets = {0: (0.0, 0.0, 0.0), 70: (0.6, 0.0, 3.4), 140: (-0.4, 0.0, 7.5), 192: (0.3, 0.0, 10.2)}
    for f, p in targets.items():
        examples.add_position_constraint(stage, f"/Edits/c{f}", a, f, p)
    # The path edit alone: foot locking, which then bends the legs, is tested in test_feet.py.
    result, src, out = _solve(tmp_path, stage, foot_locking=False)
    frames = np.arange(193)
    before, after = world_joints(src, f"{a}/Skel", frames), world_joints(out, f"{a}/Skel", frames)
    for f, p in targets.items():
        np.testing.assert_allclose(after[f, 0, [0, 2]], np.array(p)[[0, 2]], atol=1e-6)
        assert _entry(result, f"/Edits/c{f}")["residual"] < 1e-6 and _entry(result, f"/Edits/c{f}")["met"]
    # Only the ground motion and yaw change: heights keep their source values and each
    # frame's pose moves rigidly (joint-to-joint distances are kept).
    np.testing.assert_allclose(after[..., 1], before[..., 1], atol=1e-6)
    d0 = np.linalg.norm(before[:, :, None] - before[:, None], axis=-1)
    d1 = np.linalg.norm(after[:, :, None] - after[:, None], axis=-1)
    np.testing.assert_allclose(d1, d0, atol=1e-5)
    # The agent nobody constrained is not written.
    assert not result.layer.GetPrimAtPath(f"{CROWD}/b")
    agent = result.report.agents[a]
    assert agent["solver"] == "LDLT" and 0.9 < agent["lengthRatio"] < 1.1


def test_a_rigid_edit_gives_exactly_that_rigid_motion(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    a = f"{CROWD}/a"
    angle, shift = np.radians(35.0), np.array([2.0, 0.0, -1.0])
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])   # row vectors, about +Y
    src_stage = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    root = world_joints(src_stage, f"{a}/Skel", [0, 120, 192])[:, 0]
    for f, p in zip((0, 120, 192), root @ rot + shift):
        examples.add_position_constraint(stage, f"/Edits/c{f}", a, f, p)
    result, src, out = _solve(tmp_path, stage)
    frames = np.arange(0, 193, 7)
    expect = world_joints(src, f"{a}/Skel", frames) @ rot + shift
    np.testing.assert_allclose(world_joints(out, f"{a}/Skel", frames), expect, atol=1e-5)
    assert result.report.agents[a]["solver"] == "rigid"
    assert abs(result.report.agents[a]["lengthRatio"] - 1.0) < 1e-12


@pytest.mark.parametrize("pin_end, limit", [(False, 0.02), (True, 0.025)])
def test_moving_the_middle_of_a_ten_metre_walk_sideways(tmp_path, walk_clip, pin_end, limit):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/middle", a, 96, (1.0, 0.0, 5.0))
    if pin_end:
        examples.add_position_constraint(stage, "/Edits/end", a, 192, (0.0, 0.0, 10.0))
    result, src, out = _solve(tmp_path, stage)
    frames = np.arange(193)
    s, e = _root_ground(src, a, frames), _root_ground(out, a, frames)
    ratio = metrics.length_ratio(e, s)
    # With both ends pinned no path through the three points can be shorter than 1.98%
    # longer (two straight 5.1 m legs); the solve stays within half a percent of that.
    assert abs(ratio - 1.0) < limit
    assert result.report.agents[a]["lengthRatio"] == pytest.approx(ratio, abs=1e-6)
    np.testing.assert_allclose(e[96], [1.0, -5.0], atol=1e-6)


def test_stationary_ranges_move_rigidly_and_keep_their_heading(tmp_path, stop_clip):
    stage, a, clip, (first, last) = _standing_agent(tmp_path, stop_clip)
    reach = float(clip.translations[first, 0, 2])
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/stand", a, first + 10, (0.8, 0.0, reach + 0.3))
    examples.add_position_constraint(stage, "/Edits/end", a, 149, (2.5, 0.0, float(clip.translations[-1, 0, 2])))
    result, src, out = _solve(tmp_path, stage)
    frames = np.arange(first, last + 1)
    before, after = world_joints(src, f"{a}/Skel", frames), world_joints(out, f"{a}/Skel", frames)
    # One rigid transform (rotation about up, then translation) takes every joint of every
    # frame of the range from the source to the edit.
    p, q = before.reshape(-1, 3), after.reshape(-1, 3)
    pc, qc = p - p.mean(0), q - q.mean(0)
    h = pc[:, [0, 2]].T @ qc[:, [0, 2]]
    u, _, vt = np.linalg.svd(h)
    r2 = u @ vt
    moved = pc[:, [0, 2]] @ r2 + q.mean(0)[[0, 2]]
    assert np.abs(moved - q[:, [0, 2]]).max() < 1e-5
    turn = np.degrees(np.arctan2(r2[0, 1], r2[0, 0]))
    assert abs(turn) > 2.0, "the edit should turn the stand"
    entry = next(c for c in result.report.constraints if c["kind"] == "stationary")
    assert entry["residual"] < 1e-6 and entry["met"] and entry["agent"] == a
    assert _entry(result, "/Edits/stand")["residual"] < 1e-6


def test_heading_follows_the_new_path(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/mid", a, 64, (0.0, 0.0, float(walk_clip.translations[64, 0, 2])))
    examples.add_position_constraint(stage, "/Edits/end", a, 192, (4.0, 0.0, 9.0))
    result, src, out = _solve(tmp_path, stage)
    frames = np.arange(193)
    # The body's yaw change at each frame is the change of the path's direction there,
    # measured over a window of a gait cycle so the sway averages out.
    def yaw(stage):
        cache = UsdSkel.Cache()
        cache.Populate(UsdSkel.Root(stage.GetPrimAtPath(a)), Usd.PrimDefaultPredicate)
        q = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath(f"{a}/Skel")))
        out = []
        for f in frames:
            m = np.array(q.ComputeJointWorldTransforms(UsdGeom.XformCache(Usd.TimeCode(float(f))))[1])
            fwd = m[2, :3]   # the hips' local +Z in world space
            out.append(np.arctan2(-fwd[2], fwd[0]))
        return np.unwrap(out)
    turn_body = yaw(out) - yaw(src)
    s, e = _root_ground(src, a, frames), _root_ground(out, a, frames)
    w = 24
    ds, de = s[2 * w:] - s[:-2 * w], e[2 * w:] - e[:-2 * w]
    turn_path = np.unwrap(np.arctan2(de[:, 1], de[:, 0]) - np.arctan2(ds[:, 1], ds[:, 0]))
    body = np.array([turn_body[i - w:i + w].mean() for i in range(w, len(frames) - w)])
    assert np.abs(turn_path).max() > np.radians(15)
    assert np.abs(body - turn_path).max() < np.radians(3)


def test_hip_carried_motion(tmp_path):
    """A clip whose root stays at the origin while the hips walk: the hips' ground
    projection is the trajectory, and the whole body follows the edit."""
    path = write_toy_stage(tmp_path / "hips.usda", agents=1)
    stage = Usd.Stage.Open(str(path))
    anim = stage.GetPrimAtPath("/World/agent0/Skel/Anim")
    tr = anim.GetAttribute("translations")
    for t in tr.GetTimeSamples():
        v = np.array(tr.Get(t), dtype=np.float32)
        v[1, :2] += v[0, :2]                        # the hips carry the walk ...
        v[0, :2] = 0.0                              # ... and the root stays put
        tr.Set(Vt.Vec3fArray.FromNumpy(v), t)
    stage.GetPrimAtPath("/World/agent0").CreateAttribute("mocap:hipJoint", Sdf.ValueTypeNames.Token).Set("Hips")
    examples.add_position_constraint(stage, "/Edits/a", "/World/agent0", 0, (0.0, 0.0, 90.0))
    examples.add_position_constraint(stage, "/Edits/b", "/World/agent0", 30, (150.0, 40.0, 90.0))
    stage.GetRootLayer().Save()
    result = solve(str(path), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert result.report.agents["/World/agent0"]["trajectoryJoint"] == "Root/Hips"
    out = Usd.Stage.Open(str(tmp_path / "c.usda"))
    hips = world_joints(out, "/World/agent0/Skel", [0, 30])[:, 1]
    np.testing.assert_allclose(hips[:, :2], [[0.0, 0.0], [150.0, 40.0]], atol=1e-6)


# ---- path curves ------------------------------------------------------------------------

def _curve(kind, points, **kw):
    rec = {"type": "BasisCurves", "points": np.array(points, float), "counts": np.array([len(points)]),
           "local_to_world": np.eye(4), "basis": "bezier", "curve_type": "cubic", "wrap": "nonperiodic",
           "order": None, "knots": None, "weights": None}
    rec.update(kind=kind, **kw)
    return rec


def test_curve_evaluation_matches_closed_forms():
    # A cubic Bezier with collinear, evenly spaced controls is a straight line.
    line = curves.evaluate(_curve("bezier", [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)]))
    np.testing.assert_allclose(line[[0, -1]], [[0, 0, 0], [3, 0, 0]])
    assert np.all(np.diff(line[:, 0]) > 0)
    # Catmull-Rom (pinned) passes through its points; B-spline (pinned) through its ends.
    pts = [(0, 0, 0), (1, 2, 0), (3, 1, 0), (4, 4, 0)]
    for basis in ("catmullRom", "bspline"):
        poly = curves.evaluate(_curve(basis, pts, basis=basis, wrap="pinned"))
        np.testing.assert_allclose(poly[[0, -1]], [pts[0], pts[-1]], atol=1e-12)
        if basis == "catmullRom":
            for p in pts:
                assert np.linalg.norm(poly - p, axis=1).min() < 1e-12
    lin = curves.evaluate(_curve("linear", pts, curve_type="linear"))
    np.testing.assert_allclose(lin, pts)
    # A rational quadratic NURBS with the right weight is an exact quarter circle.
    w = np.sqrt(0.5)
    quarter = {"type": "NurbsCurves", "points": np.array([(1, 0, 0), (1, 1, 0), (0, 1, 0)], float),
               "counts": np.array([3]), "local_to_world": np.diag([2.0, 2.0, 2.0, 1.0]),
               "order": np.array([3]), "knots": np.array([0, 0, 0, 1, 1, 1], float),
               "weights": np.array([1, w, 1])}
    arc = curves.evaluate(quarter)
    np.testing.assert_allclose(np.linalg.norm(arc[:, :2], axis=1), 2.0, atol=1e-12)
    with pytest.raises(MocapEditError, match=r"</Curves/bad>.*knots"):
        curves.evaluate({**quarter, "knots": np.array([0, 0, 1, 1], float)}, "/Curves/bad")


def test_remap_keeps_distance_per_frame_and_sway():
    f = np.arange(240)
    uv = np.stack([f * 0.05, 0.03 * np.sin(2 * np.pi * f / 24)], axis=1)      # 1.2 m/s with a sway
    t = np.linspace(0, np.pi / 2, 400)
    arc = np.stack([8 * np.sin(t), 8 - 8 * np.cos(t)], axis=1)                   # a quarter turn, r = 8
    r = curves.remap(uv, arc, [], 24.0, 1e-6)
    centre = curves.smooth(uv, 12.0)
    step_src = np.linalg.norm(np.diff(centre, axis=0), axis=1)
    # Along the curve the agent covers the same distance per frame as its centreline did;
    # across it, it keeps its sway (measured from the circle).
    radius = np.linalg.norm(r.ground - [0, 8], axis=1)
    angle = np.arctan2(r.ground[:, 0], 8 - r.ground[:, 1])
    np.testing.assert_allclose(np.diff(angle)[24:-24] * 8, step_src[24:-24], rtol=0.02)
    np.testing.assert_allclose(8 - radius, uv[:, 1] - centre[:, 1], atol=2e-3)
    np.testing.assert_allclose(r.ground[0], [0, 0.0], atol=0.02)


def _chord_winding(path: np.ndarray, chord: int = 8) -> float:
    """Degrees the direction of a path's chords turns through in all (left and right)."""
    d = path[chord:] - path[:-chord]
    d = d[np.linalg.norm(d, axis=1) > 1e-3]
    return float(np.degrees(np.abs(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0])))).sum()))


def test_remap_keeps_a_shuffle_at_the_start_sideways():
    """A take that stands, shuffles 0.8 m sideways and half way back at 0.2 m/s, then walks off
    at right angles (a start-walk-stop take): on a curve, the shuffle stays a shuffle beside the
    curve's start, and the walk settles onto the curve. Measured against the centreline's own
    tangents, which turn through the corner, the sway swung round with them: loops, the path's
    direction turning 870 degrees more than the source's (a CMU take: its facing turned at 336
    degrees per second)."""
    fps = 30.0
    x = np.concatenate([np.zeros(60), np.linspace(0.0, 0.8, 120), np.linspace(0.8, 0.3, 75)])
    walk = -np.arange(1, 150) * 1.3 / fps
    uv = np.concatenate([np.stack([x, np.zeros_like(x)], axis=1),
                         np.stack([np.full_like(walk, 0.3), walk], axis=1)])
    uv[:, 0] += 0.02 * np.sin(2.0 * np.pi * np.arange(len(uv)) / fps)       # the sway
    t = np.linspace(0.0, np.pi / 2, 400)
    arc = np.stack([6.0 - 6.0 * np.cos(t), -6.0 * np.sin(t)], axis=1)       # sets off along -y, turns to +x
    r = curves.remap(uv, arc, [], fps, 1e-5, curves.SLOW_M_S, curves.SETTLE_M)
    assert _chord_winding(r.ground) < _chord_winding(uv) + 90.0
    # The shuffle moves across the curve's start, not along it; the walk ends on the curve.
    shuffle = r.ground[60:255]
    assert np.ptp(shuffle[:, 1]) < 0.2 and np.ptp(shuffle[:, 0]) > 0.7
    assert _to_polyline(r.ground[-10:], arc).max() < 0.1


def test_spline_and_constraints_and_stationary_tags_together(tmp_path, stop_clip):
    stage, a, clip, (first, last) = _standing_agent(tmp_path, stop_clip)
    examples.add_path_curve(stage, "/Curves/arc", [(0, 0, 0), (0, 0, 3), (2, 0, 5), (5, 0, 5)], [a],
                            basis="bezier", wrap="nonperiodic")
    result, src, out = _solve(tmp_path, stage)
    frames = np.arange(150)
    e = _root_ground(out, a, frames)
    poly = curves.ground_polyline(result.data.curves["/Curves/arc"], "/Curves/arc", "Y")
    assert _to_polyline(e, poly).max() < 0.02                  # this root walks without sway
    np.testing.assert_allclose(e[0], poly[0], atol=0.05)      # starts at the curve's start
    assert result.report.agents[a]["solver"] == "none"

    # A position constraint on top: it holds, the stand stays rigid, the rest follows the curve.
    examples.add_position_constraint(stage, "/Edits/end", a, 149, (4.5, 0.0, 5.8))
    result, src, out = _solve(tmp_path, stage)
    e = _root_ground(out, a, frames)
    np.testing.assert_allclose(e[149], [4.5, -5.8], atol=1e-6)
    stand = next(c for c in result.report.constraints if c["kind"] == "stationary")
    assert stand["residual"] < 1e-6
    assert _to_polyline(e[:first - 24], poly).max() < 0.02


def test_a_pin_off_the_curve_stretches_the_walk_gradually(tmp_path, stop_clip):
    """The last frame pinned 42 cm off the curve, after a stand: the walk after the stand takes
    the extra length over its whole span, not between the pin and the nearest curve anchor (it
    sped up by 46 % there, and the locked feet slid)."""
    stage, a, clip, _ = _standing_agent(tmp_path, stop_clip)
    examples.add_path_curve(stage, "/Curves/arc", [(0, 0, 0), (0, 0, 3), (2, 0, 5), (5, 0, 5)], [a],
                            basis="bezier", wrap="nonperiodic")
    _, _, out = _solve(tmp_path, stage)
    end = _root_ground(out, a, [149])[0]
    examples.add_position_constraint(stage, "/Edits/end", a, 149, (end[0] + 0.3, 0.0, -end[1] + 0.3))
    result, src, out = _solve(tmp_path, stage)
    frames = np.arange(150)
    speed = [np.linalg.norm(np.diff(_root_ground(s, a, frames), axis=0), axis=1) * FPS for s in (src, out)]
    walking = speed[0] > 0.5
    assert np.linalg.norm(_root_ground(out, a, [149])[0] - (end + [0.3, -0.3])) < 1e-6
    assert (speed[1][walking] / speed[0][walking]).max() < 1.3
    entry = result.report.agents[a]
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.005


# ---- bad input ------------------------------------------------------------------------

def test_bad_input_names_the_prims(tmp_path, walk_clip, stop_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    a = f"{CROWD}/a"
    examples.add_position_constraint(stage, "/Edits/one", a, 50, (0, 0, 2))
    examples.add_position_constraint(stage, "/Edits/two", a, 50, (0.5, 0, 2))
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</Edits/one>.*</Edits/two>.*frame 50"):
        solve(str(tmp_path / "shot.usda"))
    # The same place twice is fine.
    stage.GetPrimAtPath("/Edits/two").GetAttribute("position").Set((0.0, 0.0, 2.0))
    stage.GetRootLayer().Save()
    solve(str(tmp_path / "shot.usda"))
    proc = run_cli("solve", tmp_path / "shot.usda", "-o", tmp_path / "x.usda")
    assert proc.returncode == 0
    stage.GetPrimAtPath("/Edits/two").GetAttribute("position").Set((0.0, 0.0, 3.0))
    stage.GetRootLayer().Save()
    proc = run_cli("solve", tmp_path / "shot.usda", "-o", tmp_path / "y.usda")
    assert proc.returncode == 1 and "/Edits/two" in proc.stderr and not (tmp_path / "y.usda").exists()
    stage.RemovePrim("/Edits/two")

    cases = [
        ("agent", lambda: examples.add_position_constraint(stage, "/Edits/bad", "/World/Nobody", 3, (0, 0, 0)),
         r"</Edits/bad>\.agent.*/World/Nobody"),
        ("frame", lambda: examples.add_position_constraint(stage, "/Edits/bad", a, 500, (0, 0, 0)),
         r"</Edits/bad>\.frame.*500"),
        ("curve", lambda: stage.GetPrimAtPath(a).CreateRelationship("mocap:pathCurve").SetTargets(["/Edits/one"]),
         r"<%s>\.mocap:pathCurve.*/Edits/one" % a),
    ]
    for what, author, pattern in cases:
        author()
        stage.GetRootLayer().Save()
        with pytest.raises(MocapEditError, match=pattern):
            solve(str(tmp_path / "shot.usda"))
        stage.RemovePrim("/Edits/bad")
        stage.GetPrimAtPath(a).RemoveProperty("mocap:pathCurve")

    clip, _ = stop_clip
    other = tmp_path / "other"
    stage = examples.build_crowd_stage(other / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y", fps=FPS,
                                       stationary={clip.name: {"late": (140, 160)}})
    examples.add_position_constraint(stage, "/Edits/one", a, 10, (0, 0, 0))
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"stationary:late:frames.*\[140, 160\]"):
        solve(str(other / "shot.usda"))


def test_contradicting_hard_constraints_through_a_stationary_range(tmp_path, stop_clip):
    stage, a, clip, (first, last) = _standing_agent(tmp_path, stop_clip)
    reach = float(clip.translations[first, 0, 2])
    examples.add_position_constraint(stage, "/Edits/start", a, 0, (0, 0, 0))
    examples.add_position_constraint(stage, "/Edits/in", a, first, (0, 0, reach))
    examples.add_position_constraint(stage, "/Edits/out", a, last, (0, 0, reach + 2))   # a stand does not walk 2 m
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</Edits/in>.*</Edits/out>.*stationary:stand:frames"):
        solve(str(tmp_path / "shot.usda"))
    stage.RemovePrim("/Edits/start")   # held at one place: one translation, which cannot split
    stage.GetRootLayer().Save()
    with pytest.raises(MocapEditError, match=r"</Edits/in>.*</Edits/out>.*single place"):
        solve(str(tmp_path / "shot.usda"))


# ---- the interactive editor -------------------------------------------------------------

def test_path_editor_drags_without_refactoring(tmp_path, walk_clip):
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    a = f"{CROWD}/a"
    editor = PathEditor.for_agent(reader.read_stage(stage), a, [0, 96, 192])
    assert editor.solver == "rigid"
    np.testing.assert_allclose(editor.ground[96], [0.0, -5.0], atol=1e-6)
    factor = editor.problem.data
    for step in range(1, 6):
        g = editor.move(1, (0.2 * step, -5.0))
        np.testing.assert_allclose(g[96], [0.2 * step, -5.0], atol=1e-9)
    assert editor.problem.data is factor
    assert editor.heading.shape == (193,) and "LDLT" in editor.solver
    # The same edit through the stage gives the same path (the path pass's: the editor does not
    # pivot the body on its feet, a later pass).
    examples.add_position_constraint(stage, "/Edits/s", a, 0, (0, 0, 0))
    examples.add_position_constraint(stage, "/Edits/m", a, 96, (1.0, 0.0, 5.0))
    examples.add_position_constraint(stage, "/Edits/e", a, 192, (0, 0, 10))
    _, _, out = _solve(tmp_path, stage, pivot_on_feet=False)
    np.testing.assert_allclose(editor.ground, _root_ground(out, a, np.arange(193)), atol=1e-6)
    w = editor.to_world()
    assert w.shape == (193, 3) and abs(w[96, 0] - 1.0) < 1e-9
    with pytest.raises(ValueError, match="frame 300"):
        PathEditor(editor.ground, [0, 300])
    one = PathEditor(editor.ground, [10])
    moved = one.move(0, one.ground[10] + [1.0, 2.0])
    np.testing.assert_allclose(moved - editor.ground, np.tile([1.0, 2.0], (193, 1)), atol=1e-12)


def test_path_editor_drags_a_path_about_one_spot_as_the_solve_does():
    """A 12 s bounce within 10 cm at 60 fps: its spot terms turn with the body, settled by
    re-solving, in the editor as in the solve. Dragged aside at its middle it slides as a whole;
    turned a quarter turn by its three handles it turns rigidly (the editor solved once with the
    spot terms unturned: 0.19 m off the rigid motion)."""
    t = np.arange(720) / 60.0
    rest = 0.08 * np.stack([0.6 * np.sin(1.3 * t) + 0.4 * np.sin(3.1 * t + 1.0),
                            0.6 * np.sin(1.7 * t + 0.5) + 0.4 * np.sin(2.3 * t + 2.0)], axis=1)
    editor = PathEditor(rest, [0, 360, 719], fps=60.0)
    g = editor.move(1, rest[360] + (0.4, 0.0))
    carried = np.interp(np.arange(720), [0, 360, 719], [0.0, 0.4, 0.0])
    assert np.hypot(g[:, 0] - rest[:, 0] - carried, g[:, 1] - rest[:, 1]).max() < 0.02
    quarter = np.array([[0.0, -1.0], [1.0, 0.0]])
    turned = (rest - (1.0, 2.0)) @ quarter.T + (1.0, 2.0)
    g = editor.set_positions(turned[[0, 360, 719]])
    np.testing.assert_allclose(g, turned, atol=1e-9)


def test_a_curve_drawn_against_the_walk_is_not_a_reversal(tmp_path, walk_clip):
    """A path curve is the way the artist draws an agent to walk: drawn back along the take's
    walk, the agent walks it the other way round. Its walking direction deviates from its
    source's by nearly 180 degrees, which the report still gives, but that turn is the curve's:
    the agent is not reversing. A walker sent back by pins still is
    (``test_path_multi.test_an_edit_that_sends_a_walker_back_is_a_reversal``)."""
    stage = _stage(tmp_path, [examples.AgentSpec("a", walk_clip)])
    a = f"{CROWD}/a"
    examples.add_path_curve(stage, "/Curves/back", [(0, 0, 12.0), (1.0, 0, 9.0), (-0.5, 0, 6.0), (1.0, 0, 3.0),
                                                     (0, 0, 0)], [a])
    result, src, out = _solve(tmp_path, stage)
    p = result.report.agents[a]["plausibility"]
    assert p["maxDirectionDeviation"] > 150.0 and p["maxEditTurn"] > metrics.REVERSE_TURN_DEGREES
    assert p["maxTurnOffCurve"] < 30.0
    assert p["reverses"] is False and result.report.stats["plausibility"]["reversingAgents"] == 0
    # Walking the curve back and forth would still reverse against it.
    figures = metrics.Plausibility(agent=a, max_facing_rate=0.0, source_max_facing_rate=0.0,
                                   max_extra_facing_rate=0.0, spin_frames=0, max_direction_deviation=170.0,
                                   length_ratio=1.0, time_warp=(1.0, 1.0), foot_skate_source=1.0,
                                   foot_skate_edited=1.0, foot_skate_ratio=1.0, max_turned_deviation=10.0,
                                   max_edit_turn=170.0, max_turn_off_curve=170.0)
    assert figures.reverses


def test_a_relative_constraint_on_the_agent_itself_sets_how_far_it_goes(tmp_path):
    """Target the constrained agent at another frame: the offset is its travel between the two
    frames (the schema allows it; the same frame is an error)."""
    from mocapedit.usd import evaluate
    clip = walker.walk(frames=72, name="walk")
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip, (0, 0, 0), 0.0)])
    agent = "/World/Crowd/a"
    source = evaluate.agent_root_positions(stage, [agent], [10.0, 60.0])[0]
    travel = source[1] - source[0]
    examples.add_relative_constraint(stage, "/Edits/further", agent, 60, agent, 10, tuple(1.25 * travel))
    stage.GetRootLayer().Save()
    solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"),
          collisions=False, foot_locking=False)
    edited = evaluate.agent_root_positions(Usd.Stage.Open(str(tmp_path / "c.usda")), [agent], [10.0, 60.0])[0]
    ground_axes = [0, 2]   # Y-up
    np.testing.assert_allclose((edited[1] - edited[0])[ground_axes], 1.25 * travel[ground_axes], atol=1e-6)


def test_three_hard_pins_on_a_stationary_range_that_one_rigid_motion_meets_solve(tmp_path):
    """A stationary range held by three hard pins at their source places (or all moved 1 m
    the same way): one rigid motion meets them all, so the range moves by it. The solve said
    "hard constraints contradict each other: a rotating rigid range holds hard constraints at 3
    vertices", naming no prim. Three pins no rigid motion meets are still a contradiction,
    named by their prims."""
    from mocapedit.usd import evaluate
    clip, _ = walker.walk_idle_walk(frames=240, name="wiw")
    agent = "/World/Crowd/w"
    for case, shift in (("still", (0.0, 0.0, 0.0)), ("moved", (1.0, 0.0, 0.0)), ("bent", None)):
        folder = tmp_path / case
        folder.mkdir()
        stage = examples.build_crowd_stage(folder / "shot.usda", [examples.AgentSpec("w", clip)])
        roots = evaluate.agent_root_positions(stage, agent, np.arange(240.0)) * [1, 0, 1]
        anim = stage.GetPrimAtPath(agent + "/Skel/Anim")
        anim.AddAppliedSchema("MocapStationaryAPI:r")
        anim.CreateAttribute("stationary:r:frames", Sdf.ValueTypeNames.Int2,
                             variability=Sdf.VariabilityUniform).Set(Gf.Vec2i(140, 200))
        for f in (140, 170, 200):
            p = roots[f] + (shift if shift is not None else (0.0, 0.0, 0.5 * (f == 170)))
            examples.add_position_constraint(stage, f"/Edits/pin{f}", agent, f, tuple(map(float, p)))
        stage.GetRootLayer().Save()
        if shift is None:
            with pytest.raises(MocapEditError, match=r"</Edits/pin1[47]0>.*contradict"):
                solve(str(folder / "shot.usda"))
            continue
        result = solve(str(folder / "shot.usda"), output=str(folder / "e.usda"), composed=str(folder / "c.usda"))
        assert all(c.met for c in result.report.constraints), [(c.prim, c.residual) for c in result.report.constraints]
        edited = evaluate.agent_root_positions(Usd.Stage.Open(str(folder / "c.usda")), agent, np.arange(240.0))
        np.testing.assert_allclose((edited - roots)[140:201] * [1, 0, 1], np.tile(shift, (61, 1)), atol=1e-6)


def _still_path_with_a_hop(frames: int = 240, fps: float = 60.0):
    """(rest (F,2), planted (F,)) of a take about one spot: a sway of a centimetre or two at
    ``fps``, with no foot planted over frames 105 to 135 (a hop)."""
    t = np.arange(frames) / fps
    rest = 0.015 * np.stack([np.sin(1.1 * t), np.sin(0.7 * t + 1.0)], axis=1)
    planted = np.ones(frames, dtype=bool)
    planted[105:136] = False
    return rest, planted


def test_a_take_about_one_spot_travels_where_no_foot_is_planted():
    """A take about one spot whose end is dragged 0.6 m aside travels while its source has no
    foot on the ground (the flight of a hop), and keeps its own motion on the ground: 0.6 m
    spread evenly over its 4 s, the planted feet were dragged 15 cm/s. Without contacts, the
    drag is spread as before."""
    rest, planted = _still_path_with_a_hop()
    last = len(rest) - 1
    handles = [path_edit.Handle("a", 0, rest[0], path_edit.HARD, "/start"),
               path_edit.Handle("a", last, rest[last] + (0.6, 0.0), path_edit.HARD, "/end")]
    settings = path_edit.Settings(min_baseline=0.01, rigid_min_extent=0.02, still=1e-5,
                                  **path_edit.turn_settings(60.0, 1.0))

    def moved(contacts):
        a = path_edit.AgentInput("a", rest, rest, np.zeros(len(rest)), [],
                                 stance=None if contacts is None else path_edit.stance_weights(contacts))
        g = path_edit.ComponentProblem([a], handles, [], [], settings).solve().agents["a"].ground
        np.testing.assert_allclose(g[[0, last]], [h.position for h in handles], atol=1e-9)
        return np.linalg.norm(g - rest - (g[0] - rest[0]), axis=1)   # how far each frame is carried

    carried = moved(planted)
    assert carried[136] - carried[104] > 0.9 * 0.6            # in the air
    assert carried[104] < 0.03 and carried[136] > 0.57         # on the ground before and after
    even = moved(None)
    assert 0.05 < even[136] - even[104] < 0.1                  # a 30-frame share of 0.6 m


def _hop_shot(tmp_path, drag: float, hop: float = 0.0):
    """(stage, agent) of the generated idle at 60 fps with a 15 cm hop over frames 105 to 135
    that travels ``hop`` metres along the take's way (z), its last frame dragged ``drag`` metres
    along x and along z (a pair) by a hard handle, its first frame held."""
    clip = walker.idle(frames=240, fps=60.0, name="hop")
    bump = np.clip((np.arange(240) - 105) / 30.0, 0.0, 1.0)
    clip.translations[:, 0, 1] += 0.15 * np.sin(np.pi * bump)
    clip.translations[:, 0, 2] += hop * bump * bump * (3.0 - 2.0 * bump)
    stage = examples.build_crowd_stage(tmp_path / "shot.usda", [examples.AgentSpec("a", clip)], up_axis="Y",
                                       fps=60.0, clips_dir=tmp_path / "clips")
    a = f"{CROWD}/a"
    for name, frame, (dx, dz) in (("start", 0, (0.0, 0.0)), ("end", 239, drag)):
        p = clip.translations[frame, 0]
        examples.add_position_constraint(stage, f"/Edits/{name}", a, frame, (float(p[0]) + dx, 0.0, float(p[2]) + dz))
    return stage, a


def test_a_take_planted_throughout_or_never_weighs_as_before():
    """Contacts that tell nothing of flights (every frame planted, or no frame: feet never found on
    the ground) leave the take's terms as they were."""
    assert path_edit.stance_weights(np.ones(10, dtype=bool)) is None
    assert path_edit.stance_weights(np.zeros(10, dtype=bool)) is None
    w = path_edit.stance_weights(np.arange(10) < 6)
    np.testing.assert_array_equal(w, [1.0] * 6 + [path_edit.AIRBORNE_WEIGHT] * 4)


def test_a_standing_take_with_a_hop_dragged_aside_hops_across_on_the_stage(tmp_path):
    """The generated idle with a 15 cm hop in its middle, its last frame dragged 0.6 m aside by
    a hard handle: measured by UsdSkel FK on the composed stage before foot locking, the hips
    travel 0.55 m of it during the hop (0.08 m with the drag spread over the take) and the feet
    slide 1.4 cm/s over the source's contacts (15 cm/s); locked, they are as planted as the
    source's."""
    stage, a = _hop_shot(tmp_path, (0.6, 0.0))
    result, src, out = _solve(tmp_path, stage, foot_locking=False)
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    frames = np.arange(240.0)
    shift = _root_ground(out, a, frames)[:, 0] - _root_ground(src, a, frames)[:, 0]
    assert shift[136] - shift[104] > 0.5 and abs(shift[0]) < 0.005 and abs(shift[239] - 0.6) < 0.005
    before = measure.foot_skate(src, a)
    after = measure.foot_skate(out, a, times=before.times, contact=before.contact)
    assert not before.contact[112:129].any() and before.contact[:100].all()   # the hop is in the air
    assert before.mean < 0.005 and after.mean < 0.03, (before.mean, after.mean)
    locked, _, lout = _solve(tmp_path, stage)
    assert locked.report.agents[a]["footSkateEdited"] <= locked.report.agents[a]["footSkateSource"] + 0.005


def test_a_hop_dragged_against_its_way_is_not_turned_back(tmp_path):
    """The hop travels 30 cm forward in the air and the take's end is dragged 60 cm back: carried
    in the air, the whole drag would turn the hop back (a reversal, as the report counts it). The
    frames where the travel would turn more than ``AIRBORNE_MAX_DEVIATION`` from the source's
    weigh more, round by round, until it does not: measured by UsdSkel FK on the composed stage,
    the hop still goes forward, and the report finds no reversal."""
    stage, a = _hop_shot(tmp_path, (0.0, -0.6), hop=0.3)
    result, src, out = _solve(tmp_path, stage, foot_locking=False)
    frames = np.arange(240.0)
    before, after = _root_ground(src, a, frames), _root_ground(out, a, frames)
    hop, hopped = before[136] - before[104], after[136] - after[104]
    assert np.linalg.norm(hop) == pytest.approx(0.3, abs=0.01)
    assert hopped @ hop > 0.3 * hop @ hop                     # forward still, if shorter
    p = result.report.agents[a]["plausibility"]
    assert not p.reverses and p.max_direction_deviation < path.AIRBORNE_MAX_DEVIATION + 10.0
