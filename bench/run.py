#!/usr/bin/env python3
"""`make bench`: every speed figure, each measured next to a peer in the same run.

Each ``bench/bench_*.py`` module defines ``run(ctx) -> dict``; the results are gathered into
one JSON file. Each module runs in a fresh Python process, so no benchmark measures the heap
and caches another left behind (the 10,000-agent collision run would otherwise slow the
sub-millisecond path solves after it). A figure is reported with its target (from DESIGN.md) and, where there is a
peer (a scipy.sparse version of the same solve, a naive loop), the ratio to it, so the
numbers can be read on a noisy machine.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


class Context:
    def __init__(self, workdir: Path, quick: bool, large: bool = False):
        self.workdir = workdir
        self.quick = quick
        self.large = large

    @staticmethod
    def best_of(fn, repeat: int = 5, number: int = 1) -> float:
        """Best wall time of ``fn`` in seconds over ``repeat`` rounds of ``number`` calls."""
        best = float("inf")
        for _ in range(repeat):
            t = time.perf_counter()
            for _ in range(number):
                fn()
            best = min(best, (time.perf_counter() - t) / number)
        return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(HERE / "results" / "bench.json"), help="JSON file to write")
    ap.add_argument("--only", nargs="*", help="run only these benchmark modules (e.g. reader path)")
    ap.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke run")
    ap.add_argument("--large", action="store_true",
                    help="add the largest sizes (the scale benchmark's 30,000 agents: minutes)")
    ap.add_argument("--in-process", action="store_true",
                    help="run the selected modules in this process instead of one fresh process each")
    args = ap.parse_args()

    from mocapedit import _solver
    results = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                           "cpus": os.cpu_count(), "blas": _blas(_solver.blas())}, "benchmarks": {}}
    modules = sorted(HERE.glob("bench_*.py"))
    names = [p.stem[len("bench_"):] for p in modules if not args.only or p.stem[len("bench_"):] in args.only]
    if not args.in_process:
        with tempfile.TemporaryDirectory(prefix="mocapedit-bench-") as tmp:
            for name in names:
                out = Path(tmp) / f"{name}.json"
                cmd = [sys.executable, __file__, "--in-process", "--only", name, "--out", str(out)]
                cmd += (["--quick"] if args.quick else []) + (["--large"] if args.large else [])
                subprocess.run(cmd, check=True)
                results["benchmarks"].update(json.loads(out.read_text())["benchmarks"])
        return _write(results, args.out)
    with tempfile.TemporaryDirectory(prefix="mocapedit-bench-") as tmp:
        ctx = Context(Path(tmp), args.quick, args.large)
        for path in modules:
            name = path.stem[len("bench_"):]
            if args.only and name not in args.only:
                continue
            spec = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            print(f"bench {name} ...", file=sys.stderr, flush=True)
            t = time.perf_counter()
            figures = module.run(ctx)
            figures["benchSeconds"] = round(time.perf_counter() - t, 3)
            results["benchmarks"][name] = figures
            print(json.dumps({name: figures}, indent=2, sort_keys=True), file=sys.stderr, flush=True)
    return _write(results, args.out)


def _blas(info) -> dict:
    return {"name": info.name, "concurrent": info.concurrent}


def _write(results: dict, out: str) -> int:
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out, "w") as f:
        json.dump(results, f, indent=2, sort_keys=True)
        f.write("\n")
    print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
