"""Collision avoidance on a crowd of real motion capture (../shared/mocap): two flows of CMU
walks crossing at right angles, with people standing in the middle (takes that wash, balance, or
walk off and stop), in a Z-up centimetre shot at 30 fps whose clips are referenced with time
offsets, placed at random so that nobody overlaps where the shot starts. Measured by UsdSkel
FK on the composed stage: everyone parted, nobody sent round in a loop or back the way they
came, paths barely longer, and locked feet sliding no more than the source's (issue #17's bar,
0.5 cm/s)."""
from __future__ import annotations

import random

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

from mocapedit.formats import bvh
from mocapedit.inspect import metrics
from mocapedit.pipeline.processor import solve
from mocapedit.tools import measure
from mocapedit.usd import bvh_usd, evaluate

from conftest import SHARED_MOCAP

WALKS = {"cc_cmu07_01_walk": "cm", "cc_cmu07_04_slow_walk": "cm", "cc_cmu07_12_brisk_walk": "cm",
         "cc_cmu02_01_walk": "cm", "cmu131_01_start_walk_stop": "cmu"}
STANDS = {"cc_cmu02_10_wash_self": "cm", "cc_cmu02_04_jump_balance": "cm"}
FPS = 30.0
RADIUS = 30.0           # stage units (cm): the schema's default capsule, 0.3 m
APART = 90.0            # where the shot starts, nobody is closer than this (cm)

pytestmark = [pytest.mark.realdata,
              pytest.mark.skipif(not all((SHARED_MOCAP / f"{n}.bvh").exists() for n in {**WALKS, **STANDS}),
                                 reason="../shared/mocap is absent")]


def _clips(folder) -> dict[str, str]:
    folder.mkdir()
    out = {}
    for name, unit in {**WALKS, **STANDS}.items():
        bvh_usd.import_bvh(str(SHARED_MOCAP / f"{name}.bvh"), str(folder / f"{name}.usda"),
                           bvh_usd.ImportSettings(scale=bvh.UNITS[unit] / 0.01, up_axis="Z", agent=True))
        out[name] = f"./{folder.name}/{name}.usda"
    return out


def crowd(tmp_path, seed: int, walkers: int = 30, standers: int = 6):
    """The shot (see the module doc): ``walkers`` in each flow over 11 x 8 m, ``standers`` in
    the 5 m square where the flows cross."""
    clips = _clips(tmp_path / "clips")
    rng = random.Random(seed)
    stage = Usd.Stage.CreateNew(str(tmp_path / "crowd.usda"))
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(FPS)
    stage.SetFramesPerSecond(FPS)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(8 * FPS)
    starts: list[np.ndarray] = []
    names: list[str] = []

    def place(clip: str, at, yaw: float, offset: float) -> None:
        path = f"/World/Crowd/a{len(names):03d}"
        prim = stage.DefinePrim(path)
        prim.GetReferences().AddReference(clips[clip], layerOffset=Sdf.LayerOffset(offset=offset))
        xf = UsdGeom.Xformable(prim)
        translate = xf.AddTranslateOp()
        xf.AddRotateZOp().Set(yaw)
        for _ in range(200):
            translate.Set(tuple(map(float, at)) + (0.0,))
            start = evaluate.agent_root_positions(stage, path, [0.0])[0, :2]
            if all(np.linalg.norm(start - s) >= APART for s in starts):
                starts.append(start)
                names.append(path)
                return
            at = (at[0] + rng.uniform(-120, 120), at[1] + rng.uniform(-120, 120))
        stage.RemovePrim(path)

    for flow in range(2):
        for _ in range(walkers):
            a, b = rng.uniform(-550, 550), rng.uniform(-900, -250)
            place(rng.choice(sorted(WALKS)), (a, b) if flow == 0 else (-b, a),
                  (0.0 if flow == 0 else 90.0) + rng.uniform(-8, 8), -rng.uniform(0, 40))
    for _ in range(standers):
        place(rng.choice(sorted(STANDS)), (rng.uniform(-250, 250), rng.uniform(-250, 250)),
              rng.uniform(0, 360), -rng.uniform(0, 30))
    settings = stage.DefinePrim("/Edits/settings", "MocapSolveSettings")
    settings.CreateAttribute("collisionAvoidance", Sdf.ValueTypeNames.Bool, custom=False,
                             variability=Sdf.VariabilityUniform).Set(True)
    stage.GetRootLayer().Save()
    return stage, names


@pytest.mark.parametrize("seed", [1, 3, 8])
def test_a_real_crowd_crossing_is_parted_without_loops_and_keeps_its_feet(tmp_path, seed):
    stage, names = crowd(tmp_path, seed)
    result = solve(str(tmp_path / "crowd.usda"), output=str(tmp_path / "e.usdc"), composed=str(tmp_path / "c.usda"))
    stats = result.report.stats
    assert stats["collisionsPerIteration"][0] > 10, "the crowd must need avoidance"
    edited = Usd.Stage.Open(str(tmp_path / "c.usda"))
    times = np.arange(0.0, 8 * FPS + 1)
    bases = evaluate.agent_root_positions(edited, names, times)
    bases[..., metrics.ground_axes("Z")[0]] = 0.0
    sep = metrics.min_separation(bases, RADIUS, 180.0, "Z")
    assert sep.overlaps == 0, (sep.agents, sep.clearance)
    moved = [p for p in names if p in result.report.agents and result.report.agents[p].edited]
    figures = measure.shot_plausibility(stage, edited, moved)
    assert not [f.agent for f in figures if f.reverses]
    ratios = np.array([f.length_ratio for f in figures])
    assert ratios.mean() < 1.02 and ratios.max() < 1.3, (ratios.mean(), names[int(np.argmax(ratios))])
    skate = np.array([(f.foot_skate_source, f.foot_skate_edited) for f in figures])
    skate = skate[np.isfinite(skate).all(axis=1)]
    assert skate[:, 1].mean() <= skate[:, 0].mean() + 0.5, skate.mean(axis=0)
