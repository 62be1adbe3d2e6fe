"""`mocapedit preview`: the PNG and the EXR are decoded and checked pixel by pixel."""
from __future__ import annotations

import io
import json

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from mocapedit.geometry import ground
from mocapedit.tools import preview
from mocapedit.pipeline.processor import solve
from mocapedit.model.progress import Progress

from conftest import run_cli
from inspection_scene import DRIFT, MOVED, REGION_CENTRE, install_pass, write_scene


@pytest.fixture(params=["Z", "Y"])
def solved(request, tmp_path, monkeypatch):
    stage = write_scene(tmp_path / "shot.usda", up_axis=request.param)
    install_pass(monkeypatch)
    edits, composed = tmp_path / "shot.edits.usda", tmp_path / "shot.edited.usda"
    solve(str(stage), output=str(edits), composed=str(composed))
    scene = preview.load(str(stage), str(edits))
    return scene, stage, edits, composed


def _to_pixel(matrix, uv, up):
    ab = preview.plan(np.asarray(uv, dtype=np.float64), up)
    p = np.c_[ab, np.ones(len(ab))] @ np.asarray(matrix)
    return np.floor(p[:, :2]).astype(int)    # (column, row)


def _empty_spot(scene):
    """A ground point inside the view, far from every path, handle and region."""
    box = preview.scene_bounds(scene)
    pts = np.concatenate([np.concatenate([a.source.ground, a.edited.ground]) for a in scene.crowd.agents])
    pts = np.concatenate([pts, [h for h, _ in scene.handles]] + [poly for _, poly, _ in scene.regions])
    u, v = np.meshgrid(np.linspace(*box[:, 0], 40)[5:-5], np.linspace(*box[:, 1], 40)[5:-5])
    cand = np.stack([u.ravel(), v.ravel()], axis=-1)
    # Away from the scale bar (lower left) too.
    cand = cand[~((cand[:, 0] < box[0, 0] + 0.3 * np.ptp(box[:, 0])) & (cand[:, 1] < box[0, 1] + 0.2 * np.ptp(box[:, 1])))]
    dist = np.min(np.linalg.norm(cand[:, None] - pts[None], axis=-1), axis=1)
    best = cand[np.argmax(dist)]
    assert dist.max() > 60.0
    return best


def _agent(scene, path):
    return next(a for a in scene.crowd.agents if a.path == path)


def _window(img, col, row, r=2):
    return img[max(row - r, 0):row + r + 1, max(col - r, 0):col + r + 1].reshape(-1, img.shape[-1])


def test_png_shows_paths_collisions_and_regions_where_they_are(solved, tmp_path):
    scene, *_ = solved
    out = tmp_path / "top.png"
    matrix = preview.write(scene, str(out), resolution=900)
    with Image.open(out) as im:
        stored = np.array(json.loads(im.text["mocapedit:worldToPixel"]))
        img = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    np.testing.assert_allclose(stored, matrix)
    assert max(img.shape[:2]) == 900
    up = scene.up_axis
    moved = _agent(scene, MOVED)

    def colour_near(uv, colour, tol=0.12, r=2):
        col, row = _to_pixel(matrix, np.atleast_2d(uv), up)[0]
        win = _window(img, col, row, r)
        return np.min(np.abs(win - colour).max(axis=1)) < tol

    for f in (8, 24, 44):
        assert colour_near(moved.edited.ground[f], preview_colour("EDITED")), f"edited path missing at frame {f}"
    assert colour_near(_agent(scene, "/World/agent3").source.ground[30], preview.UNCHANGED)
    assert any(colour_near(moved.source.ground[f], preview_colour("SOURCE"), r=4) for f in (34, 36, 38))
    assert not colour_near(moved.source.ground[36], preview_colour("EDITED"), r=3), "edited colour on the source path"
    for p in scene.remaining.ground:
        assert colour_near(p, preview_colour("COLLISION"), tol=0.05, r=1)
    col, row = _to_pixel(matrix, [_empty_spot(scene)], up)[0]
    assert np.all(_window(img, col, row, 3) > 0.97), "an empty spot is not white"
    col, row = _to_pixel(matrix, [np.array(REGION_CENTRE) + (0.0, 25.0)], up)[0]
    region = _window(img, col, row, 3).mean(axis=0)
    assert region[0] > region[2] + 0.03 and region.mean() < 0.99, "the avoid region is not drawn"


