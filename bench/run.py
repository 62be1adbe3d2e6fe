#!/usr/bin/env python3
"""`make bench`: every speed figure, each measured next to a peer in the same run.

Each ``bench/bench_*.py`` module defines ``run(ctx) -> dict``; the results are gathered into
one JSON file. A figure is reported with its target (from DESIGN.md) and, where there is a
peer (a scipy.sparse version of the same solve, a naive loop), the ratio to it, so the
numbers can be read on a noisy machine.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


class Context:
    def __init__(self, workdir: Path, quick: bool):
        self.workdir = workdir
        self.quick = quick

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
    args = ap.parse_args()

    results = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                           "cpus": os.cpu_count()}, "benchmarks": {}}
    modules = sorted(HERE.glob("bench_*.py"))
    with tempfile.TemporaryDirectory(prefix="mocapedit-bench-") as tmp:
        ctx = Context(Path(tmp), args.quick)
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
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(results, f, indent=2, sort_keys=True)
        f.write("\n")
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
