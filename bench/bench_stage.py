"""Whole stage: 1,000 agents x 240 frames x 31 joints, read-solve-write with edits.

Target (DESIGN.md): under 20 s and under 2 GB. The edits: 100 agents get a pinned start and a
moved end, 50 get a time constraint, a 10-member group is turned, collision avoidance is on.
The solve runs as `mocapedit solve` in a child process, so its peak memory is its own.
Peer: the same stage solved with no edits authored (read, trajectories, inspection, write).
"""
from __future__ import annotations

import dataclasses
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from pxr import Sdf, Usd

from mocapedit.data import examples, walker

FINGERS = 9  # the walker's 22 joints plus finger joints: 31


def _with_fingers(clip: walker.Clip) -> walker.Clip:
    hand = next(i for i, j in enumerate(clip.joints) if j.endswith("LeftHand"))
    joints = list(clip.joints) + [f"{clip.joints[hand]}/Finger{k}" for k in range(FINGERS)]
    parents = np.concatenate([clip.parents, np.full(FINGERS, hand, dtype=clip.parents.dtype)])
    rest_t = np.concatenate([clip.rest_translations, np.tile([[0.0, -0.05, 0.0]], (FINGERS, 1))]).astype(np.float32)
    rest_r = np.concatenate([clip.rest_rotations, np.tile([[0, 0, 0, 1.0]], (FINGERS, 1))]).astype(np.float32)
    f = clip.translations.shape[0]
    tr = np.concatenate([clip.translations, np.broadcast_to(rest_t[-FINGERS:], (f, FINGERS, 3))], 1)
    rot = np.concatenate([clip.rotations, np.broadcast_to(rest_r[-FINGERS:], (f, FINGERS, 4))], 1)
    return dataclasses.replace(clip, joints=joints, parents=parents, rest_translations=rest_t,
                               rest_rotations=rest_r, translations=tr.astype(np.float32),
                               rotations=rot.astype(np.float32))


def _build(ctx, agents: int, with_edits: bool) -> Path:
    rng = np.random.default_rng(11)
    kinds = [walker.walk, walker.run, walker.turn, walker.walk]
    clips = [_with_fingers(kinds[i % 4](frames=240, name=f"clip31_{i:02d}", phase=i / 10)) for i in range(10)]
    side = np.sqrt(agents / 0.05)  # 0.05 agents per square metre
    specs = [examples.AgentSpec(f"agent_{i:04d}", clips[i % 10],
                                (float(rng.uniform(-side / 2, side / 2)), 0.0, float(rng.uniform(-side / 2, side / 2))),
                                float(rng.uniform(-180, 180)), time_offset=float(rng.integers(0, 24)))
             for i in range(agents)]
    name = "stage_edits" if with_edits else "stage_plain"
    path = ctx.workdir / f"{name}.usda"
    stage = examples.build_crowd_stage(path, specs, up_axis="Y", meters_per_unit=1.0, fps=24.0,
                                       clips_dir=ctx.workdir / "clips31", clip_format="usdc")
    if with_edits:
        from mocapedit.usd import evaluate
        crowd = "/World/Crowd"
        for i in range(0, agents, agents // 100):
            a = f"{crowd}/agent_{i:04d}"
            t0 = specs[i].time_offset  # frame 0 plays at the agent's clip offset
            p = evaluate.agent_root_positions(stage, a, [t0, t0 + 239])
            examples.add_position_constraint(stage, f"/Edits/start_{i:04d}", a, 0, tuple(map(float, p[0])))
            end = p[1] + np.array([1.5, 0.0, -1.0])
            examples.add_position_constraint(stage, f"/Edits/end_{i:04d}", a, 239, tuple(map(float, end)))
        for i in range(5, agents, agents // 50):
            examples.add_time_constraint(stage, f"/Edits/time_{i:04d}", f"{crowd}/agent_{i:04d}", 120,
                                         float(specs[i].time_offset + 130))
        examples.add_group(stage, "/Edits/group", [f"{crowd}/agent_{i:04d}" for i in range(3, 13)])
        examples.define_mocap_prim(stage, "/Edits/settings", "MocapSolveSettings", attributes={
            "collisionAvoidance": (Sdf.ValueTypeNames.Bool, True)})
        stage.GetRootLayer().Save()
    return path


def _solve(path: Path, out: Path) -> tuple[float, float, dict]:
    cli = Path(sys.executable).with_name("mocapedit")
    report = out.with_suffix(".json")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    subprocess.run([str(cli), "solve", str(path), "-o", str(out), "--report", str(report), "-q"], check=True)
    seconds = time.perf_counter() - t
    peak_mb = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before) / 1024.0
    return seconds, peak_mb, json.loads(report.read_text())


def run(ctx):
    agents = 100 if ctx.quick else 1000
    plain = _build(ctx, agents, with_edits=False)
    edited = _build(ctx, agents, with_edits=True)
    peer_s, peer_mb, _ = _solve(plain, ctx.workdir / "plain.edits.usdc")
    seconds, peak_mb, report = _solve(edited, ctx.workdir / "edits.edits.usdc")
    residuals = [c.get("residual", 0.0) for c in report["constraints"] if c.get("hard")]
    return {
        "agents": agents, "frames": 240, "joints": 22 + FINGERS,
        "seconds": round(seconds, 3), "peakMemoryMB": round(peak_mb, 1),
        "targetSeconds": 20.0, "targetMemoryMB": 2048, "meetsTarget": seconds < 20.0 and peak_mb < 2048,
        "editedAgents": report["stats"].get("editedAgents"),
        "constraints": report["stats"].get("constraints"),
        "remainingOverlaps": report["stats"].get("remainingOverlaps"),
        "collisionIterations": report["stats"].get("collisionIterations"),
        "footLockedAgents": report["stats"].get("footLockedAgents"),
        "worstHardResidual": max(residuals, default=0.0),
        "phases": {k: round(v, 3) for k, v in report["timings"].items()},
        "peer": "the same stage with no edits authored (read, trajectories, inspection, write)",
        "peerSeconds": round(peer_s, 3), "peerPeakMemoryMB": round(peer_mb, 1),
        "ratioToPeer": round(seconds / peer_s, 2),
    }
