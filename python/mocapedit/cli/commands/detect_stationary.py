"""mocapedit detect-stationary: propose MocapStationaryAPI tags where a clip stands still."""
from __future__ import annotations

import argparse
import os
import sys

from mocapedit.geometry.stationary import DetectSettings

HELP = "find where clips stand still and write MocapStationaryAPI tags for review"
DESCRIPTION = """\
Measures the root of every clip on STAGE (each agent's source clip, or each Skeleton's
bound SkelAnimation in a plain clip layer) and tags the frame ranges where its ground
speed and its turning rate stay under thresholds for a minimum duration. The tags are
written to a new layer TAGS as MocapStationaryAPI instances on the SkelAnimation
(stationary:auto1:frames = (first, last), inclusive 0-based frames); STAGE is not
modified. Sub-layer TAGS over STAGE to review them (usdview, or --composed), edit or
delete any, then keep the layer with the clip.

  mocapedit detect-stationary walk.usda -o walk.tags.usda
  mocapedit detect-stationary walk.usda -o walk.tags.usda --max-speed 0.1 --min-duration 1

Speed and turning are measured over a short window (--window) so that mocap jitter and
the sway of the hips do not count; a range therefore starts and ends about half a
window inside the idle section."""


def register(sub: argparse._SubParsersAction) -> None:
    d = DetectSettings()
    p = review_parser(sub, "detect-stationary", HELP, DESCRIPTION, "TAGS", "tags layer to write")
    p.add_argument("--max-speed", type=float, default=d.max_speed, metavar="M_PER_S",
                   help=f"largest ground speed of the root, metres per second (default {d.max_speed})")
    p.add_argument("--max-turn", type=float, default=d.max_turn, metavar="DEG_PER_S",
                   help=f"largest turning rate of the root's facing, degrees per second (default {d.max_turn:g})")
    p.add_argument("--min-duration", type=float, default=d.min_duration, metavar="SECONDS",
                   help=f"shortest range to tag, seconds (default {d.min_duration})")
    p.add_argument("--window", type=float, default=d.window, metavar="SECONDS",
                   help=f"window over which speed and turning are measured, seconds (default {d.window})")
    p.add_argument("--max-gap", type=float, default=d.max_gap, metavar="SECONDS",
                   help=f"bridge interruptions shorter than this between two ranges, seconds (default {d.max_gap})")
    p.add_argument("--root-joint", metavar="JOINT",
                   help="measure this joint (name or joint path) instead of each agent's root joint")
    add_review_options(p, "auto", "tag names are <prefix>1, <prefix>2, ... (default auto)", "TAGS")
    p.set_defaults(run=run)


def review_parser(sub: argparse._SubParsersAction, name: str, help: str, description: str, layer_name: str,
                  layer_help: str) -> argparse.ArgumentParser:
    """A command that reads STAGE and writes proposed tags to a new layer for review."""
    p = sub.add_parser(name, help=help, description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("stage", metavar="STAGE", help="a clip layer or a shot stage (.usd, .usda, .usdc)")
    p.add_argument("-o", "--output", required=True, metavar=layer_name, help=layer_help)
    return p


def add_review_options(p: argparse.ArgumentParser, prefix: str, prefix_help: str, layer_name: str) -> None:
    """The options every command that proposes tags for review shares."""
    p.add_argument("--animation", metavar="PRIM", help="only the clip at this SkelAnimation path")
    p.add_argument("--prefix", default=prefix, help=prefix_help)
    p.add_argument("--composed", metavar="OUT", help=f"also write a stage that sub-layers {layer_name} over STAGE")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


def check_review_outputs(args, stage) -> None:
    """Refuses, before any work, outputs that name the input or a layer it uses (see outputs)."""
    from mocapedit.usd import outputs
    stem = "." + args.command.split("-", 1)[-1]    # detect-contacts: .contacts
    outputs.check_outputs([outputs.Output(args.output, "-o", stem=stem),
                           outputs.Output(args.composed, "--composed", stem=stem + ".composed")],
                          outputs.input_files(stage))


def save_review(args, stage, layer, info) -> None:
    """Writes the proposed tags (and with --composed, a stage to review them on), together."""
    from mocapedit.usd import outputs, writer
    with outputs.Writes() as w:
        w.add(args.output, writer.export_layer(layer))
        if args.composed:
            w.add(args.composed, writer.export_layer(writer.composed_layer(
                args.composed, args.output, args.stage, info, stage.GetRootLayer().defaultPrim or None)))


def run(args) -> int:
    from mocapedit.usd import reader
    from mocapedit.tools import tags
    from mocapedit.model.progress import Progress

    progress = Progress(quiet=args.quiet)
    settings = DetectSettings(max_speed=args.max_speed, max_turn=args.max_turn, min_duration=args.min_duration,
                              window=args.window, max_gap=args.max_gap)
    stage = reader.open_stage(args.stage)
    check_review_outputs(args, stage)
    clips, info = tags.detect(stage, settings, root_joint=args.root_joint, animation=args.animation,
                              prefix=args.prefix)
    save_review(args, stage, tags.build_layer(clips, info, settings), info)
    for clip in clips:
        tagged = ", ".join(f"{name} ({a}-{b})" for name, a, b in clip.existing)
        progress.message(f"<{clip.animation}> ({clip.frames} frames, measured on {clip.joint.rsplit('/', 1)[-1]}): "
                         f"{len(clip.ranges)} stationary range{'s' if len(clip.ranges) != 1 else ''}"
                         + (f"; already tagged: {tagged}" if tagged else ""))
        for name, r in zip(clip.names, clip.ranges):
            bridged = (f"; bridges {r.bridged} frame{'s' if r.bridged != 1 else ''} of shorter gaps (--max-gap) "
                       f"reaching {r.bridged_max_speed:.3f} m/s, {r.bridged_max_turn:.1f} deg/s") if r.bridged else ""
            progress.message(f"  {name}: frames {r.first}-{r.last} ({r.duration:.2f} s), "
                             f"speed <= {r.max_speed:.3f} m/s, turning <= {r.max_turn:.1f} deg/s{bridged}")
    if not args.quiet:
        print(f"wrote {os.path.abspath(args.output)}", file=sys.stderr)
    return 0
