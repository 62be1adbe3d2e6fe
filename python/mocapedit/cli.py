"""Command line: ``mocapedit <command> ...``. Each command lives in ``mocapedit.commands``."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from . import __version__
from .errors import MocapEditError

DESCRIPTION = """\
Edit the motion capture of crowd agents in a USD shot stage without re-simulating.

Author small prims on the stage (MocapPositionConstraint, MocapTimeConstraint,
MocapAgentGroup, MocapAnimationLayer, ... from the mocapEdit schema), then run
`mocapedit solve shot.usda -o shot.edits.usda`. The input is never modified: the
result is a new layer that, placed over the input, plays the edited crowd in any
USD tool. Run `mocapedit <command> --help` for each command."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mocapedit", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"mocapedit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    from . import commands
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return 2
    try:
        return int(args.run(args) or 0)
    except MocapEditError as exc:
        print(f"mocapedit: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("mocapedit: interrupted; nothing was written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