def preview_colour(name):
    from mocapedit.pipeline import guides
    return np.array(getattr(guides, name))


def _read_exr(path):
    f = OpenEXR.File(str(path), separate_channels=True)
    return f.header(), {k: c.pixels for k, c in f.channels().items()}


def test_exr_channels_are_world_aligned(solved, tmp_path):
    scene, *_ = solved
    out = tmp_path / "top.exr"
    grid = preview.write(scene, str(out), resolution=500)
    header, ch = _read_exr(out)
    assert set(ch) == set(preview.CHANNELS)
    assert all(c.dtype == np.float32 and c.shape == (grid.height, grid.width) for c in ch.values())
    up = scene.up_axis
    matrix = header["mocapedit:worldToPixel"]
    np.testing.assert_allclose(matrix, grid.world_to_pixel(), rtol=1e-6)
    assert header["mocapedit:planAxes"] == ("x z" if up == "Y" else "x y")
    # The mapping agrees with the pixel centres: world -> pixel -> centre -> world.
    col, row = _to_pixel(matrix, [[37.0, 81.0]], up)[0]
    uc, vc = grid.centres()
    assert abs(uc[col] - 37.0) <= 0.5 * grid.pixel + 1e-9 and abs(vc[row] - 81.0) <= 0.5 * grid.pixel + 1e-9

    def at(name, uv):
        c, r = _to_pixel(matrix, np.atleast_2d(uv), up)[0]
        return float(ch[name][r, c])

    moved = _agent(scene, MOVED)
    other = _agent(scene, "/World/agent3")
    empty = _empty_spot(scene)
    for name in preview.CHANNELS:
        assert at(name, empty) == 0.0, name
    assert at("sourcePathDensity", other.source.ground[30]) >= 1
    assert at("editedPathDensity", other.source.ground[30]) >= 1
    assert at("displacement", other.source.ground[30]) == 0.0
    assert at("editedPathDensity", moved.edited.ground[30]) >= 1
    assert at("sourcePathDensity", moved.source.ground[42]) == 1
    assert at("editedPathDensity", moved.source.ground[42]) == 0, "agent1 left its source path"
    assert at("displacement", moved.edited.ground[-1]) == pytest.approx(DRIFT, abs=4.0)
    assert at("displacement", moved.edited.ground[24]) == pytest.approx(DRIFT * 24 / 47, abs=4.0)
    for p in scene.remaining.ground:
        assert at("overlapCount", p) >= 1
    assert ch["overlapCount"].sum() > 0
    # Overlaps lie between agent1's edited path and another agent, never far from agent1.
    rows, cols = np.nonzero(ch["overlapCount"])
    centres = np.stack([uc[cols], vc[rows]], axis=-1)
    near = np.min(np.linalg.norm(centres[:, None] - moved.edited.ground[None], axis=-1), axis=1)
    assert near.max() < 2 * moved.radius + 2 * grid.pixel


def test_composed_stage_previews_like_input_plus_edits(solved, tmp_path):
    _, stage, edits, composed = solved
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert run_cli("preview", stage, "--edits", edits, "-o", a, "--resolution", "300", "-q").returncode == 0
    proc = run_cli("preview", composed, "-o", b, "--resolution", "300", "-q")
    assert proc.returncode == 0, proc.stderr
    (ha, ca), (hb, cb) = _read_exr(a), _read_exr(b)
    np.testing.assert_allclose(ha["mocapedit:worldToPixel"], hb["mocapedit:worldToPixel"])
    for name in preview.CHANNELS:
        np.testing.assert_array_equal(ca[name], cb[name])
    assert ca["displacement"].max() > 0


