"""A clip whose first frame is its rest pose far from the walk (as many captures are exported: a
T-pose at the origin, then the take): the jump from that frame to the next is a cut, not a motion.
Bent by handles (one at the first frame of the take, one 0.65 s later), the body turns smoothly by the edit, with no pop where that jump would leave the
windows that measure the edit's rotation. Measured by UsdSkel FK on the composed stage."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from bvhgen import walk_idle_walk, write_bvh
from mocapedit.data import examples
from mocapedit.geometry import trajectory
from mocapedit.inspect import metrics
from mocapedit.pipeline.processor import solve
from mocapedit.usd import bvh_usd, evaluate


def _shot(tmp_path, cut: bool, walk1: float = 2.0, idle: float = 0.5, handles=None):
    """A generated walk (60 fps, centimetres, Y-up), its first frame a T-pose 3 m away when
    ``cut``, bent by hard handles: ``handles(n)`` gives {frame: ground move (cm)}, by default
    four, the first at the take's first frame."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    rig, values, _ = walk_idle_walk(fps=60.0, walk1=walk1, idle=idle, walk2=2.0)
    if cut:
        values[0] = 0.0
        values[0, :3] = (200.0, 95.0, -300.0)          # the Hips position channels come first
    write_bvh(tmp_path / "take.bvh", rig, values)
    bvh_usd.import_bvh(str(tmp_path / "take.bvh"), str(tmp_path / "clip.usda"),
                       bvh_usd.ImportSettings(scale=1.0, up_axis="Y", agent=True))
    clip = Usd.Stage.Open(str(tmp_path / "clip.usda"))
    agent = clip.GetDefaultPrim().GetPath()
    stage = Usd.Stage.CreateNew(str(tmp_path / "shot.usda"))
    UsdGeom.SetStageUpAxis(stage, "Y")
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(60.0)
    stage.SetStartTimeCode(clip.GetStartTimeCode())
    stage.SetEndTimeCode(clip.GetEndTimeCode())
    stage.GetRootLayer().subLayerPaths.append("./clip.usda")
    times, hips = evaluate.joint_world_matrices(clip, agent)
    n = len(times)
    moves = handles(n) if handles else {1: (0.0, 0.0), 40: (50.0, 0.0), n // 2: (-60.0, 20.0), 4 * n // 5: (50.0, -30.0)}
    for k, (f, move) in enumerate(moves.items()):
        at = metrics.to_ground(hips[f, 3, :3], "Y") + np.array(move)
        p = metrics.from_ground(at, hips[f, 3, 1], "Y")
        examples.add_position_constraint(stage, f"/Edits/handle{k}", agent, int(f), tuple(map(float, p)))
    stage.GetRootLayer().Save()
    return str(tmp_path / "shot.usda"), str(agent)


def _edit_turn_steps(tmp_path, cut: bool, **options) -> np.ndarray:
    """Degrees the edit's turn of the body changes by from frame to frame, over the first walk
    (frames 1 to 90, before it slows down to stand); ``options`` go to the solve."""
    shot, agent = _shot(tmp_path, cut)
    solve(shot, output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"), **options)
    _, ms = evaluate.joint_world_matrices(Usd.Stage.Open(shot), agent)
    _, me = evaluate.joint_world_matrices(Usd.Stage.Open(str(tmp_path / "c.usda")), agent)
    turn = np.degrees(metrics.body_facing(me, "Y") - metrics.body_facing(ms, "Y"))
    return np.abs(np.diff(turn[1:91]))


def test_a_cut_in_the_source_makes_no_pop_in_the_edit(tmp_path):
    clean = _edit_turn_steps(tmp_path / "clean", False)
    cut = _edit_turn_steps(tmp_path / "cut", True)
    # The same turns as the take without the rest frame, to a tenth of a degree per frame
    # (the handle 0.65 s in bends the walk by up to 2.1 degrees per frame either way).
    assert np.abs(cut - clean).max() < 0.1, (int(np.argmax(np.abs(cut - clean))) + 1, float(cut.max()))
    assert cut.max() < 3.0


def test_the_cut_is_what_the_limit_leaves_out(tmp_path, monkeypatch):
    """Counted as a motion, the cut's 3.6 m step outweighs the walk's steps in every window that
    holds it, and the path edit turns the body 13 degrees in one frame where it leaves them (the
    body carried rigidly along the edited path: pivoting on the feet spreads the turn over the
    step, which would hide it)."""
    monkeypatch.setattr(trajectory, "CUT_SPEED_M", np.inf)
    assert _edit_turn_steps(tmp_path, True, pivot_on_feet=False).max() > 5.0
    monkeypatch.undo()
    assert _edit_turn_steps(tmp_path / "limited", True, pivot_on_feet=False).max() < 3.0


def test_feet_locked_next_to_a_cut_do_not_pull_the_body_down(tmp_path):
    """The ease into the first contact of the take reached back over the cut to the rest frame,
    whose hips stand 3.6 m from the plant: the pelvis dropped by the 3 m it took the leg to
    reach, easing out over the take's first frames."""
    shot, agent = _shot(tmp_path, True, walk1=0.0, idle=1.0)   # planted from the take's first frame
    result = solve(shot, output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"))
    _, ms = evaluate.joint_world_matrices(Usd.Stage.Open(shot), agent)
    _, me = evaluate.joint_world_matrices(Usd.Stage.Open(str(tmp_path / "c.usda")), agent)
    drop = ms[:, 3, 1] - me[:, 3, 1]                   # hips height, centimetres
    assert result.report.stats.foot_locked_agents == 1
    assert drop.max() < 8.0 + 1e-6, (int(np.argmax(drop)), float(drop.max()))
    assert result.report.stats.max_pelvis_drop < 8.0 + 1e-6


def _bent_walk(tmp_path, cut: bool, hold_first: bool, notes: list | None = None):
    """(source, edited) hips ground paths (F,2) of a walk bent 1 m sideways at its middle,
    held at its last frame, and at its first frame when ``hold_first``; the report's notes are
    added to ``notes``."""
    def handles(n):
        return {**({0: (0.0, 0.0)} if hold_first else {}), n // 2: (0.0, 100.0), n - 1: (0.0, 0.0)}
    shot, agent = _shot(tmp_path, cut, walk1=4.0, idle=0.0, handles=handles)
    result = solve(shot, output=str(tmp_path / "e.usda"), composed=str(tmp_path / "c.usda"), foot_locking=False)
    if notes is not None:
        notes.extend(result.report.notes)
    _, ms = evaluate.joint_world_matrices(Usd.Stage.Open(shot), agent)
    _, me = evaluate.joint_world_matrices(Usd.Stage.Open(str(tmp_path / "c.usda")), agent)
    return metrics.to_ground(ms[:, 3, :3], "Y"), metrics.to_ground(me[:, 3, :3], "Y")


def test_a_handle_on_the_rest_frame_before_a_cut_holds_that_frame_and_leaves_the_take_its_shape(tmp_path):
    """A handle on a clip's first frame, where the clip keeps its rest pose 3 m from the take,
    holds that frame. The take after the cut is bent by its own handles as if the rest frame
    were not there: the cut's 3.6 m step, kept rigid in the take's local frame, swung the rest
    frame round as the bend turned the take, and the held frame dragged the take's start back,
    squeezing its steps up to the bend to 0.77 of their length. (A CMU slow walk bent 1 m so
    slid its locked feet 4.8 cm/s more than its source.)"""
    notes, clean_notes = [], []
    source, cut = _bent_walk(tmp_path / "cut", True, hold_first=True, notes=notes)
    _, clean = _bent_walk(tmp_path / "clean", False, hold_first=True, notes=clean_notes)
    # The report says the handle holds the rest frame alone, and where the take starts.
    said = [n for n in notes if "</Edits/handle0> holds frame 0" in n]
    assert len(said) == 1 and "nearest frame is 1" in said[0], notes
    assert not [n for n in clean_notes if "cut off" in n]
    _, clean = _bent_walk(tmp_path / "free", False, hold_first=False)
    assert np.linalg.norm(cut[0] - source[0]) < 1e-6                      # held
    assert np.linalg.norm(cut[1:] - clean[1:], axis=1).max() < 1.0, np.linalg.norm(cut[1:] - clean[1:], axis=1).max()
    # The take's steps up to the bend, a quarter second at a time, against the source's: free to
    # turn about the bend, that part keeps its length.
    def steps(path):
        return np.linalg.norm(path[16:180:15] - path[1:165:15], axis=1)
    ratio = steps(cut) / steps(source)
    assert 0.98 < ratio.min() and ratio.max() < 1.02, (ratio.min(), ratio.max())
