"""mocapedit detect-contacts: propose MocapFootContactAPI contacts where feet are planted."""
from __future__ import annotations

import argparse
import os
import sys

from mocapedit.geometry.contacts import DetectSettings
from mocapedit.cli.commands.detect_stationary import add_review_options, check_review_outputs, review_parser, save_review

HELP = "find where feet are planted in clips and write MocapFootContactAPI contacts for review"
DESCRIPTION = """\
Measures the ankle and toe of each leg of every clip on STAGE (each agent's source clip,
or each Skeleton's bound SkelAnimation in a plain clip layer) and finds the frame ranges
where the foot is planted: the joint is near the lowest height it reaches in the clip and
barely moves over the ground (stricter to enter a contact than to stay in it), for a
minimum duration. The contacts are written to a new layer CONTACTS as MocapFootContactAPI
instances on the SkelAnimation (footContact:left1:joint, footContact:left1:frames =
(first, last), inclusive 0-based frames); STAGE is not modified. Sub-layer CONTACTS over
STAGE to review them, edit or delete any, then keep the layer with the clip: a clip with
contacts uses exactly those when foot locking holds its feet in place.

  mocapedit detect-contacts walk.usda -o walk.contacts.usda
  mocapedit detect-contacts walk.usda -o walk.contacts.usda --height 0.03 --speed 0.2

Legs are found by joint name (CMU, Mixamo, Character Creator and similar rigs) or set on
the agent with mocap:leftLegJoints and mocap:rightLegJoints."""


# DetectSettings fields offered as options: (field, metavar, help).
THRESHOLDS = (
    ("height", "M", "height above the joint's lowest to enter a contact, metres"),
    ("release_height", "M", "height above the joint's lowest to stay in a contact, metres"),
    ("speed", "M_PER_S", "ground speed to enter a contact, metres per second"),
    ("release_speed", "M_PER_S", "ground speed to stay in a contact, metres per second"),
    ("min_duration", "SECONDS", "shortest contact, seconds"),
    ("max_gap", "SECONDS", "bridge breaks shorter than this between two contacts, seconds"),
    ("relative_speed", "FRACTION", "the speeds grow to this fraction of the foot's mean ground speed in the clip"),
)


def register(sub: argparse._SubParsersAction) -> None:
    d = DetectSettings()
    p = review_parser(sub, "detect-contacts", HELP, DESCRIPTION, "CONTACTS", "contacts layer to write")
    for field, metavar, what in THRESHOLDS:
        p.add_argument("--" + field.replace("_", "-"), type=float, default=getattr(d, field), metavar=metavar,
                       help=f"{what} (default {getattr(d, field)})")
    add_review_options(p, "", "contact names are <prefix>left1, <prefix>right1, ...", "CONTACTS")
    p.set_defaults(run=run)


def run(args) -> int:
    from mocapedit.tools import contact_tags
    from mocapedit.usd import reader
    from mocapedit.model.progress import Progress

    progress = Progress(quiet=args.quiet)
    settings = DetectSettings(**{field: getattr(args, field) for field, _, _ in THRESHOLDS})
    stage = reader.open_stage(args.stage)
    check_review_outputs(args, stage)
    clips, info, legless = contact_tags.detect(stage, settings, animation=args.animation, prefix=args.prefix)
    save_review(args, stage, contact_tags.build_layer(clips, info, settings), info)
    for path in legless:
        progress.message(f"<{path}>: no legs found by name, left out; set mocap:leftLegJoints and "
                         "mocap:rightLegJoints on it to find its contacts")
    for clip in clips:
        counts = ", ".join(f"{leg.side} {len(r)}" for leg, r in zip(clip.legs, clip.ranges))
        progress.message(f"<{clip.animation}> ({clip.frames} frames): contacts {counts}"
                         + (f"; {clip.note}" if clip.note else ""))
    if not args.quiet:
        print(f"wrote {os.path.abspath(args.output)}", file=sys.stderr)
    return 0
