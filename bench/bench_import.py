"""BVH import: a 1,000-frame, 100-joint file to a UsdSkel layer, end to end. Target: under 1 s.

Measured: parse + Euler-to-quaternion conversion + authoring + atomic save of the
``.usda`` (and of a ``.usdc``), best of three, with the phases apart; and the whole
``mocapedit import-bvh`` command, process start and USD import included. Peer: the bvhio
package (pure Python) reading the same file (``readAsBvh``: parse and per-joint Euler to
quaternion, the part of our import it also does), timed in the same run. A second figure
streams a long clip (20,000 frames, 100 joints) to ``.usdc`` in chunks, for throughput.
"""
from __future__ import annotations

import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from mocapedit.formats import bvh
from mocapedit.usd import bvh_usd

ORDERS = ("ZXY", "ZYX", "XYZ", "YXZ", "XZY", "YZX")


def write_clip(path, frames: int, joints: int, seed: int = 5) -> None:
    """A deterministic random 100-joint rig: 6-channel root, 3 rotation channels elsewhere."""
    rng = np.random.default_rng(seed)
    lines = ["HIERARCHY"]
    parents = [-1]
    for j in range(1, joints):
        parents.append(int(rng.integers(max(0, j - 4), j)))
    children = {j: [c for c in range(joints) if parents[c] == j] for j in range(joints)}
    channel_count = 0

    def joint(j, depth):
        nonlocal channel_count
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} joint_{j}")
        lines.append(pad + "{")
        lines.append(pad + "  OFFSET " + " ".join(f"{v:.5f}" for v in rng.uniform(-10, 10, 3)))
        rot = " ".join(f"{a}rotation" for a in ORDERS[j % 6])
        if j == 0:
            lines.append(pad + f"  CHANNELS 6 Xposition Yposition Zposition {rot}")
            channel_count += 6
        else:
            lines.append(pad + f"  CHANNELS 3 {rot}")
            channel_count += 3
        for c in children[j]:
            joint(c, depth + 1)
        if not children[j]:
            lines.extend([pad + "  End Site", pad + "  {", pad + "    OFFSET 0 1 0", pad + "  }"])
        lines.append(pad + "}")

    joint(0, 0)
    lines += ["MOTION", f"Frames: {frames}", "Frame Time: .0083333"]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
        block = 1000
        for start in range(0, frames, block):
            n = min(block, frames - start)
            values = rng.uniform(-180, 180, (n, channel_count))
            f.write("\n".join(" ".join(f"{v:.4f}" for v in row) for row in values) + "\n")


def _peer(path) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio
    t = time.perf_counter()
    bvhio.readAsBvh(str(path))
    return time.perf_counter() - t


def run(ctx):
    frames, joints = 1000, 100
    src = ctx.workdir / "clip_1000x100.bvh"
    write_clip(src, frames, joints)
    out_a, out_c = ctx.workdir / "clip.usda", ctx.workdir / "clip.usdc"
    settings = bvh_usd.ImportSettings(agent=True)

    usda = ctx.best_of(lambda: bvh_usd.import_bvh(src, out_a, settings), repeat=3)
    usdc = ctx.best_of(lambda: bvh_usd.import_bvh(src, out_c, settings), repeat=3)
    parse = ctx.best_of(lambda: bvh.load(src), repeat=3)
    motion = bvh.load(src)
    convert = ctx.best_of(lambda: bvh.convert(motion), repeat=3)
    pose, translations, rotations = bvh.convert(motion)

    def author():
        builder = bvh_usd.ClipLayerBuilder("clip", pose, settings, motion.skeleton.fps, {"source": src.name},
                                           None, None)
        builder.add(translations, rotations)
        return builder.finish()

    author_s = ctx.best_of(author, repeat=3)
    layer = author()
    save = ctx.best_of(lambda: layer.Export(str(ctx.workdir / "phase.usda")), repeat=3)
    peer = min(_peer(src) for _ in range(1 if ctx.quick else 2))
    exe = Path(sys.executable).with_name("mocapedit")
    cli = ctx.best_of(lambda: subprocess.run([str(exe), "import-bvh", str(src), "-o", str(out_a), "--agent", "-q"],
                                             check=True), repeat=2)

    figures = {
        "frames": frames, "joints": joints, "fileMB": round(src.stat().st_size / 1e6, 2),
        "importSeconds": round(usda, 4), "importSecondsUsdc": round(usdc, 4),
        "cliSeconds": round(cli, 4),
        "targetSeconds": 1.0, "meetsTarget": usda < 1.0,
        "phases": {"parse": round(parse, 4), "convert": round(convert, 4), "author": round(author_s, 4),
                   "saveUsda": round(save, 4)},
        "peer": "bvhio 1.5.4 readAsBvh (parse and per-joint Euler to quaternion, pure Python)",
        "peerSeconds": round(peer, 4), "speedupVsPeer": round(peer / usda, 2),
        "speedupVsPeerSameWork": round(peer / (parse + convert), 2),
    }
    if not ctx.quick:
        long_frames = 20000
        big = ctx.workdir / "long.bvh"
        write_clip(big, long_frames, joints, seed=6)
        t = time.perf_counter()
        bvh_usd.import_bvh(big, ctx.workdir / "long.usdc", settings)
        seconds = time.perf_counter() - t
        figures["streamed"] = {"frames": long_frames, "joints": joints, "fileMB": round(big.stat().st_size / 1e6, 1),
                               "chunkFrames": bvh.CHUNK_FRAMES, "seconds": round(seconds, 3),
                               "framesPerSecond": round(long_frames / seconds)}
    return figures
