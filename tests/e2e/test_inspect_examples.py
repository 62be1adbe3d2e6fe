"""Guides, report and previews on every stage example_stages/make_stages.py writes, solved
with whatever passes the package has."""
from __future__ import annotations

import importlib.util
import json

import numpy as np
import OpenEXR
import pytest
from PIL import Image
from pxr import Usd, UsdValidation

from mocapedit.tools import preview
from mocapedit.model import report
from mocapedit.usd import edits_format
from mocapedit.usd.report_io import read_report
from mocapedit.pipeline.processor import solve

from conftest import REPO, run_cli


def _make_stages_module():
    spec = importlib.util.spec_from_file_location("mocapedit_make_stages", REPO / "example_stages" / "make_stages.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def solved_examples(tmp_path_factory):
    """Every example stage, solved: (stage, edits, composed, result)."""
    out = tmp_path_factory.mktemp("examples")
    stages = _make_stages_module().make_stages(out)
    assert len(stages) >= 2
    solved = []
    for stage in stages:
        edits = out / f"{stage.stem}.edits.usda"
        composed = out / f"{stage.stem}.edited.usda"
        solved.append((stage, edits, composed, solve(str(stage), output=str(edits), composed=str(composed))))
    return solved


def test_guides_validate_and_show_every_agent(solved_examples):
    context = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    for stage_path, edits, composed, result in solved_examples:
        for path in (edits, composed):
            stage = Usd.Stage.Open(str(path))
            errors = [f"{e.GetName()}: {e.GetMessage()}" for e in context.Validate(stage)
                      if e.GetType() == UsdValidation.ValidationErrorType.Error]
            assert not errors, f"{path.name}: {errors}"
        stage = Usd.Stage.Open(str(composed))
        src = stage.GetPrimAtPath("/MocapEdit/Guides/SourcePaths")
        assert src, stage_path.name
        assert len(src.GetAttribute("curveVertexCounts").Get()) == result.report.stats["agents"], stage_path.name
        for prim in stage.GetPrimAtPath("/MocapEdit/Guides").GetChildren():
            assert prim.GetAttribute("purpose").Get() == "guide"
            assert prim.GetAttribute("extent").HasAuthoredValue(), prim.GetPath()


def test_every_agent_keeps_its_feet_within_the_bar_of_its_source_on_every_example(solved_examples):
    """Issue #17's bar, agent by agent, as solved by default (foot locking on): the feet slide
    during contacts no more than the source's plus 0.5 cm/s, whatever moved the agent (a path
    edit, avoidance, a stand walked off in a new direction)."""
    for stage_path, _, _, result in solved_examples:
        metres = Usd.Stage.Open(str(stage_path)).GetMetadata("metersPerUnit")
        for path, entry in result.report.agents.items():
            if entry.foot_skate_edited is None:
                continue
            over = (entry.foot_skate_edited - entry.foot_skate_source) * metres
            assert over <= 0.005 + 1e-9, f"{stage_path.name}: {path} slides {100 * over:.2f} cm/s over its source"


def test_report_reads_back_on_every_example(solved_examples):
    for stage_path, edits, _, result in solved_examples:
        stored = read_report(str(edits))
        assert stored.report.to_layer_dict() == json.loads(edits_format.report_text(result.report.to_layer_dict())), \
            stage_path.name
        text = report.format_text(stored, show_all=True)
        for agent in result.data.agents:
            assert f"\n{agent}  (" in text, f"{stage_path.name}: {agent} missing from the report"
    proc = run_cli("report", solved_examples[0][1], "--json")
    assert proc.returncode == 0 and json.loads(proc.stdout)["stats"]["agents"] > 0


def test_previews_put_paths_and_collisions_where_they_are(solved_examples, tmp_path):
    for stage_path, _, composed, _ in solved_examples:
        scene = preview.load(str(composed))
        up = scene.up_axis
        exr = tmp_path / f"{stage_path.stem}.exr"
        grid = preview.write(scene, str(exr), resolution=400)
        f = OpenEXR.File(str(exr), separate_channels=True)
        ch = {k: c.pixels for k, c in f.channels().items()}
        m = f.header()["mocapedit:worldToPixel"]

        def pixel(uv):
            ab = preview.plan(np.atleast_2d(uv), up)
            col, row = np.floor((np.c_[ab, np.ones(len(ab))] @ m)[:, :2]).astype(int)[0]
            return row, col

        for agent in scene.crowd.agents:
            mid = agent.source.ground[len(agent.source.ground) // 2]
            assert ch["sourcePathDensity"][pixel(mid)] >= 1, f"{stage_path.name}: {agent.path}"
            mid = agent.edited.ground[len(agent.edited.ground) // 2]
            assert ch["editedPathDensity"][pixel(mid)] >= 1, f"{stage_path.name}: {agent.path}"
        # Nothing is drawn in the corners, which the padding keeps empty.
        for name in preview.CHANNELS:
            assert ch[name][0, 0] == 0 and ch[name][-1, -1] == 0, f"{stage_path.name}: {name}"
        if len(scene.remaining.a):
            for p in scene.remaining.ground:
                assert ch["overlapCount"][pixel(p)] >= 1, stage_path.name
        else:
            assert ch["overlapCount"].sum() == 0, stage_path.name
        assert grid.width == 400 or grid.height == 400

        png = tmp_path / f"{stage_path.stem}.png"
        matrix = preview.write(scene, str(png), resolution=700)
        with Image.open(png) as im:
            img = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        ab = preview.plan(np.array([a.edited.ground[len(a.edited.ground) // 2] for a in scene.crowd.agents]), up)
        for col, row in np.floor((np.c_[ab, np.ones(len(ab))] @ matrix)[:, :2]).astype(int):
            win = img[row - 2:row + 3, col - 2:col + 3].reshape(-1, 3)
            assert win.min() < 0.8, f"{stage_path.name}: no path drawn at ({col}, {row})"
