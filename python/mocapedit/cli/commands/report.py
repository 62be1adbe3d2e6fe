"""mocapedit report: print the solve report stored in an edits layer."""
from __future__ import annotations

import argparse
import json

HELP = "print the solve report stored in an edits layer (a table per agent, or JSON)"
DESCRIPTION = """\
Prints the report that `mocapedit solve` stores in the edits layer it writes
(customLayerData mocapedit.report): run-wide counts and notes, then per agent the
constraints with their residuals and whether each is met, the path length ratio, the
displacement, the foot-skate change, the minimum separation to other agents, and the
solver and fallback notes. EDITS may also be a stage that sub-layers an edits layer.

By default only agents that were edited, are constrained, have notes or overlap
another agent are listed; --all lists every agent. --json prints the same data as
JSON for pipelines.

Exit status: 0 on success, 1 when the file cannot be read or holds no report."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("edits", metavar="EDITS", help="edits layer written by `mocapedit solve` (or a stage using one)")
    p.add_argument("--json", action="store_true", help="print the report as JSON (every agent)")
    p.add_argument("--all", action="store_true", help="list every agent, not only the edited or constrained ones")
    p.add_argument("--agent", metavar="PATTERN", action="append",
                   help="only agents whose prim path matches PATTERN (shell-style, e.g. '/World/Crowd/a*'); "
                        "repeat for several")
    p.set_defaults(run=run)


def run(args) -> int:
    from mocapedit.model import report
    from mocapedit.model.errors import MocapEditError
    from mocapedit.usd.report_io import read_report

    whole = read_report(args.edits)
    stored = report.select(whole, args.agent)
    if args.agent and not stored.report.agents:
        some = sorted(whole.report.agents)[:2]
        raise MocapEditError(f"--agent {' --agent '.join(args.agent)}: matches no agent of the report"
                             + (f" (its agents are like {', '.join(some)})" if some else " (it lists none)"))
    if args.json:
        print(json.dumps(stored.to_dict(), indent=2, sort_keys=True))
    else:
        print(report.format_text(stored, show_all=args.all or bool(args.agent)))
    return 0
