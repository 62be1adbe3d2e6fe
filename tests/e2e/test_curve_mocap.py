"""Path curves on real motion capture (../shared/mocap): a CMU take that stands, shuffles
sideways and back, walks off and stops, put on a curve drawn from where it starts along the way
it walks, in a Z-up centimetre shot at 30 fps. Measured on the composed stage: the body turns no
faster than the curve asks, nothing is sent back the way it came, and the locked feet slide no
more than the source's (issue #17's bar, 0.5 cm/s)."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

from mocapedit.data import examples
from mocapedit.formats import bvh
from mocapedit.inspect import metrics
from mocapedit.pipeline.processor import solve
from mocapedit.usd import bvh_usd, evaluate

from conftest import SHARED_MOCAP

TAKE = "cmu131_01_start_walk_stop"

pytestmark = [pytest.mark.realdata,
              pytest.mark.skipif(not (SHARED_MOCAP / f"{TAKE}.bvh").exists(), reason="../shared/mocap is absent")]


def test_a_real_start_walk_stop_on_a_curve_turns_with_the_curve_only(tmp_path):
    (tmp_path / "clips").mkdir()
    bvh_usd.import_bvh(str(SHARED_MOCAP / f"{TAKE}.bvh"), str(tmp_path / "clips" / f"{TAKE}.usda"),
                       bvh_usd.ImportSettings(scale=bvh.UNITS["cmu"] / 0.01, up_axis="Z", agent=True))
    stage = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(30.0)
    stage.SetFramesPerSecond(30.0)
    agent = "/World/Crowd/walker"
    stage.DefinePrim(agent).GetReferences().AddReference(f"./clips/{TAKE}.usda", layerOffset=Sdf.LayerOffset())
    times = evaluate.sample_times(stage, agent)
    stage.SetStartTimeCode(float(times[0]))
    stage.SetEndTimeCode(float(times[-1]))
    ground = metrics.to_ground(evaluate.agent_root_positions(stage, [agent], times)[0], "Z")
    start, way = ground[0], ground[-1] - ground[0]
    way /= np.linalg.norm(way)
    left = np.array([-way[1], way[0]])
    # Along the way it walks for 1.5 m, then a quarter turn to the left over about 3 m.
    points = [start, start + 150.0 * way, start + 250.0 * way + 100.0 * left, start + 250.0 * way + 300.0 * left]
    examples.add_path_curve(stage, "/Curves/arc", [(p[0], p[1], 0.0) for p in points], [agent],
                            basis="bezier", wrap="nonperiodic")
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usdc"), composed=str(tmp_path / "c.usda"))
    entry = result.report.agents[agent]
    figures = entry["plausibility"]
    assert not figures["reverses"]
    # The curve turns the walk by 90 degrees over about 2 s: well under 150 degrees per second
    # more than the source (336 before the shuffle kept its heading).
    assert figures["maxExtraFacingRate"] < 150.0, figures
    assert entry["footSkateEdited"] <= entry["footSkateSource"] + 0.5
