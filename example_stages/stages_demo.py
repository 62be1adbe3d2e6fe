"""The stage `make demo` solves: a small Z-up, centimetre shot with a few edits on it.

- ``demo_shot.usda`` sub-layers ``crowd_zup_cm.usda`` (the input crowd, untouched) and adds
  the artist's edits in its own root layer, as a shot layer in a pipeline would:
  ``agent_0000`` keeps its start but its last frame is pinned 30 degrees to its left, so its
  walk bends; ``agent_0001`` must be where it was at frame 0; and collision avoidance is on,
  so the walkers that cross in the source crowd step around each other.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Sdf, Usd

from mocapedit.data import examples
from mocapedit.usd import evaluate

CROWD = "/World/Crowd"


def demo_shot(out: Path) -> None:
    crowd = out / "crowd_zup_cm.usda"
    if not crowd.exists():  # make_stages writes the crowd first; build it when run alone
        import importlib.util
        spec = importlib.util.spec_from_file_location("make_stages", Path(__file__).with_name("make_stages.py"))
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module._zup_cm_stage(out, "usda")
    source = Usd.Stage.Open(str(crowd))
    start = evaluate.agent_root_positions(source, f"{CROWD}/agent_0000", [0.0])[0]
    end = evaluate.agent_root_positions(source, f"{CROWD}/agent_0000", [119.0])[0]
    other = evaluate.agent_root_positions(source, f"{CROWD}/agent_0001", [0.0])[0]
    a = np.radians(30.0)
    turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    bent = start[:2] + turn @ (end[:2] - start[:2])

    path = out / "demo_shot.usda"
    layer = Sdf.Layer.CreateNew(str(path))
    layer.subLayerPaths.append("crowd_zup_cm.usda")
    src_root = source.GetRootLayer()
    for key in ("upAxis", "metersPerUnit"):
        layer.pseudoRoot.SetInfo(key, src_root.pseudoRoot.GetInfo(key))
    layer.timeCodesPerSecond = src_root.timeCodesPerSecond
    layer.framesPerSecond = src_root.framesPerSecond
    layer.startTimeCode = src_root.startTimeCode
    layer.endTimeCode = src_root.endTimeCode
    layer.defaultPrim = "World"
    stage = Usd.Stage.Open(layer)
    stage.SetEditTarget(Usd.EditTarget(layer))
    r = lambda v: tuple(float(round(x, 4)) for x in v)  # noqa: E731
    examples.add_position_constraint(stage, "/Edits/keepStart", f"{CROWD}/agent_0000", 0, r(start))
    examples.add_position_constraint(stage, "/Edits/bendLeft", f"{CROWD}/agent_0000", 119,
                                     r((bent[0], bent[1], start[2])))
    examples.add_position_constraint(stage, "/Edits/holdStart", f"{CROWD}/agent_0001", 0, r(other))
    examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (Sdf.ValueTypeNames.Bool, True),
        "margin": (Sdf.ValueTypeNames.Double, 5.0),
    })
    layer.Save()


STAGES = {"demo_shot.usda": demo_shot}
