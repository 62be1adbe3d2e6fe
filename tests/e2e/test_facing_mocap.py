"""Facing after path edits on real motion capture (../shared/mocap): long CMU clips with
idles, slow turns and hops, bent by three hard handles, never spin where their source does not
(15 degrees per frame at 60 fps, scaled), measured by UsdSkel FK on the composed stage."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from mocapedit.formats import bvh
from mocapedit.usd import bvh_usd
from mocapedit.data import examples
from mocapedit.inspect import metrics
from mocapedit.tools import measure
from mocapedit.usd import evaluate
from mocapedit.pipeline.processor import solve

from conftest import SHARED_MOCAP, shot_over_clip

CLIPS = {"cmu131_01_start_walk_stop": ("cmu", "Y"), "cmu131_03_start_hop_stop": ("cmu", "Z"),
         "cc_cmu02_04_jump_balance": ("cm", "Y")}

pytestmark = [pytest.mark.realdata,
              pytest.mark.skipif(not all((SHARED_MOCAP / f"{n}.bvh").exists() for n in CLIPS),
                                 reason="../shared/mocap is absent")]


def _bent(tmp_path, name, unit, up, scale):
    """The clip as an agent, with hard handles at a quarter, half and three quarters of it,
    moved by ``scale`` times (0.6, 0.4), (-1.0, 0.8), (0.7, -0.5) metres on the ground."""
    bvh_usd.import_bvh(str(SHARED_MOCAP / f"{name}.bvh"), str(tmp_path / "clip.usda"),
                       bvh_usd.ImportSettings(scale=bvh.UNITS[unit] / 0.01, up_axis=up, agent=True))
    clip = Usd.Stage.Open(str(tmp_path / "clip.usda"))
    agent = clip.GetDefaultPrim().GetPath()
    stage = shot_over_clip(tmp_path / "shot.usda", clip, up)
    stage.GetRootLayer().subLayerPaths.append("./clip.usda")
    times, hips = evaluate.joint_world_matrices(clip, agent)
    n = len(times)
    for k, (f, move) in enumerate({n // 4: (0.6, 0.4), n // 2: (-1.0, 0.8), 3 * n // 4: (0.7, -0.5)}.items()):
        at = metrics.to_ground(hips[f, 3, :3], up) + scale * np.array(move) / 0.01
        p = metrics.from_ground(at, hips[f, 3, metrics.ground_axes(up)[0]], up)
        examples.add_position_constraint(stage, f"/Edits/handle{k}", agent, int(f), tuple(map(float, p)))
    stage.GetRootLayer().Save()
    return str(tmp_path / "shot.usda"), str(agent)


@pytest.mark.parametrize("name", sorted(CLIPS))
@pytest.mark.parametrize("scale", [0.25, 1.0])
def test_real_clips_bent_by_three_handles_never_spin(tmp_path, name, scale):
    shot, agent = _bent(tmp_path, name, *CLIPS[name], scale)
    result = solve(shot, output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert all(c["residual"] < 1e-6 for c in result.report.constraints)
    p = measure.plausibility(Usd.Stage.Open(shot), Usd.Stage.Open(str(tmp_path / "c.usda")), agent)
    assert p.spin_frames == 0, p
    # At most 4 degrees per frame at 60 fps more than the source turns (tangent headings: 88 to
    # 160; a slow frame's own turn counted in full, before its neighbours smoothed it: up to 6.5).
    assert p.max_extra_facing_rate < 4.0 * 60.0, p
    assert result.report.agents[agent]["plausibility"]["spinFrames"] == 0


GROUP_WALK = "cc_cmu07_01_walk"


@pytest.mark.skipif(not (SHARED_MOCAP / f"{GROUP_WALK}.bvh").exists(), reason="../shared/mocap is absent")
def test_a_group_of_real_walkers_turned_90_degrees_walks_round_the_corner(tmp_path):
    """Six CMU walkers (60 fps, Z-up centimetres) in rows of two, one group; the front-left
    one's second half turned 90 degrees about its middle. The members follow it round the corner;
    none walks back against the turn the edit makes, none spins."""
    bvh_usd.import_bvh(str(SHARED_MOCAP / f"{GROUP_WALK}.bvh"), str(tmp_path / "walk.usda"),
                       bvh_usd.ImportSettings(scale=bvh.UNITS["cm"] / 0.01, up_axis="Z", agent=True))
    clip = Usd.Stage.Open(str(tmp_path / "walk.usda"))
    stage = shot_over_clip(tmp_path / "shot.usda", clip, "Z")
    names = [f"/World/Crowd/m{r}{c}" for r in range(3) for c in range(2)]
    for p in names:
        stage.DefinePrim(p).GetReferences().AddReference("./walk.usda")
    t, hips = evaluate.joint_world_matrices(stage, names[0])
    g = metrics.to_ground(hips[:, 3, :3], "Z")
    forward = (g[-1] - g[0]) / np.linalg.norm(g[-1] - g[0])
    side = np.array([-forward[1], forward[0]])
    for k, p in enumerate(names):
        at = -120.0 * (k // 2) * forward + 100.0 * (k % 2) * side
        UsdGeom.Xformable(stage.GetPrimAtPath(p)).AddTranslateOp().Set((float(at[0]), float(at[1]), 0.0))
    examples.add_group(stage, "/Edits/rows", names)
    n, half = len(t), len(t) // 2
    quarter = np.array([[0.0, -1.0], [1.0, 0.0]])
    for name, f, at in (("start", 0, g[0]), ("middle", half, g[half]), ("end", n - 1, g[half] + quarter @ (g[-1] - g[half]))):
        examples.add_position_constraint(stage, f"/Edits/{name}", names[0], f, (float(at[0]), float(at[1]), float(hips[f, 3, 2])))
    stage.GetRootLayer().Save()
    result = solve(str(tmp_path / "shot.usda"), output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    assert max(c["residual"] for c in result.report.constraints) < 1e-6
    figures = measure.shot_plausibility(Usd.Stage.Open(str(tmp_path / "shot.usda")),
                                        Usd.Stage.Open(str(tmp_path / "c.usda")), names)
    assert figures[0].max_edit_turn == pytest.approx(90.0, abs=5.0)   # the leader turned the corner
    for f in figures:   # the rows behind follow, the last ones reaching the corner as the clip ends
        assert 30.0 < f.max_edit_turn < metrics.REVERSE_TURN_DEGREES, f
        assert not f.reverses and f.spin_frames == 0, f   # the leader's corner: 69 degrees at most
    assert result.report.stats["plausibility"]["reversingAgents"] == 0
