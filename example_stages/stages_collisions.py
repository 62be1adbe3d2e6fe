"""Example stages for collision avoidance and avoid regions.

- ``collisions_head_on.usda``: two agents walking straight at each other on one line; they
  meet at frame 68.
- ``collisions_crossing.usda``: two perpendicular streams of 64 walkers each cross in the
  middle of the shot (as in figure 6.2 of the deliverable); four of them have their first
  and last frames pinned by hard position constraints (artist marks).
- ``avoid_regions.usda``: 24 walkers cross a plaza holding a fountain (a circle region), a
  roped-off rectangle (a box region, rotated) and a kiosk (the footprint of a Cube prim).
- ``collisions_corridor.usda``: a 3 m corridor between two walls (box regions); two
  walkers each way meet head-on in it, two of them on one line.
- ``collisions_counterflow.usda``: a 6 m street; 16 walkers east and 16 west in random
  lanes, staggered, so the two flows thread through each other.
- ``collisions_bottleneck.usda``: 12 walkers eastwards in lanes 5 m wide meet a 2.4 m gap
  between two box regions; the outer lanes must squeeze in between the inner ones.
- ``collisions_groups.usda``: two 3 x 3 formations (MocapAgentGroup, 1.3 m spacing) cross
  each other at right angles in the middle of the shot.

All of them are Y-up, in metres, at 24 fps, and carry a MocapSolveSettings prim that turns
collision avoidance on. The walkers come from :mod:`mocapedit.data.walker`; positions and
phases come from a seeded generator, so every run writes the same bytes.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, UsdGeom

from mocapedit.data import examples, walker

FPS = 24.0
FRAMES = 120
SPEED = 1.4


def _walks(count: int, frames: int = FRAMES):
    """Walk clips with different gait phases, so neighbours do not step in unison (stages
    that share the clips folder ask for the same count, so each clip name has one phase)."""
    return [walker.walk(frames=frames, fps=FPS, speed=SPEED, up="Y", meters_per_unit=1.0,
                        phase=k / count, name=f"walk_collide_{k}") for k in range(count)]


def _settings(stage, margin: float = 0.05) -> None:
    vt = Sdf.ValueTypeNames
    examples.define_mocap_prim(stage, "/World/MocapSettings", "MocapSolveSettings", attributes={
        "collisionAvoidance": (vt.Bool, True), "margin": (vt.Double, margin)})


def _stage(out: Path, name: str, agents):
    """A Y-up metre crowd stage of ``agents`` with collision avoidance on (not saved yet)."""
    stage = examples.build_crowd_stage(out / name, agents, up_axis="Y", meters_per_unit=1.0, fps=FPS,
                                       clips_dir=out / "clips")
    _settings(stage)
    return stage


def _heading_yaw(direction) -> float:
    """rotateY angle (degrees) that turns the walker's +Z towards a ground direction (x, z)."""
    return float(np.degrees(np.arctan2(direction[0], direction[1])))


def head_on(out: Path) -> None:
    (walk,) = _walks(1)
    agents = [examples.AgentSpec("agent_0000", walk, (0.0, 0.0, -4.0), 0.0),
              examples.AgentSpec("agent_0001", walk, (0.0, 0.0, 4.0), 180.0)]
    stage = _stage(out, "collisions_head_on.usda", agents)
    stage.GetRootLayer().Save()


