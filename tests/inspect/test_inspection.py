"""Inspection: overlaps, guides in the edits layer, the stored report and `mocapedit report`."""
from __future__ import annotations

import json

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdValidation

from mocapedit.pipeline import guides
from mocapedit.inspect import overlaps
from mocapedit.model import report
from mocapedit.model.report import ConstraintEntry
from mocapedit.usd.report_io import read_report
from mocapedit.usd import edits_format, writer
from mocapedit.pipeline.processor import solve

from conftest import run_cli, write_toy_stage
from inspection_scene import DRIFT, MOVED, install_pass, write_scene


# ---- overlaps ---------------------------------------------------------------------------------

def _brute_force(pos, radii, reach, active):
    rows = []
    for s in range(pos.shape[1]):
        for a in range(len(pos)):
            for b in range(a + 1, len(pos)):
                if not (active[a] and active[b]):
                    continue
                gap = np.linalg.norm(pos[a, s] - pos[b, s]) - radii[a] - radii[b]
                if gap < reach:
                    rows.append((s, a, b, gap))
    return rows


@pytest.mark.parametrize("reach", [0.0, 1.5, 0.5])
def test_proximity_finds_exactly_the_pairs_a_brute_force_finds(reach):
    rng = np.random.default_rng(4)
    pos = rng.uniform(-6, 6, size=(30, 9, 2))
    pos[rng.random((30, 9)) < 0.1] = np.nan       # absent at some samples
    radii = rng.uniform(0.2, 0.9, size=30)
    active = rng.random(30) > 0.15
    found = overlaps.proximity(pos, radii, reach, active)
    expect = _brute_force(pos, radii, reach, active)
    assert len(expect) > 10
    assert list(zip(found.sample, found.a, found.b)) == [r[:3] for r in expect]
    np.testing.assert_allclose(found.clearance, [r[3] for r in expect], atol=1e-12)
    worst = overlaps.worst_per_pair(found.overlapping())
    pairs = {(r[1], r[2]) for r in expect if r[3] < 0}
    assert set(zip(worst.a, worst.b)) == pairs
    for a, b, c in zip(worst.a, worst.b, worst.clearance):
        assert c == pytest.approx(min(r[3] for r in expect if r[1:3] == (a, b)))


def test_proximity_rejects_bad_shapes():
    with pytest.raises(ValueError, match="#A by #T by 2"):
        overlaps.proximity(np.zeros((3, 4, 3)), np.ones(3))
    with pytest.raises(ValueError, match="reach"):
        overlaps.proximity(np.zeros((3, 4, 2)), np.ones(3), reach=-1.0)
    assert len(overlaps.proximity(np.zeros((1, 4, 2)), np.ones(1))) == 0


# ---- guides -----------------------------------------------------------------------------------

@pytest.fixture
def scene(tmp_path, monkeypatch):
    stage = write_scene(tmp_path / "shot.usda")
    install_pass(monkeypatch)
    edits, composed = tmp_path / "shot.edits.usda", tmp_path / "shot.edited.usda"
    result = solve(str(stage), output=str(edits), composed=str(composed))
    return result, stage, edits, composed


def _guide(stage, name):
    prim = stage.GetPrimAtPath(f"/MocapEdit/Guides/{name}")
    assert prim, f"missing guide {name}"
    return prim


def _colors(prim):
    return np.array(prim.GetAttribute("primvars:displayColor").Get())


