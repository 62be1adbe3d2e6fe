"""Foot locking: the C++ FootLockJob on 1,000 agents x 240 frames, both legs, next to the same
IK in vectorised numpy (``footlock.lock_feet_numpy``) in the same run. Target (issue 17):
under 0.5 s on 2 cores.

The inputs are walking-like legs (hips 0.9 m up, knees bent 3 to 35 degrees) with targets a few
centimetres away, weights ramping in and out, and one leg in twenty asked beyond its reach so the
pelvis drop runs too. Also timed: the whole solve of a crowd whose paths are bent (the foot
locking pass against the solve with foot locking off).
"""
from __future__ import annotations

import time

import numpy as np

from mocapedit.data import examples, walker
from mocapedit.solve import footlock
from mocapedit.pipeline.processor import solve

TARGET_S = 0.5


def _inputs(agents, frames, seed=5):
    rng = np.random.default_rng(seed)
    n = agents * frames
    weights = np.clip(1.5 * np.sin(np.linspace(0, 40 * np.pi, n))[:, None] ** 2, 0, 1) * np.ones((1, 2))
    inputs = examples.leg_inputs(rng, agents, frames, 0.05, np.full(agents, 3), weights)
    inputs.target[rng.random((n, 2)) < 0.05] += np.array([0.0, -0.3, 0.0])
    return inputs


def _crowd_solve(ctx, agents):
    clip = walker.walk(frames=240, fps=24.0, speed=1.25, name="walk")
    specs = [examples.AgentSpec(f"a{i}", clip, (2.0 * (i % 10), 0.0, 3.0 * (i // 10))) for i in range(agents)]
    stage = examples.build_crowd_stage(ctx.workdir / "feet_shot.usda", specs, up_axis="Y", fps=24.0,
                                       clips_dir=ctx.workdir / "feet_clips")
    for i in range(agents):
        x, z = 2.0 * (i % 10), 3.0 * (i // 10)
        examples.add_position_constraint(stage, f"/Edits/s{i}", f"/World/Crowd/a{i}", 0, (x, 0.0, z))
        examples.add_position_constraint(stage, f"/Edits/m{i}", f"/World/Crowd/a{i}", 120, (x + 0.8, 0.0, z + 6.0))
    stage.GetRootLayer().Save()
    path = str(ctx.workdir / "feet_shot.usda")
    times = {}
    for lock in (False, True):
        t = time.perf_counter()
        result = solve(path, guides=False, foot_locking=lock)
        times[lock] = time.perf_counter() - t
    return {"agents": agents, "frames": 240, "solveSeconds": round(times[True], 3),
            "solveSecondsWithoutFootLocking": round(times[False], 3),
            "footLockingPassSeconds": round(result.report.timings.get("foot locking", float("nan")), 3),
            "footLockedAgents": result.report.stats.get("footLockedAgents", 0)}


def run(ctx) -> dict:
    agents = 100 if ctx.quick else 1000
    frames = 240
    inputs = _inputs(agents, frames)
    job_s = ctx.best_of(lambda: footlock.lock_feet(inputs), repeat=5)
    one_thread = footlock.LegInputs(**vars(inputs))
    arrays = one_thread.arrays()
    from mocapedit import _solver
    single_s = ctx.best_of(lambda: _solver.lock_feet(**arrays, threads=1), repeat=3)
    peer_s = ctx.best_of(lambda: footlock.lock_feet_numpy(inputs), repeat=2)
    fast, slow = footlock.lock_feet(inputs), footlock.lock_feet_numpy(inputs)
    err = max(float(np.abs(getattr(fast, k) - getattr(slow, k)).max())
              for k in ("hip_local", "knee_local", "ankle_local", "drop", "reached"))
    figures = {
        "job": {"agents": agents, "frames": frames, "legs": 2 * agents * frames, "seconds": round(job_s, 4),
                "secondsOneThread": round(single_s, 4), "targetSeconds": TARGET_S, "meetsTarget": job_s < TARGET_S,
                "numpySeconds": round(peer_s, 4), "speedupOverNumpy": round(peer_s / job_s, 1),
                "maxDifferenceFromNumpy": err},
    }
    figures["crowdSolve"] = _crowd_solve(ctx, 20 if ctx.quick else 100)
    return figures