def crossing(out: Path) -> None:
    walks = _walks(4)
    rng = np.random.default_rng(62)
    spacing, rows = 2.0, 8
    lattice = (np.arange(rows) - (rows - 1) / 2) * spacing
    agents = []
    travel = SPEED * (FRAMES - 1) / FPS
    # Stream east (+x) and stream north (-z): both lattices are centred on the origin at
    # mid-shot.
    for stream, (direction, across) in enumerate((((1.0, 0.0), (0.0, 1.0)), ((0.0, -1.0), (1.0, 0.0)))):
        d, c = np.array(direction), np.array(across)
        for i in lattice:
            for j in lattice:
                jitter = rng.uniform(-0.35, 0.35, size=2)
                start = d * (j - travel / 2) + c * i + jitter
                yaw = _heading_yaw(d) + rng.uniform(-4.0, 4.0)
                agents.append(examples.AgentSpec(
                    f"agent_{len(agents):04d}", walks[int(rng.integers(len(walks)))],
                    (float(start[0]), 0.0, float(start[1])), float(yaw)))
    stage = _stage(out, "collisions_crossing.usda", agents)
    # Artist marks: where four agents start and end must not move.
    for k in (0, 27, 64, 100):
        name = agents[k].name
        walk = agents[k].clip
        yaw = np.radians(agents[k].yaw)
        for frame in (0, FRAMES - 1):
            local = walk.translations[frame, 0].astype(np.float64)   # the root joint's ground position
            x = agents[k].position[0] + local[0] * np.cos(yaw) + local[2] * np.sin(yaw)
            z = agents[k].position[2] - local[0] * np.sin(yaw) + local[2] * np.cos(yaw)
            examples.add_position_constraint(stage, f"/World/Marks/{name}_f{frame}", f"/World/Crowd/{name}",
                                             frame, (float(x), 0.0, float(z)))
    stage.GetRootLayer().Save()


def avoid_regions(out: Path) -> None:
    walks = _walks(4)
    rng = np.random.default_rng(7)
    agents = []
    travel = SPEED * (FRAMES - 1) / FPS
    for k in range(24):
        lane = (k % 12 - 5.5) * 1.2 + rng.uniform(-0.2, 0.2)
        if k < 12:   # westwards across the plaza, through the fountain and the ropes
            start, yaw = (travel / 2, 0.0, lane), -90.0
        else:        # northwards, through the kiosk
            start, yaw = (lane, 0.0, travel / 2), 180.0
        agents.append(examples.AgentSpec(f"agent_{k:04d}", walks[k % 3], start, yaw + rng.uniform(-3, 3)))
    stage = _stage(out, "avoid_regions.usda", agents)
    vt = Sdf.ValueTypeNames
    fountain = examples.define_mocap_prim(stage, "/World/Regions/fountain", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "circle"), "radius": (vt.Double, 1.2), "margin": (vt.Double, 0.1)})
    UsdGeom.Xformable(fountain).AddTranslateOp().Set(Gf.Vec3d(0.5, 0.0, 1.5))
    ropes = examples.define_mocap_prim(stage, "/World/Regions/ropes", "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(2.0, 1.0, 1.2)),
        "margin": (vt.Double, 0.1)})
    xf = UsdGeom.Xformable(ropes)
    xf.AddTranslateOp().Set(Gf.Vec3d(-1.0, 0.0, -3.0))
    xf.AddRotateYOp().Set(30.0)
    kiosk = UsdGeom.Cube.Define(stage, "/World/Set/kiosk")
    kiosk.GetSizeAttr().Set(1.5)
    kiosk.AddTranslateOp().Set(Gf.Vec3d(-3.5, 0.75, 2.5))
    examples.define_mocap_prim(stage, "/World/Regions/kiosk", "MocapAvoidRegion",
                               attributes={"margin": (vt.Double, 0.1)},
                               relationships={"geometry": ["/World/Set/kiosk"]})
    stage.GetRootLayer().Save()


def _box_region(stage, path: str, centre, size) -> None:
    vt = Sdf.ValueTypeNames
    prim = examples.define_mocap_prim(stage, path, "MocapAvoidRegion", attributes={
        "shape": (vt.Token, "box"), "size": (vt.Double3, Gf.Vec3d(*size)), "margin": (vt.Double, 0.05)})
    UsdGeom.Xformable(prim).AddTranslateOp().Set(Gf.Vec3d(*centre))


