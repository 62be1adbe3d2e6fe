"""mocapedit plugin-path: where the schema plugin lives, for PXR_PLUGINPATH_NAME."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plugin-path", help="print the folder to add to PXR_PLUGINPATH_NAME",
        description="Prints the folder holding the mocapEdit schema plugin (plugInfo.json). Load the "
                    "schema in usdview or a DCC with:\n  export PXR_PLUGINPATH_NAME=$(mocapedit plugin-path)"
                    "${PXR_PLUGINPATH_NAME:+:$PXR_PLUGINPATH_NAME}",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(run=run)


def run(args) -> int:
    from mocapedit import plugin_path
    print(plugin_path())
    return 0