def test_bounds_and_resolution_options(solved, tmp_path):
    scene, stage, edits, _ = solved
    out = tmp_path / "crop.exr"
    up = scene.up_axis
    # Only the lower-left part of the shot: a plan box around agent1's start.
    start = preview.plan(_agent(scene, MOVED).source.ground[0], up)
    box = [start[0] - 50, start[1] - 50, start[0] + 50, start[1] + 50]
    proc = run_cli("preview", stage, "--edits", edits, "-o", out, "--resolution", "200x100",
                   "--bounds", *box, "-q")
    assert proc.returncode == 0, proc.stderr
    header, ch = _read_exr(out)
    assert ch["sourcePathDensity"].shape == (100, 200)
    assert header["mocapedit:pixelSize"] == pytest.approx(1.0, rel=1e-6)   # 100 units on 100 rows
    far = _agent(scene, "/World/agent3").source.ground
    m = header["mocapedit:worldToPixel"]
    cr = _to_pixel(m, far, up)
    assert not np.any((cr[:, 0] >= 0) & (cr[:, 0] < 200) & (cr[:, 1] >= 0) & (cr[:, 1] < 100))
    c, r = _to_pixel(m, [_agent(scene, MOVED).source.ground[0]], up)[0]
    assert (c, r) == (100, 50)
    assert ch["sourcePathDensity"][r, c] >= 1


def test_preview_errors_name_the_problem(tmp_path, toy_stage):
    proc = run_cli("preview", toy_stage, "-o", tmp_path / "x.jpg")
    assert proc.returncode == 1 and ".png or .exr" in proc.stderr
    proc = run_cli("preview", toy_stage, "-o", tmp_path / "x.png", "--resolution", "big")
    assert proc.returncode == 1 and "--resolution" in proc.stderr
    proc = run_cli("preview", toy_stage, "-o", tmp_path / "x.png", "--bounds", "0", "0", "-1", "5")
    assert proc.returncode == 1 and "--bounds" in proc.stderr
    proc = run_cli("preview", toy_stage, "--edits", toy_stage, "-o", tmp_path / "x.png")
    assert proc.returncode == 1 and "not an edits layer" in proc.stderr
    assert not list(tmp_path.glob("*.png")) and not list(tmp_path.glob(".x*"))


def test_edits_of_another_shot_or_an_older_input_are_named(tmp_path, toy_stage):
    """An edits layer solved for another shot is refused (it drew that shot's constraints over
    this one, with USD warnings); one solved before the input changed is previewed with a note."""
    from conftest import write_toy_stage
    other = write_toy_stage(tmp_path / "other" / "crowd.usda", agents=5)
    edits = tmp_path / "other" / "crowd.edits.usda"
    solve(str(other), output=str(edits))
    proc = run_cli("preview", toy_stage, "--edits", edits, "-o", tmp_path / "x.png")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "was solved for" in proc.stderr and "crowd.usda" in proc.stderr and "shot.usda" in proc.stderr
    assert not (tmp_path / "x.png").exists()
    # The same shot, changed after its solve: previewed, with a note that says so.
    own = tmp_path / "shot.edits.usda"
    solve(str(toy_stage), output=str(own))
    assert "solved from" not in run_cli("preview", toy_stage, "--edits", own, "-o", tmp_path / "a.png").stderr
    toy_stage.write_text(toy_stage.read_text() + "\n")
    proc = run_cli("preview", toy_stage, "--edits", own, "-o", tmp_path / "b.png")
    assert proc.returncode == 0, proc.stderr
    assert "has changed since" in proc.stderr


def test_edits_of_a_shot_of_the_same_name_in_another_folder_are_refused(tmp_path, toy_stage):
    """seqA/shot.usda's edits over seqB/shot.usda: a note that the input changed, and the other
    shot's constraints drawn over this one; the inputs are told apart by where they are."""
    from conftest import write_toy_stage
    other = write_toy_stage(tmp_path / "seqB" / "shot.usda", agents=5)
    edits = tmp_path / "seqB" / "shot.edits.usda"
    solve(str(other), output=str(edits))
    proc = run_cli("preview", toy_stage, "--edits", edits, "-o", tmp_path / "x.png")
    assert proc.returncode == 1 and "was solved for" in proc.stderr and "seqB" in proc.stderr, proc.stderr
    assert not (tmp_path / "x.png").exists()


