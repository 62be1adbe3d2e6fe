"""Scale: 1,000 and 10,000 agents (30,000 with --large) x 240 frames x 31 joints, read-solve-write.

The stage is the whole-stage benchmark's crowd (`bench_stage`): pins and moved ends on 1% of the
agents, time constraints on 0.5%, a 10-member group, collision avoidance on. Each solve runs in a
child process that reports its own phase times and peak memory; the layer size is the .usdc on disk.
Peer, in the same run: the same solve with time-only edits baked into SkelAnimation samples
(`bake_timing=True`), as the writer did before value clips.

Also: 1,000 agents whose only edit is a time constraint each (no collisions), written with value
clips and baked; target: the value-clip layer under 5% of the baked one.

Targets (issue 19): 10,000 agents under 15 s and 2 GB; 30,000 under 60 s.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from pxr import Usd

import bench_stage
from mocapedit.data import examples

CHILD = """
import json, resource, sys, time
from mocapedit.pipeline import processor
t = time.perf_counter()
result = processor.solve(sys.argv[1], output=sys.argv[2], bake_timing=sys.argv[3] == "1")
seconds = time.perf_counter() - t
print(json.dumps({"seconds": seconds, "phases": result.report.timings,
                  "peakMemoryMB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                  "editedAgents": result.report.stats.get("editedAgents"),
                  "remainingOverlaps": result.report.stats.get("remainingOverlaps")}))
"""


def _solve(path: Path, out: Path, bake: bool) -> dict:
    proc = subprocess.run([sys.executable, "-c", CHILD, str(path), str(out), "1" if bake else "0"],
                          check=True, capture_output=True, text=True)
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    figures["layerMB"] = round(out.stat().st_size / 1e6, 2)
    figures["seconds"] = round(figures["seconds"], 2)
    figures["peakMemoryMB"] = round(figures["peakMemoryMB"], 1)
    figures["phases"] = {k: round(v, 3) for k, v in figures["phases"].items()}
    out.unlink()
    return figures


def _time_only_stage(ctx, agents: int) -> Path:
    """The crowd with no edits but one time constraint per agent (frame 120 a few frames late)."""
    path = bench_stage._build(ctx, agents, with_edits=False)
    stage = Usd.Stage.Open(str(path))
    rng = np.random.default_rng(5)
    for i in range(agents):
        agent = f"/World/Crowd/agent_{i:04d}"
        t0 = stage.GetPrimAtPath(f"{agent}/Skel/Anim").GetAttribute("rotations").GetTimeSamples()[0]
        examples.add_time_constraint(stage, f"/Edits/time_{i:05d}", agent, 120, float(t0 + 120 + rng.uniform(-6, 6)))
    stage.GetRootLayer().Save()
    return path


def run(ctx):
    sizes = [100] if ctx.quick else [1000, 10000] + ([30000] if getattr(ctx, "large", False) else [])
    results = {}
    for n in sizes:
        (ctx.workdir / f"n{n}").mkdir(exist_ok=True)
        sub = type(ctx)(ctx.workdir / f"n{n}", ctx.quick)
        path = bench_stage._build(sub, n, with_edits=True)
        clips = _solve(path, sub.workdir / "clips.usdc", bake=False)
        baked = _solve(path, sub.workdir / "baked.usdc", bake=True)
        results[str(n)] = {"valueClips": clips, "baked": baked,
                           "ratioSecondsToBaked": round(clips["seconds"] / baked["seconds"], 2),
                           "ratioLayerToBaked": round(clips["layerMB"] / baked["layerMB"], 3)}
    n = 100 if ctx.quick else 1000
    (ctx.workdir / "timeonly").mkdir(exist_ok=True)
    sub = type(ctx)(ctx.workdir / "timeonly", ctx.quick)
    path = _time_only_stage(sub, n)
    clips = _solve(path, sub.workdir / "clips.usdc", bake=False)
    baked = _solve(path, sub.workdir / "baked.usdc", bake=True)
    ratio = clips["layerMB"] / baked["layerMB"]
    return {
        "frames": 240, "joints": 22 + bench_stage.FINGERS, "crowd": results,
        "targets": {"10000": "15 s, 2 GB", "30000": "60 s", "timeOnlyLayerRatio": 0.05},
        "large": bool(getattr(ctx, "large", False)),
        "timeOnly": {"agents": n, "valueClips": clips, "baked": baked, "layerRatio": round(ratio, 4),
                     "meetsTarget": ratio < 0.05},
    }
