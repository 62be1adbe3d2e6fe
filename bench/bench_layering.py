"""Layering: joint samples per second on one core. Target (DESIGN.md): at least 50 million
for additive layering.

Per core means per second of CPU time of the one thread that runs the job (the machine is
shared, so wall time depends on what else runs; it is reported beside). A joint sample is
one joint at one pose.

The job (C++ LayeringJob through ``_solver.apply_layers``) layers agents one call each
(240 frames x 31 joints, the whole skeleton), the way the pass calls it. The headline figure
uses a weight strictly between 0 and 1 at every pose (the worst case: every sample runs the
full slerp); an eased weight (0, up, 1, down) is reported beside it. The peer is the same
computation in vectorised numpy (``layering.apply_layers_numpy``, trigonometric slerp) on
all agents at once, which is numpy's best case. Also timed: the offline builder (clip to
deltas), blend layering, and the whole layering pass on a crowd stage.
"""
from __future__ import annotations

import time

import numpy as np
from pxr import Sdf, Usd

from mocapedit import _solver
from mocapedit.data import examples, gestures, walker
from mocapedit.solve import layering
from mocapedit.usd import schema
from mocapedit.pipeline.processor import solve

TARGET = 50e6


def _poses(rng, frames, joints):
    q = rng.normal(size=(frames, joints, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return (rng.normal(size=(frames, joints, 3)).astype(np.float32), q.astype(np.float32),
            (1 + 0.1 * rng.normal(size=(frames, joints, 3))).astype(np.float32))


def _best_cpu(fn, repeat):
    """(best CPU seconds of this thread, best wall seconds) over ``repeat`` calls. The job runs
    on the calling thread, so its CPU time is its cost on one core whatever else the machine
    is doing; wall time is reported beside it."""
    cpu = wall = float("inf")
    for _ in range(repeat):
        c, w = time.thread_time(), time.perf_counter()
        fn()
        cpu, wall = min(cpu, time.thread_time() - c), min(wall, time.perf_counter() - w)
    return cpu, wall


def _weights(frames, eased):
    """Eased: 0, up to 1, held, down to 0 (the usual layer). Otherwise strictly between 0 and
    1 at every pose, so no pose takes the weight-0 or weight-1 shortcuts (the worst case)."""
    bump = np.sin(np.linspace(0, np.pi, frames))
    w = np.clip(1.5 * bump, 0, 1) if eased else 0.05 + 0.9 * bump
    return w.astype(np.float32)


def _throughput(ctx, agents, frames, joints, mode, eased=False):
    rng = np.random.default_rng(11)
    sources = [_poses(rng, frames, joints) for _ in range(agents)]
    layer = _poses(rng, frames, joints)
    weights = _weights(frames, eased)
    if mode == "additive":
        layer = _solver.build_additive_clip(tuple(a[0] for a in layer), layer)
    job = [(mode, layer, weights, None)]

    def run_job():
        for s in sources:
            _solver.apply_layers(s, job)

    stacked = tuple(np.concatenate(parts) for parts in zip(*sources))
    peer_job = [(mode, tuple(np.concatenate([a] * agents) for a in layer), np.tile(weights, agents), None)]
    samples = agents * frames * joints
    job_s, job_wall = _best_cpu(run_job, repeat=5)
    peer_s, peer_wall = _best_cpu(lambda: layering.apply_layers_numpy(stacked, peer_job), repeat=2)
    # The two agree (rotations up to sign).
    got = _solver.apply_layers(stacked, peer_job)
    want = layering.apply_layers_numpy(stacked, peer_job)
    err = float(np.max(1 - np.abs(np.sum(got[1].astype(np.float64) * want[1], -1))))
    return {"jointSamples": samples, "cpuSeconds": round(job_s, 5), "wallSeconds": round(job_wall, 5),
            "samplesPerSecond": round(samples / job_s), "samplesPerSecondWall": round(samples / job_wall),
            "peerCpuSeconds": round(peer_s, 5), "peerSamplesPerSecond": round(samples / peer_s),
            "speedupVsPeer": round(peer_s / job_s, 1), "maxRotationDifferenceVsPeer": err}


def _builder(ctx, frames, joints):
    rng = np.random.default_rng(5)
    clip = _poses(rng, frames, joints)
    reference = tuple(a[0] for a in clip)
    s, _ = _best_cpu(lambda: _solver.build_additive_clip(reference, clip), repeat=20)
    return {"jointSamples": frames * joints, "cpuSeconds": round(s, 6), "samplesPerSecond": round(frames * joints / s)}


def _crowd(ctx, agents, frames):
    walk = walker.walk(frames=frames, name="bench_walk")
    specs = [examples.AgentSpec(f"agent_{i:04d}", walk, (float(i % 20), 0.0, float(i // 20)), 0.0,
                                time_offset=float(i % 24)) for i in range(agents)]
    path = ctx.workdir / f"layering_{agents}.usda"
    stage = examples.build_crowd_stage(path, specs, clips_dir=ctx.workdir / "layering_clips", clip_format="usdc")
    examples.write_clip_layer(gestures.phone_call(frames=96), ctx.workdir / "layering_clips" / "phone.usdc")
    stage.DefinePrim("/World/Clips/Phone").GetReferences().AddReference(
        "./layering_clips/phone.usdc", examples.CLIP_ANIMATION_PATH)
    layer = schema.AnimationLayer.Define(stage, "/World/Layers/Phone")
    layer.CreateAgentsRel().SetTargets([Sdf.Path(f"/World/Crowd/agent_{i:04d}") for i in range(0, agents, 2)])
    layer.CreateAnimationRel().SetTargets([Sdf.Path("/World/Clips/Phone")])
    layer.CreateJointAttr("Spine")
    layer.CreateReferencePoseAttr("restPose")
    weight = layer.CreateWeightAttr()
    for t, w in ((20.0, 0.0), (40.0, 1.0), (180.0, 1.0), (200.0, 0.0)):
        weight.Set(w, Usd.TimeCode(t))
    stage.GetRootLayer().Save()
    t = time.perf_counter()
    result = solve(str(path), output=str(ctx.workdir / "layering_edits.usdc"))
    total = time.perf_counter() - t
    return {"agents": agents, "layeredAgents": result.report.stats["layeredAgents"], "frames": frames,
            "joints": len(walk.joints), "layeringPassSeconds": round(result.report.timings["layering"], 4),
            "solveSeconds": round(total, 4),
            "solvePhases": {k: round(v, 4) for k, v in result.report.timings.items()}}


def run(ctx):
    agents = 20 if ctx.quick else 100
    additive = _throughput(ctx, agents, 240, 31, "additive")
    return {
        "target": "additive layering >= 50 million joint samples per second per core",
        "targetSamplesPerSecond": TARGET,
        "meetsTarget": additive["samplesPerSecond"] >= TARGET,
        "peer": "vectorised numpy (float64 trigonometric slerp), all agents in one call",
        "sizes": f"{agents} agents x 240 frames x 31 joints, one job call per agent, whole skeleton",
        "additive": additive,
        "additiveEasedWeight": _throughput(ctx, agents, 240, 31, "additive", eased=True),
        "blend": _throughput(ctx, agents, 240, 31, "blend"),
        "additiveBuilder": _builder(ctx, 240, 31),
        "crowd": _crowd(ctx, 50 if ctx.quick else 1000, 240),
    }
