"""Collision avoidance: detection and resolution, 100, 1,000 and 10,000 agents x 240 frames.

The crowds walk at 1.4 m/s (+-20 %) in random directions from random places in a square
holding 0.25 agents per square metre (a dense, randomly crossing crowd), with a 3 cm
lateral sway. Capsules are 0.3 m by 1.8 m, margin 0.05 m, one sample per frame.

Figures, each beside a peer measured in the same run:
- detection alone: the uniform grid (C++) against all pairs (C++, the same narrow phase)
  and against a numpy grid over (time, cell) (overlaps_peer.py); at 10,000 agents the
  all-pairs peer runs on every tenth sample and is scaled up (it says so);
- resolution per strategy: seconds to the end, iterations, overlaps left, mean and
  largest displacement, path length change, where the time went (factoring, detection,
  gathering the rows, the agents' Schur blocks, the sweeps, the responses, forming the
  rows in Python) and the work done (rows, force updates, back-substitutions). DESIGN.md:
  1,000 agents dense, under 2 s to zero overlaps. Beside the default, the same with every
  row swept in time order on one thread (``split_from_frames=None``, as before the crowd's
  two halves were swept on two threads: at 10,000 agents, not at 1,000). The peer of the solve is scipy.sparse:
  the rows the last solve pushed with, as hard equalities, both steps as one KKT system
  each (100 agents);
- quality on a composed stage: the 128-walker crossing example solved with each strategy
  and with steering alone (maxWait 0), measured with mocapedit.usd.evaluate and
  mocapedit.tools.measure by UsdSkel forward kinematics (overlaps in the shot; root displacement, path length and foot skate against
  the source, over the shot and the 3 s after it in which walkers that waited finish).
"""
from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mocapedit.solve import avoidance, collisions
from mocapedit.data import examples
from mocapedit.inspect import metrics
from mocapedit.tools import measure
from mocapedit.usd import evaluate
from mocapedit.pipeline.processor import solve

import overlaps_peer

FRAMES = 240
DENSITY = 0.25          # agents per square metre
RADIUS, HEIGHT, MARGIN = 0.3, 1.8, 0.05
#: Collision avoidance as it was before walkers waited: steering alone, one anchor, no rows against walking back.
STEER_ONLY_BEFORE = {"max_wait_s": 0.0, "anchor_weight": 1e-4, "stiffen": 1.0, "forward_keep": None}
HERE = Path(__file__).resolve().parent


def crowd(agents: int, seed: int = 1) -> avoidance.Problem:
    paths = examples.dense_crowd_paths(agents, FRAMES, 24.0, DENSITY, seed)
    t = np.arange(FRAMES, dtype=np.float64)
    return avoidance.Problem(names=[f"a{i}" for i in range(agents)], paths=paths,
                             frame_times=[t] * agents, radius=np.full(agents, RADIUS),
                             height=np.full(agents, HEIGHT), margin=MARGIN)


def _detection(ctx, problem: avoidance.Problem) -> dict:
    state = avoidance._State(problem, avoidance.Settings())
    s = state.sampling
    radius, height = problem.radius, problem.height
    grid_s = ctx.best_of(lambda: collisions.detect(s, radius, height, MARGIN), repeat=3)
    found = collisions.detect(s, radius, height, MARGIN)
    agents = len(problem.names)
    out = {"collisionIntervals": len(found), "collidingSamples": int(found.colliding_samples),
           "gridSeconds": round(grid_s, 4)}
    if agents <= 1000:
        brute_s = ctx.best_of(lambda: collisions.detect(s, radius, height, MARGIN, brute_force=True), repeat=1)
        brute = collisions.detect(s, radius, height, MARGIN, brute_force=True)
        assert np.array_equal(brute.deepest, found.deepest) and np.array_equal(brute.agent_a, found.agent_a)
        out["allPairsSeconds"] = round(brute_s, 4)
    else:
        step = 10
        sub = collisions.Sampling(s.agents, s.times[::step], s.frames[::step], s.positions[::step])
        brute_s = ctx.best_of(lambda: collisions.detect(sub, radius, height, MARGIN, brute_force=True), repeat=1)
        out["allPairsSeconds"] = round(brute_s * step, 4)
        out["allPairsExtrapolatedFromEvery"] = step
    out["speedupVsAllPairs"] = round(out["allPairsSeconds"] / grid_s, 1)
    # A numpy grid finds the same overlapping (pair, sample) records.
    pos = np.ascontiguousarray(s.positions.transpose(1, 0, 2))
    numpy_s = ctx.best_of(lambda: overlaps_peer.proximity(pos, radius + MARGIN / 2), repeat=1)
    out["numpyGridSeconds"] = round(numpy_s, 4)
    out["speedupVsNumpyGrid"] = round(numpy_s / grid_s, 1)
    return out


