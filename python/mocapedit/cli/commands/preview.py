"""mocapedit preview: a top-down picture of the crowd (PNG for people, EXR for compositing)."""
from __future__ import annotations

import argparse
import os
import sys

HELP = "draw a top-down view of the crowd: source and edited paths, constraints, collisions"
DESCRIPTION = """\
Reads STAGE (and the edits layer over it) and draws the crowd seen from above. It
solves nothing: run `mocapedit solve` first. STAGE may be the input with --edits
EDITS, or a stage that already sub-layers an edits layer (the --composed output of
`mocapedit solve`); a stage without edits shows its source paths.

-o top.png: a picture for people: source and edited paths, constraint handles (green
met, red not met, yellow not solved), relative and sync constraint links, avoid
regions, the collisions left between agents, a scale bar and a legend.

-o top.exr: a world-aligned 32-bit float image for compositing, with square pixels
and the world-to-pixel mapping in its header (mocapedit:worldToPixel, a 3x3 matrix
with [a, b, 1] @ M = [column, row, 1] for world (x, z) on Y-up stages, (x, y) on Z-up
stages). Channels: sourcePathDensity and editedPathDensity (agents whose path crosses
the pixel), displacement (stage units between edited and source position at the same
shot time), overlapCount (agent pairs overlapping there, summed over time samples).

Exit status: 0 on success, 1 on bad input; nothing is written on error."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("preview", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("stage", metavar="STAGE", help="input stage, or a stage that sub-layers an edits layer")
    p.add_argument("--edits", metavar="EDITS", help="edits layer to put over STAGE (from `mocapedit solve -o`)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="image to write: .png or .exr")
    p.add_argument("--resolution", metavar="N|WxH", default=None,
                   help="pixels: N for the longer side (default 1600), or exact WxH (the view "
                        "grows to keep pixels square)")
    p.add_argument("--bounds", nargs=4, type=float, metavar=("MINA", "MINB", "MAXA", "MAXB"),
                   help="world area to show, in stage units: x and z on a Y-up stage, x and y on a "
                        "Z-up stage (default: everything, padded)")
    p.add_argument("--step", type=float, metavar="TIMECODES",
                   help="time between the samples checked for collisions (default: the stage's "
                        "MocapSolveSettings sampleStep, else 1)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(run=run)


def run(args) -> int:
    from mocapedit.usd import outputs
    from mocapedit.tools import preview
    from mocapedit.model.errors import MocapEditError
    from mocapedit.model.progress import Progress

    if args.step is not None and not args.step > 0:
        raise MocapEditError(f"--step must be positive, got {args.step:g}")
    outputs.check_outputs([outputs.Output(args.output, "-o", kind="image", extensions=(".png", ".exr"))],
                          [p for p in (args.stage, args.edits) if p])
    preview.parse_resolution(args.resolution)
    progress = Progress(quiet=args.quiet)
    scene = preview.load(args.stage, args.edits, progress, args.step)
    bounds = preview.bounds_from_plan(args.bounds, scene.up_axis) if args.bounds else None
    preview.write(scene, args.output, args.resolution, bounds, progress)
    if not args.quiet:
        print(f"wrote {os.path.abspath(args.output)}", file=sys.stderr)
    return 0