def test_a_composed_stage_with_edits_given_shows_those_edits_over_its_input(solved, tmp_path):
    """A composed stage and an edits layer given with --edits: the stage's own edits layer is left
    out and the given one shown over its input (it drew the composed stage as the source, "0
    edited"); given its own edits layer, the same picture as without --edits."""
    scene, stage, edits, composed = solved
    alone = preview.load(str(composed))
    again = preview.load(str(composed), str(edits))
    for got in (alone, again):
        assert got.edited
        for a, b in zip(got.crowd.agents, scene.crowd.agents):
            np.testing.assert_allclose(a.source.ground, b.source.ground, atol=1e-9)
            np.testing.assert_allclose(a.edited.ground, b.edited.ground, atol=1e-9)
    # Another edits layer of the same input, solved with other options, over the composed stage.
    other = tmp_path / "other.edits.usda"
    solve(str(stage), output=str(other), collisions=False, foot_locking=False)
    over = preview.load(str(composed), str(other))
    direct = preview.load(str(stage), str(other))
    for a, b in zip(over.crowd.agents, direct.crowd.agents):
        np.testing.assert_allclose(a.source.ground, b.source.ground, atol=1e-9)
        np.testing.assert_allclose(a.edited.ground, b.edited.ground, atol=1e-9)


def test_a_stage_without_edits_previews_its_source_paths(tmp_path, toy_stage):
    out = tmp_path / "src.png"
    proc = run_cli("preview", toy_stage, "-o", out)
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {out}" in proc.stderr
    with Image.open(out) as im:
        assert im.size[0] > 100 and "mocapedit:worldToPixel" in im.text


def test_quiet_silences_solve_and_preview(tmp_path, toy_stage):
    edits = tmp_path / "e.usda"
    proc = run_cli("solve", toy_stage, "-o", edits, "-q")
    assert proc.returncode == 0 and proc.stderr == "" and proc.stdout == ""
    proc = run_cli("preview", toy_stage, "--edits", edits, "-o", tmp_path / "p.png", "-q")
    assert proc.returncode == 0 and proc.stderr == "" and proc.stdout == ""
    loud = run_cli("preview", toy_stage, "--edits", edits, "-o", tmp_path / "p.png")
    assert "source paths: 3 agents in" in loud.stderr
    # A small image of a long, narrow shot: the equal aspect widens a fixed limit, and
    # matplotlib's log line about it was printed through -q.
    for resolution in ("300", "600", "200x800"):
        proc = run_cli("preview", toy_stage, "-o", tmp_path / "n.png", "-q", "--resolution", resolution)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr


@pytest.mark.parametrize("resolution", ["10", "3x2", "1000x1", "150x800"])
def test_a_png_too_small_for_its_legend_is_an_error_that_says_so(toy_stage, tmp_path, resolution):
    """It was an internal error (matplotlib: "Width and height specified must be non-negative")."""
    proc = run_cli("preview", toy_stage, "-o", tmp_path / "p.png", "--resolution", resolution)
    assert proc.returncode == 1 and "--resolution" in proc.stderr and "at least" in proc.stderr, proc.stderr
    assert "internal error" not in proc.stderr and not (tmp_path / "p.png").exists()
    exr = run_cli("preview", toy_stage, "-o", tmp_path / "p.exr", "--resolution", resolution, "-q")
    assert exr.returncode == 0, exr.stderr


@pytest.mark.parametrize("resolution", ["600", "300", "400x900", "1200x300"])
def test_small_and_narrow_images_keep_the_legend_inside(solved, tmp_path, resolution):
    """The legend's column is wide enough for its text at any size (at 600 pixels it was cut
    at the image's right edge: "collision left (1 pai")."""
    scene, *_ = solved
    out = tmp_path / "p.png"
    preview.write(scene, str(out), resolution)
    with Image.open(out) as im:
        rgb = np.asarray(im.convert("RGB")).astype(int)
    edge = rgb[:, -3:]
    assert (edge > 230).all(), "something is drawn at the right edge"


@pytest.mark.parametrize("resolution", ["800", "600", "300", "1200x300", "1600"])
def test_the_title_and_its_subtitle_do_not_overlap(solved, tmp_path, resolution):
    """Above the plot, the title and the line under it are two runs of ink with paper between
    (at 800 pixels the subtitle was drawn over the title's descenders)."""
    scene, *_ = solved
    out = tmp_path / "p.png"
    preview.write(scene, str(out), resolution)
    with Image.open(out) as im:
        grey = np.asarray(im.convert("L")).astype(int)
    h, w = grey.shape
    # The plot's frame: the first row, from the top, dark over a third of the image's width.
    frame = next(r for r in range(h) if (grey[r, : int(0.7 * w)] < 100).sum() > w / 3)
    ink = (grey[:frame - 1, : int(0.6 * w)] < 200).any(axis=1)
    runs = np.flatnonzero(np.diff(np.concatenate([[0], ink.astype(int), [0]])) == 1)
    assert len(runs) >= 2, f"one run of text rows above the plot ({ink.sum()} rows)"
    # Below the plot, the tick labels and the axis label, clear of the image's edge.
    last = max(r for r in range(h) if (grey[r, : int(0.7 * w)] < 100).sum() > w / 3)
    ink = (grey[last + 2:, : int(0.6 * w)] < 200).any(axis=1)
    runs = np.flatnonzero(np.diff(np.concatenate([[0], ink.astype(int), [0]])) == 1)
    assert len(runs) >= 2 and not ink[-1], "the axis label is cut at the bottom"