def test_guides_show_paths_handles_links_stationary_ranges_and_collisions(scene):
    result, _, _, composed = scene
    stage = Usd.Stage.Open(str(composed))
    up = "Z"
    src = _guide(stage, "SourcePaths")
    assert list(src.GetAttribute("curveVertexCounts").Get()) == [48] * 4
    edited = _guide(stage, "EditedPaths")
    pts = np.array(edited.GetAttribute("points").Get())
    assert pts.shape == (48, 3)
    source_pts = np.array(src.GetAttribute("points").Get())[48:96]
    np.testing.assert_allclose(pts[-1, 1], source_pts[-1, 1] - DRIFT, atol=1e-3)
    assert not np.allclose(_colors(src)[0], _colors(edited)[0]), "source and edited paths share a colour"

    handles = _guide(stage, "ConstraintHandles")
    hp, hc = np.array(handles.GetAttribute("points").Get()), _colors(handles)
    assert len(hp) == 2
    met = np.flatnonzero(np.all(np.isclose(hc, guides.MET), axis=1))
    unsolved = np.flatnonzero(np.all(np.isclose(hc, guides.NOT_REPORTED), axis=1))
    assert len(met) == 1 and len(unsolved) == 1
    np.testing.assert_allclose(hp[met[0], :2], pts[40, :2], atol=1e-3)
    np.testing.assert_allclose(hp[unsolved[0], :2], [60.0, -40.0], atol=1e-6)

    rel = _guide(stage, "RelativeLinks")
    assert list(rel.GetAttribute("curveVertexCounts").Get()) == [2]
    assert rel.GetAttribute("primvars:displayColor").GetMetadata("interpolation") == "uniform"
    np.testing.assert_allclose(_colors(rel)[0], guides.NOT_MET, atol=1e-6)   # reported not met
    assert list(_guide(stage, "GroupLinks").GetAttribute("curveVertexCounts").Get()) == [2] * 4

    ranges = _guide(stage, "StationaryRanges")
    assert list(ranges.GetAttribute("curveVertexCounts").Get()) == [11]        # frames 10..20
    rp = np.array(ranges.GetAttribute("points").Get())
    agent0 = np.array(src.GetAttribute("points").Get())[:48]
    np.testing.assert_allclose(rp[:, :2], agent0[10:21, :2], atol=1e-4)

    # agent1's new path runs into agent0: one collision point per pair, half way between them.
    n = result.report.stats["remainingOverlaps"]
    coll = np.array(_guide(stage, "Collisions").GetAttribute("points").Get())
    assert n >= 1 and len(coll) == n
    for p in coll:
        assert np.min(np.linalg.norm(pts[:, :2] - p[:2], axis=1)) < 30.0
    for prim in stage.GetPrimAtPath("/MocapEdit/Guides").GetChildren():
        assert UsdGeom.Imageable(prim).GetPurposeAttr().Get() == "guide"
    assert result.report.agents[MOVED]["maxDisplacement"] == pytest.approx(DRIFT)
    assert result.report.agents[MOVED]["minSeparation"] < 0


def test_guides_open_cleanly_in_usd_validation(scene):
    _, _, edits, composed = scene
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    context = UsdValidation.ValidationContext(validators)
    for path in (edits, composed):
        stage = Usd.Stage.Open(str(path))
        errors = [e for e in context.Validate(stage) if e.GetType() == UsdValidation.ValidationErrorType.Error]
        assert not errors, [f"{e.GetName()}: {e.GetMessage()}" for e in errors]
        guides_root = stage.GetPrimAtPath("/MocapEdit/Guides")
        for prim in guides_root.GetChildren():
            boundable = UsdGeom.Boundable(prim)
            extent = np.array(boundable.GetExtentAttr().Get())
            pts = np.array(prim.GetAttribute("points").Get())
            assert extent.shape == (2, 3), f"{prim.GetPath()} has no extent"
            assert np.all(pts >= extent[0] - 1e-4) and np.all(pts <= extent[1] + 1e-4)
            color = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
            counts = prim.GetAttribute("curveVertexCounts").Get() if prim.IsA(UsdGeom.BasisCurves) else None
            expect = {"constant": 1, "uniform": len(counts or []), "vertex": len(pts)}[color.GetInterpolation()]
            assert len(color.Get()) == expect, f"{prim.GetPath()}: displayColor has the wrong length"
            if counts is not None:
                assert sum(counts) == len(pts) and min(counts) >= 2
    layer = Sdf.Layer.FindOrOpen(str(edits))
    assert layer.defaultPrim == "MocapEdit"


def test_no_guides_writes_no_guide_geometry_but_keeps_the_report(tmp_path, monkeypatch):
    stage = write_scene(tmp_path / "shot.usda")
    install_pass(monkeypatch)
    result = solve(str(stage), output=str(tmp_path / "e.usda"), guides=False)
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "e.usda"))
    assert layer.GetPrimAtPath("/MocapEdit") and not layer.GetPrimAtPath("/MocapEdit/Guides")
    stored = read_report(str(tmp_path / "e.usda"))
    assert stored.report.stats["remainingOverlaps"] == result.report.stats["remainingOverlaps"] >= 1


