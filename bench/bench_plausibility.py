"""Plausibility figures of a solved crowd: ``processor.measure_plausibility`` (agents measured
together: forward kinematics and foot skate of a batch in numpy, the figures by the C++
PlausibilityJob) next to the per-agent numpy code it replaced (``plausibility_peer``), on the
same solved context in the same run, and the figures of the two compared value by value.

The crowd: walkers, runners and turners, every agent pinned at its start and moved at frame 180,
one in five re-timed by a time constraint; solved with foot locking on (the feet pass measures
the feet skate, as on the whole-stage benchmark) and off (the plausibility pass measures it).
"""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np

from mocapedit.data import examples, walker
from mocapedit.pipeline import processor

sys.path.insert(0, str(Path(__file__).resolve().parent))

import plausibility_peer  # noqa: E402


def _stage(ctx, agents: int) -> str:
    kinds = [walker.walk, walker.run, walker.turn]
    clips = [kinds[i % 3](frames=240, fps=24.0, name=f"clip{i}", phase=i / 7) for i in range(6)]
    rng = np.random.default_rng(3)
    side = 4.0 * math.sqrt(agents)
    specs = [examples.AgentSpec(f"a{i:04d}", clips[i % len(clips)],
                                (float(rng.uniform(0, side)), 0.0, float(rng.uniform(0, side))),
                                float(rng.uniform(-180, 180))) for i in range(agents)]
    path = ctx.workdir / f"plausibility_{agents}.usda"
    stage = examples.build_crowd_stage(path, specs, up_axis="Y", fps=24.0, clips_dir=ctx.workdir / "plausibility_clips")
    from mocapedit.usd import evaluate
    for i, spec in enumerate(specs):
        agent = f"/World/Crowd/{spec.name}"
        start, end = evaluate.agent_root_positions(stage, agent, [0, 180])
        examples.add_position_constraint(stage, f"/Edits/s{i}", agent, 0, tuple(map(float, start)))
        examples.add_position_constraint(stage, f"/Edits/m{i}", agent, 180,
                                         tuple(map(float, end + rng.uniform(-1.0, 1.0, 3) * [1, 0, 1])))
        if i % 5 == 0:
            examples.add_time_constraint(stage, f"/Edits/t{i}", agent, 120, 132.0)
    stage.GetRootLayer().Save()
    return str(path)


def _solved(path: str, foot_locking: bool, measure) -> None:
    """Solves the stage; ``measure`` gets the solve context as measure_plausibility does (the
    solve releases its arrays after)."""
    kept = processor.measure_plausibility
    processor.measure_plausibility = measure
    try:
        processor.solve(path, guides=False, collisions=False, foot_locking=foot_locking)
    finally:
        processor.measure_plausibility = kept


def _figures(report) -> dict:
    out = {"stats": dataclasses.astuple(report.stats.plausibility)}
    for path, entry in report.agents.items():
        out[path] = (dataclasses.astuple(entry.plausibility) if entry.plausibility else None,
                     entry.foot_skate_source, entry.foot_skate_edited)
    return out


def _numbers(value):
    if isinstance(value, (tuple, list)):
        for v in value:
            yield from _numbers(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _numbers(v)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield float(value)


def _compare(a: dict, b: dict) -> tuple[int, float]:
    """(values that differ, largest relative difference) of two reports' figures."""
    differ, worst = 0, 0.0
    for key in a.keys() | b.keys():
        x, y = list(_numbers(a.get(key))), list(_numbers(b.get(key)))
        if len(x) != len(y):
            return -1, math.inf
        for u, v in zip(x, y):
            if u == v or (math.isnan(u) and math.isnan(v)):
                continue
            differ += 1
            worst = max(worst, abs(u - v) / max(1.0, abs(u)))
    return differ, worst


def _measure(ctx, solved, measure) -> tuple[float, dict]:
    entries = {p: (e.plausibility, e.foot_skate_source, e.foot_skate_edited) for p, e in solved.report.agents.items()}

    def once():
        for p, (plaus, skate_s, skate_e) in entries.items():
            e = solved.report.agents[p]
            e.plausibility, e.foot_skate_source, e.foot_skate_edited = plaus, skate_s, skate_e
        solved.report.stats.plausibility = None
        measure(solved)
    seconds = ctx.best_of(once, repeat=3)
    return seconds, _figures(solved.report)


def run(ctx) -> dict:
    agents = 100 if ctx.quick else 1000
    path = _stage(ctx, agents)
    figures = {}
    measured = processor.measure_plausibility
    for foot_locking in (True, False):
        def measure(solved, foot_locking=foot_locking):
            old_s, old = _measure(ctx, solved, plausibility_peer.measure_plausibility)
            new_s, new = _measure(ctx, solved, measured)
            differ, worst = _compare(old, new)
            figures["footLocking" if foot_locking else "noFootLocking"] = {
                "agents": agents, "frames": 240, "measuredAgents": solved.report.stats.plausibility.agents,
                "seconds": round(new_s, 4), "peerSeconds": round(old_s, 4), "speedup": round(old_s / new_s, 1),
                "valuesThatDiffer": differ, "maxRelativeDifference": worst,
                "peer": "the per-agent numpy measures (bench/plausibility_peer.py)"}
        _solved(path, foot_locking, measure)
    return figures