def _figures(problem: avoidance.Problem, outcome: avoidance.Outcome) -> dict:
    disp = np.concatenate([np.linalg.norm(a - b, axis=1) for a, b in zip(outcome.paths, problem.paths)])
    ratio = np.array([metrics.length_ratio(a, b) for a, b in zip(outcome.paths, problem.paths)])
    return {"seconds": round(outcome.seconds, 3), "iterations": len(outcome.iterations) - 1,
            "delayedAgents": int((outcome.delays > 0).sum()),
            "collisionsPerIteration": [it.collisions for it in outcome.iterations],
            "remainingOverlaps": len(outcome.remaining), "solves": outcome.solves,
            "meanDisplacement": round(float(disp.mean()), 4), "maxDisplacement": round(float(disp.max()), 4),
            "meanLengthChange": round(float(np.abs(ratio - 1.0).mean()), 5),
            "movedAgents": int(outcome.moved.sum()), "secondsByPhase": outcome.timing, "work": outcome.work}


def _peer_solve(problem: avoidance.Problem, outcome: avoidance.Outcome, settings: avoidance.Settings) -> dict:
    """scipy.sparse: the two steps as KKT systems with the pushing rows as hard equalities."""
    state = avoidance._State(problem, settings)
    # The rows that push at the end, re-linearised at the result (they hold with equality there).
    flat = np.concatenate(outcome.paths)
    found = state.detect(flat, settings.buffer_m)
    a, b, k = avoidance._expand(found, settings.spread, settings.buffer_m)
    keep = np.unique((k * len(problem.names) + a) * len(problem.names) + b, return_index=True)[1]
    a, b, k = a[keep], b[keep], k[keep]
    normal = avoidance._separation_normals(state, a, b, k)
    va, wa = state.sample_terms(a, k)
    vb, wb = state.sample_terms(b, k)
    rows = avoidance._Rows()
    rows.add(normal, avoidance._clearance(state, a, b) * (1 + settings.overshoot), 0.0,
             np.concatenate([va, vb], 1), np.concatenate([wa, -wb], 1))
    from mocapedit import _solver
    solver = _solver.SeparationSolver(rest=state.rest, starts=state.starts, rigid=[],
                                      anchor_weight=settings.anchor_weight, still_extent=1e-5, threads=1)
    t = time.perf_counter()
    ours = rows.solve(solver, tolerance=1e-9, max_sweeps=1)
    ours_s = time.perf_counter() - t
    t = time.perf_counter()
    peer = _kkt_two_step(state.rest, state.starts, settings.anchor_weight, rows)
    peer_s = time.perf_counter() - t
    return {"rows": rows.count, "solveSeconds": round(ours_s, 4), "peerSeconds": round(peer_s, 4),
            "speedupVsPeer": round(peer_s / ours_s, 1),
            "maxDifferenceVsPeer": float(np.abs(peer - ours.positions).max())}