def test_a_guide_a_pass_appended_is_kept(tmp_path, monkeypatch):
    stage = write_scene(tmp_path / "shot.usda")

    def with_own_guide(ctx):
        ctx.guides.append(writer.GuideCurves(name="EditedPaths", curves=[np.zeros((3, 3))],
                                             color=(0, 0, 1), width=1.0, doc="the pass's own"))
    install_pass(monkeypatch, with_own_guide)
    result = solve(str(stage))
    spec = result.layer.GetPrimAtPath("/MocapEdit/Guides/EditedPaths")
    assert spec.documentation == "the pass's own"
    assert not result.layer.GetPrimAtPath("/MocapEdit/Guides/EditedPaths_2")


def test_collisions_reported_by_a_pass_are_shown_as_reported(tmp_path, monkeypatch):
    stage = write_toy_stage(tmp_path / "shot.usda", agents=2)

    def collisions(ctx):
        ctx.report.stats.remaining_overlaps = 1
        ctx.report.constraints.append(ConstraintEntry(
            prim="/World/agent0", kind="collision", agent="/World/agent0", frame=3, target="/World/agent1",
            target_frame=3, hard=False, residual=0.2, met=False, position=[1.0, 2.0, 0.0]))
    install_pass(monkeypatch, collisions)
    result = solve(str(stage))
    pts = result.layer.GetAttributeAtPath("/MocapEdit/Guides/Collisions.points").default
    np.testing.assert_allclose(np.array(pts), [[1.0, 2.0, 0.0]])
    assert result.report.stats["remainingOverlaps"] == 1
    assert "minSeparation" not in result.report.agents["/World/agent0"], "the pass's word is kept"


# ---- the stored report and `mocapedit report` ------------------------------------------------------

def test_the_report_is_stored_in_the_layer_without_timings(scene):
    result, _, edits, _ = scene
    data = Sdf.Layer.FindOrOpen(str(edits)).customLayerData["mocapedit"]
    stored = json.loads(data["report"])
    assert "timings" not in stored and "output" not in stored
    assert stored == json.loads(json.dumps(result.report.to_layer_dict()))
    assert stored["constraints"][1]["residual"] == 3.5
    assert stored["agents"][MOVED]["solver"] == "LDLT"


def test_report_reads_back_the_same_from_the_edits_and_the_composed_stage(scene):
    _, _, edits, composed = scene
    a, b = read_report(str(edits)), read_report(str(composed))
    assert a.report.to_layer_dict() == b.report.to_layer_dict()
    assert a.meters_per_unit == 0.01 and a.up_axis == "Z"


def test_report_cli_prints_a_table_per_agent(scene):
    _, _, edits, _ = scene
    proc = run_cli("report", edits)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "lengths in cm" in out
    assert "constraints reported: 2, met: 1, not met: 1" in out
    assert "overlapping agent pairs left: 1" in out
    assert "note: a run-wide note" in out
    block = out.split(f"\n{MOVED}  (edited, 48 frames)\n", 1)[1].split("\n\n", 1)[0]
    assert "length ratio" in block and "displacement max 160" in block and "OVERLAP" in block
    assert "solver LDLT" in block and "note: fell back to nothing: a test note" in block
    assert "/Edits/here  position  40" in block
    rel = out.split("\n/World/agent2  (", 1)[1].split("\n\n", 1)[0]
    assert "/World/agent3@20" in rel and "3.5" in rel and "NO" in rel
    assert "\n/World/agent3  (" not in out, "agents without edits, constraints or overlaps are folded"
    assert "(1 agents without edits" in out
    all_agents = run_cli("report", edits, "--all").stdout
    assert "\n/World/agent3  (not edited, 48 frames)" in all_agents


def test_report_cli_json_and_agent_filter(scene):
    _, _, edits, _ = scene
    proc = run_cli("report", edits, "--json", "--agent", "*agent2")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert list(data["agents"]) == ["/World/agent2"]
    assert [c["prim"] for c in data["constraints"]] == ["/Edits/rel"]
    assert data["metersPerUnit"] == 0.01 and data["stats"]["remainingOverlaps"] == 1
    assert len(data["contentHash"]) == 64
    # A pattern that matches nobody says so (it printed an empty report, exit 0).
    proc = run_cli("report", edits, "--agent", "/nomatch*")
    assert proc.returncode == 1 and "--agent /nomatch*: matches no agent" in proc.stderr, proc.stderr
    assert "/World/agent" in proc.stderr


