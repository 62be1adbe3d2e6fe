"""Batch: 8 shots of 1,000 agents x 240 frames x 31 joints (the whole-stage crowd with its edits).

`mocapedit batch` on a local Dask cluster of 2 worker processes (each solver on its share of the
cores, MOCAPEDIT_THREADS), start-up included, against its peer in the same run: the same 8 shots
solved one after another in one process (no Dask), on the machine's threads.
Target (issue 19): under 0.6 times the sequential time. The outputs of both are compared byte
for byte.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import bench_stage

SHOTS = 8

SEQUENTIAL = """
import sys
from mocapedit.pipeline import processor
for shot, out in zip(sys.argv[1::2], sys.argv[2::2]):
    processor.solve(shot, output=out)
"""


def run(ctx):
    agents = 100 if ctx.quick else 1000
    shots = []
    for k in range(SHOTS):
        sub = type(ctx)(ctx.workdir / f"shot{k}", ctx.quick)
        sub.workdir.mkdir(exist_ok=True)
        built = bench_stage._build(sub, agents, with_edits=True)
        shot = built.with_name(f"shot_{k}.usda")   # the clips are referenced relative to the folder
        os.replace(built, shot)
        shots.append(shot)
    seq_dir, batch_dir = ctx.workdir / "sequential", ctx.workdir / "batch"
    seq_dir.mkdir(exist_ok=True)
    outs = [seq_dir / f"{s.stem}.edits.usdc" for s in shots]
    t = time.perf_counter()
    subprocess.run([sys.executable, "-c", SEQUENTIAL] + [str(x) for pair in zip(shots, outs) for x in pair],
                   check=True)
    sequential = time.perf_counter() - t
    cli = Path(sys.executable).with_name("mocapedit")
    t = time.perf_counter()
    subprocess.run([str(cli), "batch", *map(str, shots), "-o", str(batch_dir), "--workers", "2", "-q"], check=True)
    batch = time.perf_counter() - t
    identical = all((batch_dir / o.name).read_bytes() == o.read_bytes() for o in outs)
    return {
        "shots": SHOTS, "agentsPerShot": agents, "frames": 240, "joints": 22 + bench_stage.FINGERS,
        "workers": 2, "batchSeconds": round(batch, 2),
        "peer": "the same shots solved one after another in one process", "sequentialSeconds": round(sequential, 2),
        "ratioToSequential": round(batch / sequential, 3), "targetRatio": 0.6,
        "meetsTarget": batch / sequential < 0.6, "byteIdentical": identical,
    }
