"""Example stages for time edits (MocapTimeConstraint, MocapSyncConstraint).

- ``time_handshake.usda``: two walkers come towards each other, stop and stand face to
  face. At rest the second one arrives 16 time codes late; a hard sync constraint makes
  the frames where both stop play at the same shot time, so each is re-timed half way
  (8 time codes) and they reach the handshake together.
- ``time_beats.usda``: one walk re-timed so that three left heel strikes land on three
  beats of a soundtrack (shot times 24, 44 and 72): the walk hurries between the first
  two beats and slows down between the last two, smoothly.
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


def handshake(out: Path) -> None:
    clip, (stop, _) = walker.walk_idle_walk(frames=96, fps=FPS, stop_frame=50, idle_frames=44,
                                            name="handshake_walk")
    reach = float(clip.translations[stop, 0, 2])   # metres walked (along root-local +Z) until the stop
    gap, side, yaw = 0.8, 0.15, 60.0               # face to face, right hands level
    a = np.radians(yaw)
    ahead = np.array([np.sin(a), 0.0, np.cos(a)])  # the host's forward: rotateY turns +Z to it
    right = -np.array([np.cos(a), 0.0, -np.sin(a)])
    host_stop = -ahead * gap / 2 - right * side
    guest_stop = ahead * gap / 2 + right * side
    agents = [
        examples.AgentSpec("host", clip, tuple(np.round(host_stop - ahead * reach, 6)), yaw),
        # The guest comes the other way, 16 time codes late.
        examples.AgentSpec("guest", clip, tuple(np.round(guest_stop + ahead * reach, 6)), yaw + 180.0,
                           time_offset=16.0),
    ]
    stage = examples.build_crowd_stage(out / "time_handshake.usda", agents, up_axis="Y", fps=FPS,
                                       clips_dir=out / "clips",
                                       stationary={clip.name: {"handshake": (stop, stop + 43)}})
    examples.add_sync_constraint(stage, "/Edits/handshake", f"{CROWD}/guest", stop, f"{CROWD}/host", stop, 0.0)
    _save(stage)


def beats(out: Path) -> None:
    clip = walker.walk(frames=120, fps=FPS, name="beats_walk")
    left = clip.foot_joints.index("Root/Hips/LeftUpLeg/LeftLeg/LeftFoot")
    strikes = np.flatnonzero(np.diff(clip.foot_contacts[:, left].astype(int)) == 1) + 1
    stage = examples.build_crowd_stage(out / "time_beats.usda", [examples.AgentSpec("dancer", clip)],
                                       up_axis="Y", fps=FPS, clips_dir=out / "clips")
    for i, (frame, time) in enumerate(zip(strikes[:3], (24.0, 44.0, 72.0))):
        examples.add_time_constraint(stage, f"/Edits/beat{i + 1}", f"{CROWD}/dancer", int(frame), time)
    _save(stage)


STAGES = {"time_handshake.usda": handshake, "time_beats.usda": beats}
