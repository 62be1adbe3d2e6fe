"""A 1,000-agent shot solved whole, and split by path component over a local Dask cluster.

The whole-stage crowd of ``bench_stage`` (1,000 agents x 240 frames x 31 joints, pins, time
constraints, a group, collision avoidance), and the same crowd with 98 more groups of ten
agents, each pinned (group meshes are the path pass's largest solves). Each shot is solved in
one process (its path components on two threads), the peer, and with its path components and
its foot locking as tasks on a local cluster of two single-threaded worker processes (``batch.DaskComponents``),
in the same run; the cluster is started, and has imported mocapedit, before the clock runs. The two outputs are compared
byte for byte.
"""
from __future__ import annotations

import importlib
import time

import bench_stage

GROUPS_FROM = 20   # the crowd's own group holds agents 3-12


def _grouped(ctx, agents: int):
    from mocapedit.data import examples
    from mocapedit.usd import reader
    path = bench_stage._build(ctx, agents, with_edits=True)
    stage = reader.open_stage(str(path))
    crowd = "/World/Crowd"
    size = 10 if agents >= 100 else 5
    for k in range(GROUPS_FROM, agents - size + 1, size):
        examples.add_group(stage, f"/Edits/mesh_{k:04d}", [f"{crowd}/agent_{i:04d}" for i in range(k, k + size)])
    stage.GetRootLayer().Export(str(path.with_name("stage_groups.usda")))
    return path, path.with_name("stage_groups.usda")


def _measure(shot, out_dir, client, name: str) -> dict:
    from mocapedit.pipeline import batch, processor
    t = time.perf_counter()
    whole = processor.solve(str(shot), output=str(out_dir / f"{name}.whole.usdc"))
    whole_s = time.perf_counter() - t
    pool = batch.DaskComponents(client)
    t = time.perf_counter()
    split = processor.solve(str(shot), output=str(out_dir / f"{name}.split.usdc"), components=pool)
    split_s = time.perf_counter() - t
    same = (out_dir / f"{name}.whole.usdc").read_bytes() == (out_dir / f"{name}.split.usdc").read_bytes()
    return {
        "pathComponents": whole.report.stats.path_components, "componentTasks": pool.tasks,
        "splitSeconds": round(split_s, 2), "splitPathSeconds": round(split.report.timings["path"], 3),
        "peer": "the same shot solved in one process (path components on two threads)",
        "wholeSeconds": round(whole_s, 2), "wholePathSeconds": round(whole.report.timings["path"], 3),
        "ratioToWhole": round(split_s / whole_s, 3),
        "pathRatioToWhole": round(split.report.timings["path"] / whole.report.timings["path"], 3),
        "byteIdentical": same,
        "wholePhaseSeconds": {k: round(v, 3) for k, v in whole.report.timings.items()},
        "splitPhaseSeconds": {k: round(v, 3) for k, v in split.report.timings.items()},
    }


def run(ctx):
    from mocapedit.pipeline import batch
    agents = 100 if ctx.quick else 1000
    crowd, grouped = _grouped(ctx, agents)
    t = time.perf_counter()
    client, cluster = batch.connect(None, 2)
    with cluster, client:
        # Workers import the solver once, before the clock runs (a farm's workers stay up).
        client.run(importlib.import_module, "mocapedit.pipeline.passes.path")
        start = time.perf_counter() - t
        figures = {"crowd": _measure(crowd, ctx.workdir, client, "crowd"),
                   "groups": _measure(grouped, ctx.workdir, client, "groups")}
    return {"agents": agents, "frames": 240, "joints": 22 + bench_stage.FINGERS, "workers": 2,
            "clusterStartSeconds": round(start, 2), **figures}
