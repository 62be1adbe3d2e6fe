"""One module per ``mocapedit`` sub-command; each defines ``register(subparsers)``."""
from __future__ import annotations

import argparse


def add_solve_options(p: argparse.ArgumentParser) -> None:
    """The options of a solve, shared by ``solve`` and ``batch``."""
    p.add_argument("--no-guides", dest="guides", action="store_false",
                   help="do not author guide curves and points under /MocapEdit/Guides")
    # Each switch and its opposite exclude each other: given both, argparse says so.
    collisions = p.add_mutually_exclusive_group()
    collisions.add_argument("--collisions", dest="collisions", action="store_true", default=None,
                            help="run collision avoidance even if MocapSolveSettings does not ask for it")
    collisions.add_argument("--no-collisions", dest="collisions", action="store_false",
                            help="skip collision avoidance even if MocapSolveSettings asks for it")
    speed = p.add_mutually_exclusive_group()
    speed.add_argument("--match-speed", dest="match_speed", action="store_true", default=None,
                       help="re-time edited paths so each agent keeps its source speed along its new path "
                            "(MocapSolveSettings.matchSpeed)")
    speed.add_argument("--no-match-speed", dest="match_speed", action="store_false",
                       help="keep the source timing on edited paths even if MocapSolveSettings asks to match speed")
    p.add_argument("--no-foot-locking", dest="foot_locking", action="store_false", default=None,
                   help="leave the feet as the edits put them (MocapSolveSettings.footLocking off)")
    p.add_argument("--no-pivot-on-feet", dest="pivot_on_feet", action="store_false", default=None,
                   help="carry each frame's pose rigidly along the edited path, turned about the root, instead "
                        "of turning between steps and pivoting on the planted feet (MocapSolveSettings.pivotOnFeet off)")