def test_report_cli_fails_clearly_without_a_report(tmp_path, toy_stage):
    proc = run_cli("report", toy_stage)
    assert proc.returncode == 1 and "holds no mocapedit report" in proc.stderr
    proc = run_cli("report", tmp_path / "nope.usda")
    assert proc.returncode == 1 and "no such file" in proc.stderr


def test_stored_report_is_deterministic_and_finite(tmp_path, monkeypatch):
    stage = write_scene(tmp_path / "shot.usda")
    install_pass(monkeypatch)
    solve(str(stage), output=str(tmp_path / "a.usda"))
    solve(str(stage), output=str(tmp_path / "b.usda"))
    assert (tmp_path / "a.usda").read_bytes() == (tmp_path / "b.usda").read_bytes()
    assert edits_format.report_text({"x": float("inf"), "y": [np.float32(1.5), float("nan")]}) == '{"x":null,"y":[1.5,null]}'


@pytest.mark.parametrize("retimed", [False, True])
def test_the_report_gives_the_foot_skate_of_moved_agents_source_and_edited(tmp_path, retimed):
    from mocapedit.data import examples, walker
    from mocapedit.tools import measure
    from mocapedit.usd import evaluate
    walk = walker.walk(frames=48, name="walk")
    path = tmp_path / "shot.usda"
    examples.build_crowd_stage(path, [examples.AgentSpec("a0", walk, (0.0, 0.0, 0.0), 0.0),
                                      examples.AgentSpec("a1", walk, (3.0, 0.0, 0.0), 0.0)],
                               clips_dir=tmp_path / "clips")
    stage = Usd.Stage.Open(str(path))
    start = evaluate.agent_root_positions(stage, "/World/Crowd/a0", [0.0])[0]
    examples.add_position_constraint(stage, "/Edits/start", "/World/Crowd/a0", 0, start)
    # The end pulled a metre sideways: the path bends and the feet slide more than the source's.
    end = evaluate.agent_root_positions(stage, "/World/Crowd/a0", [47.0])[0] + (1.0, 0.0, 0.0)
    examples.add_position_constraint(stage, "/Edits/end", "/World/Crowd/a0", 47, end)
    if retimed:  # the pose is baked again on the shot's frames: measured by UsdSkel on both stages
        examples.add_time_constraint(stage, "/Edits/late", "/World/Crowd/a0", 47, 55.0)
        stage.SetEndTimeCode(55.0)   # the shot shows the walker to its last step (the report measures the shot)
    stage.GetRootLayer().Save()
    edits, composed = tmp_path / "e.usda", tmp_path / "c.usda"
    # Measured without foot locking, which would plant the feet the edit made slide.
    result = solve(str(path), output=str(edits), composed=str(composed), foot_locking=False)
    moved, still = result.report.agents["/World/Crowd/a0"], result.report.agents["/World/Crowd/a1"]
    assert "footSkateSource" not in still and "footSkateEdited" not in still
    source = measure.foot_skate(Usd.Stage.Open(str(path)), "/World/Crowd/a0")
    edited = measure.foot_skate(Usd.Stage.Open(str(composed)), "/World/Crowd/a0") if retimed else \
        measure.foot_skate(Usd.Stage.Open(str(composed)), "/World/Crowd/a0", times=source.times,
                           contact=source.contact)
    # The solve measures by forward kinematics in double precision, UsdSkel from float samples.
    assert moved["footSkateSource"] == pytest.approx(source.mean, rel=1e-4)
    assert moved["footSkateEdited"] == pytest.approx(edited.mean, rel=1e-4)
    assert moved["footSkateEdited"] > moved["footSkateSource"]
    text = report.format_text(read_report(str(edits)))
    assert f"foot skate {report._num(moved['footSkateSource'])} -> {report._num(moved['footSkateEdited'])}" in text


def test_progress_and_report_count_the_overlaps_left_alike(tmp_path, monkeypatch):
    import io

    from mocapedit.model.progress import Progress
    stage = write_scene(tmp_path / "shot.usda")
    install_pass(monkeypatch)
    stream = io.StringIO()
    result = solve(str(stage), output=str(tmp_path / "e.usda"), progress=Progress(stream=stream, interval=0.0))
    left = result.report.stats["remainingOverlaps"]
    assert left == 1
    assert "overlaps: " in stream.getvalue() and ", 1 overlapping agent pair\n" in stream.getvalue()
    assert "overlapping agent pairs left: 1" in result.report.summary().splitlines()
