"""Reader: 1,000 agents sharing 10 clips (240 frames, ~20 joints). Target: under 2 s.

Peer: the same agents read naively, each through its own UsdSkel AnimQuery (every
agent's clip read again, as a per-agent loop would).
"""
from __future__ import annotations

import time

import numpy as np
from pxr import Usd, UsdSkel

from mocapedit.data import examples, walker
from mocapedit.usd import reader
from mocapedit.pipeline.processor import solve


def _build(ctx, agents: int, clips: int, frames: int):
    rng = np.random.default_rng(7)
    kinds = [walker.walk, walker.run, walker.turn, walker.idle]
    clip_list = [kinds[i % len(kinds)](frames=frames, name=f"clip{i:02d}", phase=i / clips)
                 for i in range(clips)]
    specs = [examples.AgentSpec(f"agent_{i:04d}", clip_list[i % clips],
                                (float(rng.uniform(-50, 50)), 0.0, float(rng.uniform(-50, 50))),
                                float(rng.uniform(-180, 180)), time_offset=float(rng.integers(0, 24)))
             for i in range(agents)]
    path = ctx.workdir / f"crowd_{agents}.usda"
    examples.build_crowd_stage(path, specs, up_axis="Y", meters_per_unit=1.0, fps=24.0,
                               clips_dir=ctx.workdir / f"clips_{agents}", clip_format="usdc")
    return path, len(clip_list[0].joints)


def _naive(stage):
    cache = UsdSkel.Cache()
    n = 0
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Root):
            cache.Populate(UsdSkel.Root(prim), Usd.PrimDefaultPredicate)
            for binding in cache.ComputeSkelBindings(UsdSkel.Root(prim), Usd.PrimDefaultPredicate) or []:
                pass
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Skeleton):
            q = cache.GetSkelQuery(UsdSkel.Skeleton(prim)).GetAnimQuery()
            for t in q.GetJointTransformTimeSamples():
                q.ComputeJointLocalTransformComponents(Usd.TimeCode(t))
            n += 1
    return n


def run(ctx):
    agents = 100 if ctx.quick else 1000
    path, joints = _build(ctx, agents, 10, 240)

    def read():
        return reader.read_stage(Usd.Stage.Open(str(path)))

    t = time.perf_counter()
    data = read()
    first = time.perf_counter() - t
    best = ctx.best_of(read, repeat=3)
    peer = ctx.best_of(lambda: _naive(Usd.Stage.Open(str(path))), repeat=1)
    t = time.perf_counter()
    result = solve(str(path), output=str(ctx.workdir / "edits.usdc"))
    solve_s = time.perf_counter() - t
    return {
        "agents": len(data.agents), "clipsRead": len(data.clips), "framesPerClip": 240, "joints": joints,
        "readSeconds": round(best, 4), "readSecondsFirst": round(first, 4), "targetSeconds": 2.0,
        "meetsTarget": best < 2.0,
        "peer": "per-agent UsdSkel AnimQuery read of every agent's clip",
        "peerSeconds": round(peer, 4), "speedupVsPeer": round(peer / best, 2),
        "solveNoEditsSeconds": round(solve_s, 4),
        "solvePhases": {k: round(v, 4) for k, v in result.report.timings.items()},
    }
