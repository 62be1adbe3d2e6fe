"""mocapedit: edit the motion-capture animation of crowd agents directly in OpenUSD.

Importing the package registers the ``mocapEdit`` schema plugin with USD, so the
``Mocap*`` prim types and API schemas resolve on any stage opened afterwards.
"""
from __future__ import annotations

import os
from pathlib import Path

__version__ = "0.1.0"

_PLUGIN_REGISTERED = False


def plugin_path() -> str:
    """Folder holding the schema plugin's ``plugInfo.json``.

    Point ``PXR_PLUGINPATH_NAME`` at it to load the schema in usdview or a DCC.
    """
    here = Path(__file__).resolve().parent
    for candidate in (here / "plugin" / "mocapEdit",
                      here.parent.parent / "plugin" / "mocapEdit"):
        if (candidate / "plugInfo.json").is_file():
            return str(candidate)
    raise RuntimeError(
        "mocapedit: the schema plugin (plugInfo.json) was not found beside the package; "
        "reinstall mocapedit or run 'make' in the source tree")


def register_plugin() -> None:
    """Register the mocapEdit schema plugin in this process (idempotent)."""
    global _PLUGIN_REGISTERED
    if _PLUGIN_REGISTERED:
        return
    from pxr import Plug
    Plug.Registry().RegisterPlugins(plugin_path())
    _PLUGIN_REGISTERED = True


if os.environ.get("MOCAPEDIT_NO_PLUGIN") != "1":
    try:
        register_plugin()
    except RuntimeError:
        # The generated plugin is missing only inside a broken source checkout; the
        # schema-regeneration tooling imports the package before the plugin exists.
        pass
