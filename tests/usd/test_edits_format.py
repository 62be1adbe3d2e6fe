"""Tests for mocapedit.usd.edits_format: what mocapedit records in customLayerData, written and read in one place."""
from __future__ import annotations

import json

import pytest
from pxr import Sdf, Usd

from mocapedit import __version__
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline import processor
from mocapedit.usd import edits_format

from conftest import write_toy_stage


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("edits_format")
    shot = write_toy_stage(tmp / "shot.usda", agents=2)
    result = processor.solve(str(shot), output=str(tmp / "shot.edits.usda"), composed=str(tmp / "composed.usda"))
    return tmp, shot, result


def test_write_puts_the_version_first_and_data_reads_it_back():
    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert edits_format.data(layer) is None
    edits_format.write(layer, {"bvh": {"source": "a.bvh"}})
    assert edits_format.data(layer) == {"version": __version__, "bvh": {"source": "a.bvh"}}
    assert dict(layer.customLayerData) == {"mocapedit": {"version": __version__, "bvh": {"source": "a.bvh"}}}
    layer.customLayerData = {"mocapedit": "not a dictionary"}
    assert edits_format.data(layer) is None


def test_report_text_is_compact_sorted_and_finite():
    assert edits_format.report_text({"b": float("nan"), "a": [1.0, float("inf")]}) == '{"a":[1.0,null],"b":null}'


def test_an_edits_layer_reads_back(solved):
    tmp, shot, result = solved
    edits = tmp / "shot.edits.usda"
    layer = Sdf.Layer.FindOrOpen(str(edits))
    digest = processor.content_hash(Usd.Stage.Open(str(shot)))
    assert edits_format.content_hash(layer) == digest
    assert edits_format.recorded(str(edits)) == (digest, processor.options_text())
    assert edits_format.stored_report(layer) == json.loads(edits_format.report_text(result.report.to_layer_dict()))
    for source in (str(edits), layer, str(tmp / "composed.usda")):
        read = edits_format.read_report(source)
        assert read["file"] == layer.identifier
        assert read["contentHash"] == digest and read["version"] == __version__
        assert read["inputs"][0].endswith("shot.usda")
        assert (read["upAxis"], read["metersPerUnit"]) == ("Z", pytest.approx(0.01))
        assert read["report"] == edits_format.stored_report(layer)
    composed = Usd.Stage.Open(str(tmp / "composed.usda"))
    assert edits_format.edits_layer(composed).identifier == layer.identifier
    assert edits_format.edits_layer(Usd.Stage.Open(str(shot))) is None


def test_the_hash_of_an_open_stage_with_unsaved_changes_is_of_what_was_solved(tmp_path):
    """solve(stage) on a stage changed in memory recorded the hash of the file on disk: once
    the change was saved, the layer said its input had changed since, and a batch re-solved."""
    shot = write_toy_stage(tmp_path / "shot.usda", agents=2)
    on_disk = processor.content_hash(Usd.Stage.Open(str(shot)))
    stage = Usd.Stage.Open(str(shot))
    stage.GetRootLayer().customLayerData = {"note": "changed in memory"}
    result = processor.solve(stage, output=str(tmp_path / "shot.edits.usda"))
    recorded = edits_format.content_hash(Sdf.Layer.FindOrOpen(str(tmp_path / "shot.edits.usda")))
    assert recorded != on_disk
    stage.GetRootLayer().Save()
    assert processor.content_hash(Usd.Stage.Open(str(shot))) == recorded
    assert result.report is not None


def test_what_is_not_an_edits_layer_says_so(solved, tmp_path):
    tmp, shot, _ = solved
    assert edits_format.recorded(str(tmp_path / "missing.usda")) == (None, None)
    garbage = tmp_path / "garbage.usda"
    garbage.write_text("#usda 1.0\n(\n  this is not usda\n")
    assert edits_format.recorded(str(garbage)) == (None, None)
    with pytest.raises(MocapEditError, match="missing.usda: no such file"):
        edits_format.read_report(str(tmp_path / "missing.usda"))
    with pytest.raises(MocapEditError, match="garbage.usda: cannot be read as a USD layer"):
        edits_format.read_report(str(garbage))
    with pytest.raises(MocapEditError, match=r"holds no mocapedit report \(customLayerData mocapedit.report\)"):
        edits_format.read_report(str(shot))
    bad = Sdf.Layer.CreateAnonymous(".usda")
    edits_format.write(bad, {"report": "{not json"})
    with pytest.raises(MocapEditError, match="customLayerData mocapedit.report is not valid JSON"):
        edits_format.read_report(bad)


def test_values_that_are_none_are_left_out_so_usd_writes_no_warning(tmp_path, capfd):
    # A shot where no agent walks has no worst-walking agent: the report says null, the layer
    # leaves the key out (USD would print a warning for each empty entry as it writes).
    stats = edits_format.layer_value({"maxDirectionDeviationAgent": None, "agents": 2,
                                      "nested": {"worst": None, "figures": [1.5, 2.0]}})
    assert stats == {"agents": 2, "nested": {"figures": [1.5, 2.0]}}
    layer = Sdf.Layer.CreateAnonymous(".usda")
    edits_format.write(layer, {"stats": stats})
    capfd.readouterr()
    assert layer.Export(str(tmp_path / "edits.usda"))
    assert "Warning" not in capfd.readouterr().err
    assert edits_format.data(Sdf.Layer.FindOrOpen(str(tmp_path / "edits.usda")))["stats"]["agents"] == 2


def test_figures_that_are_not_finite_are_left_out_of_the_layer_and_null_in_the_report_json():
    """A shot whose moved agents have no foot skate to compare has no mean skate ratio: the layer
    wrote ``double meanFootSkateRatio = nan`` into its data and ``--report`` wrote ``NaN``, which
    strict JSON readers refuse. The layer leaves it out; the JSON says null."""
    import math
    from mocapedit.model.report import Report
    stats = edits_format.layer_value({"meanFootSkateRatio": float("nan"), "agents": 2, "worst": float("inf")})
    assert stats == {"agents": 2}
    report = Report(input="shot.usda")
    report.stats.extra["meanFootSkateRatio"] = math.nan
    def refuse(name):
        raise ValueError(name)
    text = report.to_json()
    assert json.loads(text, parse_constant=refuse)["stats"]["meanFootSkateRatio"] is None
