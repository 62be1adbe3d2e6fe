"""Example stages for path edits (position and relative constraints, stationary tags, path
curves, groups). All Y-up, metres, 24 fps; the walker walks along +Z before its yaw.

- ``path_edit.usda``: three 10 m walks side by side. ``walker_b`` has its start and end
  pinned and its middle dragged 1 m sideways; ``walker_c`` has its first third pinned and
  its end moved 2.5 m to the right, so it turns right; ``walker_a`` is left alone.
- ``path_spline.usda``: ``follower`` walks along an S-shaped Catmull-Rom curve;
  ``stopper`` (walk, stand, walk on, its stand tagged stationary) follows a Bezier arc
  and also has its last frame pinned off the curve.
- ``path_stationary.usda``: a walk with a 36-frame stand tagged stationary; the stand is
  moved 0.5 m sideways and the end 2 m, so the path bends around a stand that moves and
  turns as one piece.
- ``path_handshake.usda``: two walkers stop and stand 1.5 m apart; a relative constraint
  in the host's heading frame puts the guest 0.8 m in front of the host (a little to its
  right) in the middle of the stand, both starts pinned: both bend their paths to meet.
- ``path_formation.usda``: 14 walkers in a block of 7 rows of 2, one group. The front-left
  walker's first half is pinned straight and its end moved to make a 90-degree left turn;
  the group turns with it, the rows following round the corner, and keeps its formation.
- ``path_relay.usda``: a relay of 52 walkers, each handing over to the next at its last
  frame (the next one's first frame, side by side, one hard relative constraint each);
  the first start and the last end are pinned, the last moved 6 m to the side, and the
  middle runner's middle frame is dragged 3 m sideways: the whole chain bends.
- ``path_long_stand.usda`` (Z-up, centimetres, 60 fps): a 10 s walk with a 4 s stand in
  the middle that is not tagged stationary, its root jittering by a few millimetres as
  captured roots do; three handles bend it: the start held, one in the stand moved 0.8 m
  sideways (the walk there turned about its start, keeping its length), the end moved as much
  (the walk after the stand goes on its way, 0.8 m aside). The body turns with the first walk
  and back, smoothly through the stand.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Usd

from mocapedit.data import examples, walker

FPS = 24.0
CROWD = "/World/Crowd"


def _save(stage: Usd.Stage) -> None:
    stage.GetRootLayer().Save()


def _walk(name: str, frames: int = 193, speed: float = 1.25) -> walker.Clip:
    return walker.walk(frames=frames, fps=FPS, speed=speed, name=name)


def path_edit(out: Path) -> None:
    clip = _walk("path_walk")   # 10 m along +Z
    agents = [examples.AgentSpec("walker_a", clip, (-1.5, 0.0, 0.0)),
              examples.AgentSpec("walker_b", clip, (0.0, 0.0, 0.0)),
              examples.AgentSpec("walker_c", clip, (1.5, 0.0, 0.0))]
    stage = examples.build_crowd_stage(out / "path_edit.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips")
    b, c = f"{CROWD}/walker_b", f"{CROWD}/walker_c"
    examples.add_position_constraint(stage, "/Edits/b_start", b, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/b_middle", b, 96, (1.0, 0.0, 5.0))
    examples.add_position_constraint(stage, "/Edits/b_end", b, 192, (0.0, 0.0, 10.0))
    examples.add_position_constraint(stage, "/Edits/c_start", c, 0, (1.5, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/c_third", c, 64, (1.5, 0.0, float(clip.translations[64, 0, 2])))
    examples.add_position_constraint(stage, "/Edits/c_end", c, 192, (4.0, 0.0, 9.5))
    _save(stage)


def path_spline(out: Path) -> None:
    clip = _walk("path_walk")
    stop_go, stand = walker.walk_idle_walk(frames=192, fps=FPS, stop_frame=80, idle_frames=36,
                                           name="path_stop_go")
    agents = [examples.AgentSpec("follower", clip, (0.0, 0.0, 0.0)),
              examples.AgentSpec("stopper", stop_go, (4.0, 0.0, 0.0))]
    stage = examples.build_crowd_stage(out / "path_spline.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips", stationary={"path_stop_go": {"stand": stand}})
    examples.add_path_curve(stage, "/Curves/s_curve",
                            [(0, 0, 0), (1.0, 0, 3.0), (-0.5, 0, 6.0), (1.0, 0, 9.0), (0, 0, 12.0)],
                            [f"{CROWD}/follower"])
    examples.add_path_curve(stage, "/Curves/arc", [(4, 0, 0), (4, 0, 4), (6, 0, 7), (9, 0, 7)],
                            [f"{CROWD}/stopper"], basis="bezier", wrap="nonperiodic")
    examples.add_position_constraint(stage, "/Edits/stopper_end", f"{CROWD}/stopper", 191, (7.0, 0.0, 7.3))
    _save(stage)


def path_stationary(out: Path) -> None:
    stop_go, stand = walker.walk_idle_walk(frames=192, fps=FPS, stop_frame=80, idle_frames=36,
                                           name="path_stop_go")
    agents = [examples.AgentSpec("pauser", stop_go, (0.0, 0.0, 0.0))]
    stage = examples.build_crowd_stage(out / "path_stationary.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips", stationary={"path_stop_go": {"stand": stand}})
    p = f"{CROWD}/pauser"
    reach = float(stop_go.translations[97, 0, 2])
    end = float(stop_go.translations[-1, 0, 2])
    examples.add_position_constraint(stage, "/Edits/start", p, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/stand", p, 97, (0.5, 0.0, reach))
    examples.add_position_constraint(stage, "/Edits/end", p, 191, (2.0, 0.0, end - 0.3))
    _save(stage)


def path_handshake(out: Path) -> None:
    clip, (stop, last) = walker.walk_idle_walk(frames=150, fps=FPS, stop_frame=70, idle_frames=56,
                                               name="path_meet")
    reach = float(clip.translations[stop, 0, 2])
    # The host walks +Z and stops at z = 0; the guest walks -Z (yaw 180) and stops 0.8 m
    # further on and 1.5 m to the host's left: without the constraint they stand apart.
    agents = [examples.AgentSpec("host", clip, (0.0, 0.0, -reach)),
              examples.AgentSpec("guest", clip, (1.5, 0.0, 0.8 + reach), 180.0)]
    stage = examples.build_crowd_stage(out / "path_handshake.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips", stationary={"path_meet": {"stand": (stop, last)}})
    host, guest = f"{CROWD}/host", f"{CROWD}/guest"
    examples.add_position_constraint(stage, "/Edits/host_start", host, 0, (0.0, 0.0, -reach))
    examples.add_position_constraint(stage, "/Edits/guest_start", guest, 0, (1.5, 0.0, 0.8 + reach))
    # In the host's heading frame: 0.8 m ahead of it, 0.15 m to its right (ground v is -z).
    middle = (stop + last) // 2
    examples.add_relative_constraint(stage, "/Edits/handshake", guest, middle, host, middle, (0.8, 0.0, 0.15),
                                     space="target")
    _save(stage)


def path_formation(out: Path) -> None:
    clip = _walk("path_walk")   # 10 m along +Z
    agents, names = [], []
    for row in range(7):
        for col in range(2):
            name = f"m{row}{col}"
            agents.append(examples.AgentSpec(name, clip, (1.0 * col, 0.0, -1.2 * row)))
            names.append(f"{CROWD}/{name}")
    stage = examples.build_crowd_stage(out / "path_formation.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips")
    examples.add_group(stage, "/Edits/formation", names, stiffness=1.0)
    lead = f"{CROWD}/m00"
    half = float(clip.translations[96, 0, 2])
    examples.add_position_constraint(stage, "/Edits/lead_start", lead, 0, (0.0, 0.0, 0.0))
    examples.add_position_constraint(stage, "/Edits/lead_quarter", lead, 48,
                                     (0.0, 0.0, float(clip.translations[48, 0, 2])))
    examples.add_position_constraint(stage, "/Edits/lead_half", lead, 96, (0.0, 0.0, half))
    # The one edit: the leader's last frame moved so the second half turns 90 degrees left.
    examples.add_position_constraint(stage, "/Edits/lead_turn", lead, 192, (10.0 - half, 0.0, half))
    _save(stage)


RELAY_RUNNERS = 52


def path_relay(out: Path) -> None:
    clip = walker.walk(frames=96, fps=FPS, speed=1.5, name="path_relay_leg")   # 5.7 m per leg
    leg = float(clip.translations[-1, 0, 2])
    agents = []
    for k in range(RELAY_RUNNERS):
        # Laid out roughly end to end; the constraints make the hand-overs exact.
        x = 0.4 * np.sin(0.7 * k)
        agents.append(examples.AgentSpec(f"r{k:02d}", clip, (round(x, 6), 0.0, round(k * (leg + 0.3), 6)),
                                         time_offset=95.0 * k))
    stage = examples.build_crowd_stage(out / "path_relay.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips")
    for k in range(RELAY_RUNNERS - 1):
        # Runner k's last frame is side by side with runner k+1's first: 0.4 m to its right.
        examples.add_relative_constraint(stage, f"/Edits/handover{k:02d}", f"{CROWD}/r{k:02d}", 95,
                                         f"{CROWD}/r{k + 1:02d}", 0, (0.4, 0.0, 0.0))
    first, last = agents[0], agents[-1]
    examples.add_position_constraint(stage, "/Edits/first_start", f"{CROWD}/r00", 0, first.position)
    end = np.array(last.position) + (6.0, 0.0, leg - 4.0)
    examples.add_position_constraint(stage, "/Edits/last_end", f"{CROWD}/r{RELAY_RUNNERS - 1:02d}", 95,
                                     tuple(np.round(end, 6)))
    mid = RELAY_RUNNERS // 2
    at = np.array(agents[mid].position) + (3.0, 0.0, float(clip.translations[48, 0, 2]))
    examples.add_position_constraint(stage, "/Edits/middle", f"{CROWD}/r{mid:02d}", 48, tuple(np.round(at, 6)))
    _save(stage)


def long_stand_clip() -> tuple[walker.Clip, tuple[int, int]]:
    """Walk 3.3 s, stand 4 s, walk on (60 fps, Z-up, cm); the root jitters by up to 3 mm
    (uniform, seeded) through the stand."""
    clip, (first, last) = walker.walk_idle_walk(frames=600, fps=60.0, stop_frame=200, idle_frames=240,
                                                up="Z", meters_per_unit=0.01, name="path_long_stand")
    rng = np.random.default_rng(16)
    jitter = rng.uniform(-0.3, 0.3, size=(last - first + 1, 2))
    clip.translations[first:last + 1, 0, :2] += np.round(jitter, 3)
    return clip, (first, last)


#: The frames of the long stand's handles: its start, inside the stand, its end.
LONG_STAND_FRAMES = {"start": 0, "stand": 320, "end": 599}


def long_stand_handles(clip: walker.Clip, aside: float = 80.0) -> dict[str, tuple[int, tuple[float, float]]]:
    """Name -> (frame, ground offset, cm) of the long stand's handles: the start held; the stand
    moved ``aside`` sideways by turning the walk to it about its start (its length kept); the
    end moved as much (the walk after the stand keeps its way and length)."""
    start, stand = (clip.translations[LONG_STAND_FRAMES[k], 0, :2].astype(np.float64) for k in ("start", "stand"))
    reach = stand - start
    turn = np.arcsin(aside / np.linalg.norm(reach))
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    moved = tuple(float(v) for v in np.round(rot @ reach - reach, 3))
    return {"start": (LONG_STAND_FRAMES["start"], (0.0, 0.0)), "stand": (LONG_STAND_FRAMES["stand"], moved),
            "end": (LONG_STAND_FRAMES["end"], moved)}


def path_long_stand(out: Path, handles: dict | None = None) -> None:
    """``handles``: name -> (frame, ground offset) instead of :func:`long_stand_handles`'."""
    clip, _ = long_stand_clip()
    stage = examples.build_crowd_stage(out / "path_long_stand.usda", [examples.AgentSpec("stander", clip)],
                                       up_axis="Z", meters_per_unit=0.01, fps=60.0, clips_dir=out / "clips")
    for name, (frame, (dx, dy)) in (handles or long_stand_handles(clip)).items():
        x, y, z = (float(v) for v in clip.translations[frame, 0])
        examples.add_position_constraint(stage, f"/Edits/{name}", f"{CROWD}/stander", frame,
                                         (round(x + dx, 6), round(y + dy, 6), 0.0))
    _save(stage)


STAGES = {"path_edit.usda": path_edit, "path_spline.usda": path_spline,
          "path_stationary.usda": path_stationary, "path_handshake.usda": path_handshake,
          "path_formation.usda": path_formation, "path_relay.usda": path_relay,
          "path_long_stand.usda": path_long_stand}
