"""mocapedit solve: apply every edit authored on a stage and write the edits layer."""
from __future__ import annotations

import argparse
import os
import sys

from mocapedit.cli.commands import add_solve_options

HELP = "solve the edits authored on a stage and write them as a new layer"
DESCRIPTION = """\
Reads STAGE (never modifying it), solves every active mocapEdit prim on it (position,
relative, time and sync constraints, stationary tags, groups, path curves, avoid
regions, animation layers, solve settings) and writes one layer holding only the
edits: `over`s on edited agents and new prims under /MocapEdit (guides under
/MocapEdit/Guides, purpose 'guide'). Sub-layer it over the input, or pass --composed
to get a ready stage. The same input gives the same bytes.

The shot is STAGE's startTimeCode to endTimeCode (every frame the clips play when it
has none): collision avoidance parts, and the report counts and judges, only what
plays there.

The solver splits its heavier steps over two threads; MOCAPEDIT_THREADS=N caps the
threads it may use (1 on a farm slot of one core). The bytes written are the same.

Exit status: 0 on success, 1 on bad input (the message names the prim and property),
2 on bad usage. Nothing is written on error."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("solve", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("stage", metavar="STAGE", help="input shot stage (.usd, .usda, .usdc)")
    p.add_argument("-o", "--output", required=True, metavar="EDITS",
                   help="edits layer to write (.usda for text, .usdc for large crowds)")
    p.add_argument("--composed", metavar="OUT",
                   help="also write a stage that sub-layers EDITS over STAGE, for viewing")
    add_solve_options(p)
    p.add_argument("--report", metavar="JSON", help="also write the solve report as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(run=run)


def run(args) -> int:
    from mocapedit.pipeline.processor import solve
    from mocapedit.model.progress import Progress

    progress = Progress(quiet=args.quiet)
    overrides = {} if args.match_speed is None else {"match_speed": args.match_speed}
    for name in ("foot_locking", "pivot_on_feet"):
        if getattr(args, name) is not None:
            overrides[name] = getattr(args, name)
    result = solve(args.stage, output=args.output, composed=args.composed, guides=args.guides,
                   collisions=args.collisions, progress=progress, report_json=args.report, **overrides)
    if not args.quiet:
        print(result.report.summary(), file=sys.stderr)
        written = [args.output] + [p for p in (args.composed, args.report) if p]
        print("wrote " + " and ".join(os.path.abspath(p) for p in written), file=sys.stderr)
    return 0