def _kkt_two_step(rest, starts, anchor, rows) -> np.ndarray:
    """The separation solve's energy (real coordinates) with equality rows, by spsolve."""
    n = len(rest)
    cat = np.concatenate
    direction = cat(rows.direction)
    rhs = cat(rows.rhs)
    tr, tv, tw = cat(rows.term_row), cat(rows.term_vertex), cat(rows.term_weight)
    c = sp.csr_matrix((cat([tw * direction[tr, 0], tw * direction[tr, 1]]), (cat([tr, tr]), cat([2 * tv, 2 * tv + 1]))),
                      shape=(len(rhs), 2 * n))
    x = rest[:, 0] + 1j * rest[:, 1]
    tri_i, tri_mu, edges = [], [], []
    for a in range(len(starts) - 1):
        f0, f1 = starts[a], starts[a + 1]
        i = np.arange(f0 + 1, f1 - 1)
        e = x[i + 1] - x[i - 1]
        tri_i.append(i)
        tri_mu.append((x[i] - x[i - 1]) / e)
        edges.append(np.arange(f0, f1 - 1))
    i, mu, e = cat(tri_i), cat(tri_mu), cat(edges)

    def complex_rows(cols, coefs, count):
        r = np.arange(count)
        rr = cat([2 * r] * len(cols) * 2 + [2 * r + 1] * len(cols) * 2)
        cc = cat([2 * col for col in cols] + [2 * col + 1 for col in cols] +
                 [2 * col for col in cols] + [2 * col + 1 for col in cols])
        vv = cat([c_.real for c_ in coefs.T] + [-c_.imag for c_ in coefs.T] +
                 [c_.imag for c_ in coefs.T] + [c_.real for c_ in coefs.T])
        return sp.csr_matrix((vv, (rr, cc)), shape=(2 * count, 2 * n))

    step1 = complex_rows([i, i - 1, i + 1], np.stack([np.ones(len(i)), -(1 - mu), -mu], 1).astype(complex), len(i))
    anchor_rows = np.sqrt(anchor) * sp.identity(2 * n, format="csr")
    flat_rest = rest.reshape(-1)

    def solve_step(a_mat, b_vec):
        m = sp.vstack([a_mat, anchor_rows]).tocsr()
        r = cat([b_vec, np.sqrt(anchor) * flat_rest])
        kkt = sp.bmat([[m.T @ m, c.T], [c, None]]).tocsc()
        return spla.spsolve(kkt, cat([m.T @ r, rhs]))[:2 * n].reshape(-1, 2)

    shape = solve_step(step1, np.zeros(step1.shape[0]))
    z = shape[:, 0] + 1j * shape[:, 1]
    d = z[e + 1] - z[e]
    v = d / np.abs(d) * np.abs(x[e + 1] - x[e])
    step2 = complex_rows([e + 1, e], np.stack([np.ones(len(e)), -np.ones(len(e))], 1).astype(complex), len(e))
    return solve_step(step2, np.stack([v.real, v.imag], 1).reshape(-1))