def _flow(walks, rng, count: int, direction, lanes: tuple[float, float], spread: float, first: int = 0):
    """``count`` walkers walking along ground ``direction`` (x, z), centred on the origin at
    mid-shot, in random lanes across it and staggered ``spread`` metres along it."""
    d = np.asarray(direction, dtype=np.float64)
    across = np.array([-d[1], d[0]])
    travel = SPEED * (FRAMES - 1) / FPS
    agents = []
    for k in range(count):
        lane = rng.uniform(*lanes)
        start = d * (-travel / 2 + (k / max(count - 1, 1) - 0.5) * spread) + across * lane
        agents.append(examples.AgentSpec(
            f"agent_{first + k:04d}", walks[int(rng.integers(len(walks)))],
            (float(start[0]), 0.0, float(start[1])), _heading_yaw(d) + rng.uniform(-2.0, 2.0)))
    return agents


def corridor(out: Path) -> None:
    walks = _walks(4)
    travel = SPEED * (FRAMES - 1) / FPS
    agents = []
    for k, (lane, along, way) in enumerate(((0.0, 0.0, 1.0), (0.6, -2.5, 1.0), (0.0, 0.0, -1.0),
                                            (-0.7, 1.5, -1.0))):
        x = way * (along - travel / 2)
        agents.append(examples.AgentSpec(f"agent_{k:04d}", walks[k % 2], (x, 0.0, lane),
                                         _heading_yaw((way, 0.0))))
    stage = _stage(out, "collisions_corridor.usda", agents)
    for name, z in (("north", -2.0), ("south", 2.0)):
        _box_region(stage, f"/World/Regions/wall_{name}", (0.0, 0.5, z), (2.0 * travel, 1.0, 1.0))
    stage.GetRootLayer().Save()


def counterflow(out: Path) -> None:
    walks = _walks(4)
    rng = np.random.default_rng(16)
    agents = _flow(walks, rng, 16, (1.0, 0.0), (-2.4, 2.4), 14.0)
    agents += _flow(walks, rng, 16, (-1.0, 0.0), (-2.4, 2.4), 14.0, first=16)
    stage = _stage(out, "collisions_counterflow.usda", agents)
    stage.GetRootLayer().Save()


def bottleneck(out: Path) -> None:
    walks = _walks(4)
    rng = np.random.default_rng(5)
    agents = _flow(walks, rng, 12, (1.0, 0.0), (-2.5, 2.5), 12.0)
    stage = _stage(out, "collisions_bottleneck.usda", agents)
    for name, z in (("north", -3.7), ("south", 3.7)):
        _box_region(stage, f"/World/Regions/{name}", (0.0, 0.5, z), (1.0, 1.0, 5.0))
    stage.GetRootLayer().Save()


def groups(out: Path) -> None:
    walks = _walks(4)
    rng = np.random.default_rng(9)
    travel = SPEED * (FRAMES - 1) / FPS
    agents, members = [], []
    for g, direction in enumerate(((1.0, 0.0), (0.0, -1.0))):
        d = np.array(direction)
        across = np.array([-d[1], d[0]])
        names = []
        for i in range(3):
            for j in range(3):
                start = d * ((i - 1) * 1.3 - travel / 2) + across * (j - 1) * 1.3 + rng.uniform(-0.1, 0.1, 2)
                name = f"agent_{len(agents):04d}"
                agents.append(examples.AgentSpec(name, walks[int(rng.integers(len(walks)))],
                                                 (float(start[0]), 0.0, float(start[1])), _heading_yaw(d)))
                names.append(f"/World/Crowd/{name}")
        members.append(names)
    stage = _stage(out, "collisions_groups.usda", agents)
    for g, names in enumerate(members):
        examples.add_group(stage, f"/World/Groups/group_{g}", names)
    stage.GetRootLayer().Save()


STAGES = {
    "collisions_head_on.usda": head_on,
    "collisions_crossing.usda": crossing,
    "avoid_regions.usda": avoid_regions,
    "collisions_corridor.usda": corridor,
    "collisions_counterflow.usda": counterflow,
    "collisions_bottleneck.usda": bottleneck,
    "collisions_groups.usda": groups,
}