def test_preview_reports_progress_through_the_given_progress(solved, tmp_path):
    scene, stage, edits, _ = solved
    stream = io.StringIO()
    loaded = preview.load(str(stage), str(edits), Progress(stream=stream))
    preview.write(loaded, str(tmp_path / "p.exr"), 100, progress=Progress(stream=stream))
    text = stream.getvalue()
    for task in ("read agents", "source paths", "edited paths", "overlaps", "rasterize paths"):
        assert f"\n{task}: " in "\n" + text, task
    assert ground.up_index(scene.up_axis) in (1, 2)


def test_preview_marks_agents_that_spin_or_walk_back(solved, tmp_path):
    scene, *_ = solved
    agent = next(a for a in scene.crowd.agents if a.edited_flag)
    figures = scene.report.agents.setdefault(agent.path, {})
    figures["plausibility"] = {"spinFrames": 3, "worstTurnFrame": 5, "maxDirectionDeviation": 120.0,
                               "worstDirectionFrame": 9}
    marks = preview.implausible_marks(scene.report, scene.crowd)
    assert [(k, p) for k, _, p in marks] == [("spin", agent.path), ("reverse", agent.path)]
    np.testing.assert_allclose(marks[0][1], preview._edited_at_frame(agent, 5))
    np.testing.assert_allclose(marks[1][1], preview._edited_at_frame(agent, 9))
    scene.implausible = marks
    preview.write_png(scene, str(tmp_path / "marked.png"), resolution=400)
    with Image.open(tmp_path / "marked.png") as img:
        assert img.size[0] > 0
    # Within the limits (or not measured): no mark.
    figures["plausibility"] = {"spinFrames": 0, "maxDirectionDeviation": 45.0}
    assert preview.implausible_marks(scene.report, scene.crowd) == []
    figures["plausibility"] = {"spinFrames": 0, "maxDirectionDeviation": float("nan")}
    assert preview.implausible_marks(scene.report, scene.crowd) == []
    assert preview.implausible_marks(None, scene.crowd) == []


def _region(shape, local_to_world, radius=0.0, size=(0.0, 0.0, 0.0)):
    from mocapedit.model.data import AvoidRegion
    return AvoidRegion("/R", shape, radius, np.array(size, dtype=float), 0.1, [], np.asarray(local_to_world, float),
                       None, None)


def test_region_footprint_is_the_one_the_solve_avoids():
    # A 2 x 1.2 box turned 30 degrees about Y and moved to (-1, 0, -3) on a Y-up stage.
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    m = np.array([[c, 0, -s, 0], [0, 1, 0, 0], [s, 0, c, 0], [-1, 0, -3, 1]])
    poly = preview.region_footprint(_region("box", m, size=(2.0, 1.0, 1.2)), "Y")
    corners = ground.to_ground(np.array([[x, 0, z, 1] for x in (-1, 1) for z in (-0.6, 0.6)]) @ m[:, :3], "Y")
    assert len(poly) == 4
    assert sorted(map(tuple, np.round(poly, 9))) == sorted(map(tuple, np.round(corners, 9)))
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    assert area == pytest.approx(2.4)                      # counter-clockwise
    # A circle scaled by 2 on a Z-up stage: 96 points at twice its radius around its centre.
    m = np.diag([2.0, 2.0, 2.0, 1.0])
    m[3, :3] = (4.0, 5.0, 0.0)
    ring = preview.region_footprint(_region("circle", m, radius=0.5), "Z")
    assert len(ring) == 96
    np.testing.assert_allclose(np.linalg.norm(ring - (4.0, 5.0), axis=1), 1.0, atol=1e-12)
