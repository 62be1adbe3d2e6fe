"""The base layer every shot case sub-layers: two toy agents of 24 frames (Z-up, cm, 24 fps)."""
from __future__ import annotations

import functools
import tempfile
from pathlib import Path

from pxr import Sdf

from conftest import write_toy_stage


@functools.lru_cache(maxsize=None)
def _base_text(no_scales: bool = False, no_samples: bool = False) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        path = write_toy_stage(Path(tmp) / "base.usda", agents=2, frames=24,
                               skip="samples" if no_samples else None)
        layer = Sdf.Layer.FindOrOpen(str(path))
        if no_scales:
            anim = layer.GetPrimAtPath("/World/agent0/Skel/Anim")
            anim.RemoveProperty(anim.properties["scales"])
        return layer.ExportToString()


def write_base(folder: Path, no_scales: bool = False, no_samples: bool = False) -> None:
    (Path(folder) / "base.usda").write_text(_base_text(no_scales, no_samples))
