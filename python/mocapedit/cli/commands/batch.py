"""mocapedit batch: solve many shots with the same options on a Dask cluster."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

from mocapedit.cli.commands import add_solve_options

HELP = "solve many shots with the same options on Dask (a local cluster or a running scheduler)"
DESCRIPTION = """\
Solves each SHOT as `mocapedit solve` would, with the same options for all, and writes
OUTDIR/<shot name>.edits.usdc (atomically, byte for byte what `mocapedit solve` writes)
and OUTDIR/batch-summary.json (every shot's result, figures and error).

The shots run on dask.distributed: by default on a local cluster of worker processes
(--workers), or on a running cluster given by --scheduler tcp://host:port (`dask
scheduler` and `dask worker`, dask-jobqueue, Kubernetes); its workers must have
mocapedit installed and see SHOT and OUTDIR at the same paths. One failing shot does
not stop the others. A shot whose output already records the same input content hash
and options is skipped (--force solves it again).

--split-components also sends each shot's independent path components (agents
that no relative constraint or group ties together), and then its edited agents'
foot locking, to the workers as tasks of their own, so workers left idle by a
batch of fewer shots than workers help solve them; the edits layer is the same
bytes. It is a switch, not automatic: each task carries its agents' clips and
paths, and a path component's solve takes a few milliseconds, near what a task
costs, so it pays only when workers would be idle. Time warp, collision avoidance
(which couples agents that can meet), layering, inspection and writing run in the
shot's own task either way.

Each worker of the local cluster solves on its share of the machine's threads (the
threads over the workers), or on MOCAPEDIT_THREADS when it is set; set it for the
workers of a running cluster too (MOCAPEDIT_THREADS=1 dask worker ... --nthreads 1).

Exit status: 0 when every shot was solved or skipped, 1 when any failed or on bad
input (a missing shot, two shots writing the same output, an unreachable scheduler:
then nothing is solved), 2 on bad usage."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("shots", metavar="SHOT", nargs="+", help="input shot stages")
    p.add_argument("-o", "--outdir", required=True, metavar="OUTDIR", help="folder for the edits layers")
    p.add_argument("--suffix", default=".edits.usdc",
                   help="output name after the shot's stem (default .edits.usdc; .edits.usda for text)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:port) instead of a local cluster")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local cluster (default: the CPU count, at most 8)")
    p.add_argument("--split-components", action="store_true",
                   help="solve each shot's path components and foot locking as tasks of their own (same bytes)")
    p.add_argument("--force", action="store_true", help="solve shots whose outputs are up to date too")
    p.add_argument("--summary", metavar="JSON",
                   help="where to write the summary, a .json file (default OUTDIR/batch-summary.json); "
                        "like the edits layers, it may not name a file any shot reads")
    add_solve_options(p)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(run=run)


def run(args) -> int:
    from mocapedit.pipeline import batch
    from mocapedit.model.errors import MocapEditError
    from mocapedit.usd.outputs import record_committed, save_text

    if args.workers is not None and args.workers < 1:
        raise MocapEditError(f"--workers must be at least 1, got {args.workers}")
    jobs = batch.plan(args.shots, args.outdir, args.suffix, summary=args.summary)
    options = {"guides": args.guides, "collisions": args.collisions}
    if args.match_speed is not None:
        options["match_speed"] = args.match_speed
    for name in ("foot_locking", "pivot_on_feet"):
        if getattr(args, name) is not None:
            options[name] = getattr(args, name)
    t = time.perf_counter()
    client, cluster = batch.connect(args.scheduler, args.workers)

    def report(result, done, failed, remaining):
        if args.quiet:
            return
        what = result.status + (f": {result.error}" if result.error else f" in {result.seconds:.2f} s")
        print(f"batch: {done - failed} done, {failed} failed, {remaining} remaining  "
              f"[{os.path.basename(result.shot)} {what}]", file=sys.stderr, flush=True)
        if result.status == "solved" and not result.figures.get("agents"):
            # Solved with nothing to solve: what solve would have said (all notes are in the summary).
            for note in result.notes:
                print(f"  {os.path.basename(result.shot)}: note: {note}", file=sys.stderr, flush=True)

    started = time.time()
    try:
        results = batch.run(jobs, options, client, force=args.force, on_result=report,
                            split=args.split_components)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
        # The workers write the edits layers (each whole, or not at all): a stop names those
        # written by now, as the files this process wrote are named.
        for path in batch.written_since(jobs, started):
            record_committed(path)
    summary = batch.summary(results, options, time.perf_counter() - t)
    path = args.summary or os.path.join(args.outdir, batch.SUMMARY)
    save_text(path, json.dumps(summary, indent=2, sort_keys=True) + "\n")
    if not args.quiet:
        print(f"batch: {summary['solved']} solved, {summary['skipped']} skipped, {summary['failed']} failed "
              f"in {summary['seconds']:.1f} s; summary {os.path.abspath(path)}", file=sys.stderr)
    return 1 if summary["failed"] else 0
