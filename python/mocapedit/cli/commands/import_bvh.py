"""mocapedit import-bvh: convert BVH motion capture to UsdSkel clip layers."""
from __future__ import annotations

import argparse
import math
import os
import sys

HELP = "convert BVH motion capture files to UsdSkel clip layers"
USD_EXTENSIONS = (".usd", ".usda", ".usdc")
DESCRIPTION = """\
Converts BVH files to USD: a Skeleton "Skel" (joints, rest and bind transforms) holding
a SkelAnimation "Anim" (translations and rotations sampled at time codes 0..F-1), the
layout of mocapedit's clip layers, to reference into an agent; with --agent the default
prim is a SkelRoot named after the file with MocapAgentAPI, ready for `mocapedit solve`
and usdview. The layer sets metersPerUnit, upAxis and timeCodesPerSecond.

  mocapedit import-bvh walk.bvh -o walk.usda
  mocapedit import-bvh 131_01.bvh -o 131_01.usda --unit cmu --agent
  mocapedit import-bvh clips/ -o usd/            # every .bvh of a folder, in one call

Units: --meters-per-unit is the stage unit of the written layer (default 0.01, cm);
--unit says how long one BVH unit is (cm, m, mm, in, cmu = 1/0.45 inch, or metres as a
number) and sets the scale; or give --scale (stage units per BVH unit) directly.
BVH is Y-up: --up Z turns the clip about X at its roots.

Large files are streamed in chunks. A malformed file stops with its name and line
number (exit status 1) and nothing is written; with several files nothing is written
unless all convert, or use --keep-going."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import-bvh", help=HELP, description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", metavar="CLIP.bvh",
                   help="BVH files, or folders whose .bvh files are all converted")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="layer to write (.usda, .usdc or .usd) for one file; otherwise a folder, where "
                        "each file is written as <name><ext>")
    p.add_argument("--ext", choices=(".usda", ".usdc"), default=".usda",
                   help="extension of the layers written into a folder (default .usda)")
    p.add_argument("--fps", type=float, metavar="N",
                   help="frames per second (timeCodesPerSecond); default from Frame Time, snapped to the "
                        "rate a rounded Frame Time stands for (.0083333 -> 120)")
    units = p.add_mutually_exclusive_group()
    units.add_argument("--unit", default="cm", metavar="UNIT",
                       help="length of one BVH unit: cm (default), m, mm, in, ft, cmu, or metres as a number")
    units.add_argument("--scale", type=float, metavar="S",
                       help="stage units per BVH unit, instead of --unit")
    p.add_argument("--meters-per-unit", type=float, default=0.01, metavar="M",
                   help="metersPerUnit of the written layer (default 0.01: centimetres)")
    p.add_argument("--up", choices=("Y", "Z"), default="Y", help="upAxis of the written layer (default Y)")
    p.add_argument("--positions", choices=("auto", "absolute", "relative"), default="auto",
                   help="position channels replace the joint's OFFSET (absolute) or add to it (relative); "
                        "auto (default) decides per joint on its Yposition over the first frames: relative "
                        "when it stays nearer zero than the OFFSET's height (a hip-rooted rig)")
    p.add_argument("--end-sites", action="store_true",
                   help="also import End Sites as joints (<parent>_end), e.g. to draw head and toe tips")
    p.add_argument("--agent", action="store_true",
                   help="author the default prim as a SkelRoot agent with MocapAgentAPI")
    p.add_argument("--root-joint", metavar="JOINT",
                   help="the agent's mocap:rootJoint (the joint that carries the root motion), by BVH name")
    p.add_argument("--hip-joint", metavar="JOINT", help="the agent's mocap:hipJoint, by BVH name")
    p.add_argument("--name", help="name of the default prim (one input only; default: Skel, or the file name "
                                  "with --agent)")
    p.add_argument("--keep-going", action="store_true",
                   help="with several files, write every file that converts and report the others")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(run=run)


#: Lengths the unit options may give, in metres (or stage units per BVH unit for --scale): far
#: beyond any real rig either way, near enough that no joint position overflows.
UNIT_RANGE = (1e-9, 1e9)


def _in_range(option: str, value: float, what: str) -> float:
    from mocapedit.model.errors import MocapEditError
    low, high = UNIT_RANGE
    if not (math.isfinite(value) and value > 0):
        raise MocapEditError(f"{option} must be {what}, a finite number above 0, got {value:g}")
    if not low <= value <= high:
        raise MocapEditError(f"{option} {value:g} is outside {low:g} .. {high:g}: check it")
    return value


def _scale(args) -> float:
    from mocapedit.formats.bvh import UNITS
    from mocapedit.model.errors import MocapEditError
    mpu = _in_range("--meters-per-unit", args.meters_per_unit, "the stage unit in metres")
    if args.scale is not None:
        return _in_range("--scale", args.scale, "stage units per BVH unit")
    unit = UNITS.get(args.unit.lower())
    if unit is None:
        try:
            unit = float(args.unit)
        except ValueError:
            raise MocapEditError(f"--unit '{args.unit}' is neither a unit name ({', '.join(UNITS)}) nor a "
                                 "length in metres") from None
        unit = _in_range("--unit", unit, "a length in metres")
    return unit / mpu


def _inputs(args) -> tuple[list[str], bool]:
    """(files, whether the output is a folder)."""
    from mocapedit.formats.bvh import find_files
    from mocapedit.model.errors import MocapEditError
    files, folder = [], len(args.inputs) > 1
    for item in args.inputs:
        if os.path.isdir(item):
            found = find_files(item)
            if not found:
                raise MocapEditError(f"{item}: no .bvh files in this folder")
            files.extend(found)
            folder = True
        elif os.path.isfile(item):
            files.append(item)
        else:
            raise MocapEditError(f"{item}: no such file or folder")
    out = args.output
    is_layer = out.lower().endswith(USD_EXTENSIONS)
    if folder and is_layer and not os.path.isdir(out):
        raise MocapEditError(f"-o {out}: {len(files)} clips are written into a folder, one layer each; "
                             f"give a folder (a name without {', '.join(USD_EXTENSIONS)}), or one .bvh for this layer")
    if not folder and not is_layer and not os.path.isdir(out) and \
            (os.path.isfile(out) or os.path.splitext(out.rstrip("/" + os.sep))[1]):
        raise MocapEditError(f"-o {out}: a clip is written as a USD layer ({', '.join(USD_EXTENSIONS)}); "
                             f"give such a file, or a folder to write it into")
    if os.path.isdir(out) or not is_layer:
        folder = True
    return files, folder


def _check_height(result, progress) -> None:
    if not 0.3 <= result.height_m <= 3.0:
        progress.message(f"  note: {os.path.basename(result.source)} stands {result.height_m:.2f} m tall in "
                         "frame 0; check --unit/--scale and --meters-per-unit")


def run(args) -> int:
    from mocapedit.formats.bvh import FRAME_TIME_RANGE
    from mocapedit.usd.bvh_usd import ImportSettings, import_bvh, import_many
    from mocapedit.model.errors import MocapEditError
    from mocapedit.model.progress import Progress

    progress = Progress(quiet=args.quiet)
    low, high = (1.0 / t for t in reversed(FRAME_TIME_RANGE))
    if args.fps is not None and not low <= args.fps <= high:
        raise MocapEditError(f"--fps must be between {low:g} and {high:g}, got {args.fps:g}")
    settings = ImportSettings(scale=_scale(args), meters_per_unit=args.meters_per_unit, up_axis=args.up,
                              fps=args.fps, position_mode=args.positions, end_sites=args.end_sites,
                              agent=args.agent, root_joint=args.root_joint, hip_joint=args.hip_joint,
                              name=args.name)
    files, folder = _inputs(args)
    if not folder:
        result = import_bvh(files[0], args.output, settings, progress)
        _check_height(result, progress)
        progress.message(f"wrote {os.path.abspath(args.output)}: {result.joints} joints, {result.frames} frames "
                         f"at {result.fps:g} fps, {result.height_m:.2f} m tall")
        return 0
    if args.name:
        raise MocapEditError("--name names the prim of one file; it cannot be used with several inputs")
    done, failed = import_many(files, args.output, settings, progress, ext=args.ext,
                               keep_going=args.keep_going)
    for result in done:
        _check_height(result, progress)
    for source, message in failed:
        print(f"mocapedit: error: {message}", file=sys.stderr)
    progress.message(f"wrote {len(done)} of {len(files)} clips to {os.path.abspath(args.output)}")
    return 1 if failed else 0