def _stage_quality(ctx) -> dict:
    spec = importlib.util.spec_from_file_location("stages_collisions", HERE.parent / "example_stages" / "stages_collisions.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.crossing(ctx.workdir)
    stage_path = ctx.workdir / "collisions_crossing.usda"
    from pxr import Sdf, Usd
    src = Usd.Stage.Open(str(stage_path))
    agents = sorted(str(p.GetPath()) for p in src.Traverse() if "MocapAgentAPI" in p.GetAppliedSchemas())
    # Beyond the shot's end by the longest wait: a walker that waited finishes its clip later.
    times = np.arange(src.GetStartTimeCode(), src.GetEndTimeCode() + 1.0 + 3.0 * src.GetTimeCodesPerSecond())
    shot = times <= src.GetEndTimeCode()
    src_roots = evaluate.agent_root_positions(src, agents, times)
    out = {}
    # The default (wait, then steer), each strategy, and steering alone (maxWait 0).
    steer_only = ctx.workdir / "collisions_crossing_steer_only.usda"
    layer = Sdf.Layer.FindOrOpen(str(stage_path))
    copy = Sdf.Layer.CreateAnonymous(".usda")
    copy.TransferContent(layer)
    settings = copy.GetPrimAtPath("/World/MocapSettings")
    Sdf.AttributeSpec(settings, "maxWait", Sdf.ValueTypeNames.Double, Sdf.VariabilityUniform).default = 0.0
    copy.Export(str(steer_only))
    runs = [(strategy, stage_path, strategy) for strategy in avoidance.STRATEGIES]
    runs.append(("relinearizeSteerOnly", steer_only, "relinearize"))
    for label, path, strategy in runs:
        edits, composed = ctx.workdir / f"{label}.usda", ctx.workdir / f"{label}.edited.usda"
        t = time.perf_counter()
        # The edit itself: foot locking would plant again the feet it made slide.
        result = solve(str(path), output=str(edits), composed=str(composed), collision_strategy=strategy,
                       foot_locking=False)
        seconds = time.perf_counter() - t
        edited = Usd.Stage.Open(str(composed))
        roots = evaluate.agent_root_positions(edited, agents, times)
        bases = roots[:, shot].copy()
        bases[..., 1] = 0.0
        sep = metrics.min_separation(bases, RADIUS, HEIGHT, "Y")
        ground_src, ground_out = metrics.to_ground(src_roots, "Y"), metrics.to_ground(roots, "Y")
        disp = np.linalg.norm(ground_out - ground_src, axis=-1)
        ratio = np.array([metrics.length_ratio(e, s_) for e, s_ in zip(ground_out, ground_src)])
        moved = [a for a, d in zip(agents, disp.max(axis=1)) if d > 1e-6][:24]
        skate_src, skate_out = [], []
        for a in moved:
            before = measure.foot_skate(src, a)
            after = measure.foot_skate(edited, a)   # its own contacts: a wait moves them in time
            skate_src.append(before.mean)
            skate_out.append(after.mean)
        out[label] = {
            "solveSeconds": round(seconds, 3), "iterations": result.report.stats["collisionIterations"],
            "delayedAgents": result.report.stats.get("delayedAgents", 0),
            "largestDelaySeconds": result.report.stats.get("largestDelay", 0.0),
            "collisionsPerIteration": result.report.stats["collisionsPerIteration"],
            "overlappingSamples": sep.overlaps, "minClearance": round(sep.clearance, 4),
            "meanRootDisplacement": round(float(disp.mean()), 4), "maxRootDisplacement": round(float(disp.max()), 4),
            "meanPathLengthChange": round(float(np.abs(ratio - 1).mean()), 5),
            "footSkateSource": round(float(np.nanmean(skate_src)), 5),
            "footSkateEdited": round(float(np.nanmean(skate_out)), 5),
            "footSkateAgents": len(moved),
            "footSkateRatio": round(float(np.nanmean(np.asarray(skate_out) / np.asarray(skate_src))), 3)}
    return out


def run(ctx) -> dict:
    sizes = (100, 1000) if ctx.quick else (100, 1000, 10000)
    out = {"framesPerAgent": FRAMES, "agentsPerSquareMetre": DENSITY, "target1000AgentsSeconds": 1.5,
           "target10000AgentsSeconds": 30.0, "steerOnlyBefore": STEER_ONLY_BEFORE,
           "defaultStrategy": avoidance.Settings().strategy}
    settings = avoidance.Settings()
    for agents in sizes:
        problem = crowd(agents)
        entry = {"detection": _detection(ctx, problem)}
        for strategy in avoidance.STRATEGIES:
            if agents > 1000 and strategy == "accumulate" and ctx.quick:
                continue
            # The best of three runs below 10,000 agents (the machine is shared), one above.
            runs = [avoidance.resolve(problem, avoidance.Settings(strategy=strategy))
                    for _ in range(3 if agents <= 1000 else 1)]
            outcome = min(runs, key=lambda o: o.seconds)
            entry[strategy] = _figures(problem, outcome)
            if agents == 100 and strategy == "relinearize":
                entry["solvePeer"] = _peer_solve(problem, outcome, settings)
        # The peer of the default: steering alone with the stiffer anchor, as before waiting.
        runs = [avoidance.resolve(problem, avoidance.Settings(**STEER_ONLY_BEFORE))
                for _ in range(3 if agents <= 1000 else 1)]
        entry["steerOnlyBefore"] = _figures(problem, min(runs, key=lambda o: o.seconds))
        # The peer of the split sweeps: the default with every row swept in time order on one thread.
        runs = [avoidance.resolve(problem, avoidance.Settings(split_from_frames=None))
                for _ in range(3 if agents <= 1000 else 1)]
        entry["sweepsInTimeOrder"] = _figures(problem, min(runs, key=lambda o: o.seconds))
        entry["splitSweepsSpeedup"] = round(entry["sweepsInTimeOrder"]["seconds"] / entry[settings.strategy]["seconds"], 3)
        if agents == 1000:
            best = entry[settings.strategy]
            entry["meetsTarget"] = best["seconds"] < out["target1000AgentsSeconds"] and best["remainingOverlaps"] == 0
        out[f"agents{agents}"] = entry
    out["crossingStage"] = _stage_quality(ctx)
    return out
