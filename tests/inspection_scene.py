"""A small shot for the inspection tests, and a hand-written pass that edits it the way
the solve passes report (conventions of the report and the guides).

Four toy agents 100 units apart. The pass drags agent1's path sideways (0 at the start,
DRIFT at the end) so that it crosses agent2 and agent3, and reports: a met hard position
constraint with its handle, an unmet soft relative constraint, a solver and a note.
The stage also holds an avoid region, a group, a stationary range on agent0's clip and
an unsolved position constraint.
"""
from __future__ import annotations

import numpy as np
from pxr import Gf, Usd, UsdGeom

from mocapedit.geometry import ground
from mocapedit.model.report import ConstraintEntry
from mocapedit.pipeline import processor
from mocapedit.pipeline.passes import Pass
from mocapedit.usd import schema
from mocapedit.pipeline.processor import EditedPath

from conftest import write_toy_stage

DRIFT = 160.0
MOVED = "/World/agent1"
REGION_CENTRE = (150.0, 50.0)      # ground (u, v)
REGION_RADIUS = 40.0


def write_scene(path, up_axis="Z"):
    write_toy_stage(path, agents=4, up_axis=up_axis)
    stage = Usd.Stage.Open(str(path))
    c = schema.PositionConstraint.Define(stage, "/Edits/here")
    c.CreateAgentRel().SetTargets([MOVED])
    c.CreateFrameAttr(40)
    loose = schema.PositionConstraint.Define(stage, "/Edits/unsolved")
    loose.CreateAgentRel().SetTargets(["/World/agent0"])
    loose.CreateFrameAttr(10)
    loose.CreatePositionAttr(tuple(ground.from_ground(np.array([60.0, -40.0]), 0.0, up_axis)))
    r = schema.RelativeConstraint.Define(stage, "/Edits/rel")
    r.CreateAgentRel().SetTargets(["/World/agent2"])
    r.CreateFrameAttr(20)
    r.CreateTargetRel().SetTargets(["/World/agent3"])
    r.CreateTargetFrameAttr(20)
    r.CreateOffsetAttr((0.0, 0.0, 0.0))   # on top of each other: the soft link the group pulls apart
    g = schema.AgentGroup.Define(stage, "/Edits/group")
    g.CreateMembersRel().SetTargets(["/World/agent2", "/World/agent3"])
    region = schema.AvoidRegion.Define(stage, "/Edits/fountain")
    region.CreateRadiusAttr(REGION_RADIUS)
    region.CreateMarginAttr(10.0)
    UsdGeom.XformCommonAPI(region.GetPrim()).SetTranslate(
        tuple(ground.from_ground(np.array(REGION_CENTRE), 0.0, up_axis)))
    anim = stage.GetPrimAtPath("/World/agent0/Skel/Anim")
    anim.ApplyAPI("MocapStationaryAPI", "pause")
    anim.GetAttribute("stationary:pause:frames").Set(Gf.Vec2i(10, 20))
    stage.GetRootLayer().Save()
    return path


def drag_pass(ctx):
    traj = ctx.trajectories[MOVED]
    g = traj.ground.copy()
    g[:, 1] -= np.linspace(0.0, DRIFT, len(g))
    ctx.paths[MOVED] = EditedPath(ground=g, heading=traj.heading)
    up = ctx.data.info.up_axis
    ctx.report.constraints.append(ConstraintEntry(
        prim="/Edits/here", kind="position", agent=MOVED, frame=40, hard=True, residual=0.0, met=True,
        position=ground.from_ground(g[40], 0.0, up).tolist()))
    ctx.report.constraints.append(ConstraintEntry(
        prim="/Edits/rel", kind="relative", agent="/World/agent2", frame=20,
        target="/World/agent3", target_frame=20, hard=False, residual=3.5, met=False))
    entry = ctx.report.agent(MOVED)
    entry.solver = "LDLT"
    entry.notes = ["fell back to nothing: a test note"]
    ctx.report.note("a run-wide note")


def install_pass(monkeypatch, fn=drag_pass):
    monkeypatch.setattr(processor, "PASSES", (Pass("test-drag", fn),))
