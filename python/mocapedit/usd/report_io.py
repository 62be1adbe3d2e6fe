"""Reading the solve report back from an edits layer (``customLayerData`` mocapedit ``report``),
with the layer's provenance and units, as ``mocapedit report`` prints it.
"""
from __future__ import annotations

import json
import os

from pxr import Sdf, Usd

from mocapedit.model.errors import MocapEditError
from mocapedit.model.report import Report, StoredReport


def _layer_report(layer) -> dict | None:
    data = dict(layer.customLayerData or {}).get("mocapedit")
    if not isinstance(data, dict) or "report" not in data:
        return None
    return data


def read_report(path: str) -> StoredReport:
    """Reads the report from an edits layer, or from the edits layer a stage sub-layers.

    Raises:
      MocapEditError: the file cannot be read or holds no mocapedit report.
    """
    if not os.path.exists(path):
        raise MocapEditError(f"{path}: no such file")
    try:
        layer = Sdf.Layer.FindOrOpen(path)
    except Exception as exc:  # pxr raises Tf.ErrorException
        raise MocapEditError(f"{path}: cannot be read as a USD layer: {str(exc).strip().splitlines()[-1]}") from None
    if layer is None:
        raise MocapEditError(f"{path}: cannot be read as a USD layer")
    data = _layer_report(layer)
    if data is None:
        # A composed stage: the edits layer is one of the layers it uses.
        stage = Usd.Stage.Open(layer)
        for used in sorted(stage.GetUsedLayers(), key=lambda l: l.identifier):
            data = _layer_report(used)
            if data is not None:
                layer = used
                break
    if data is None:
        raise MocapEditError(f"{path}: holds no mocapedit report (customLayerData mocapedit.report); "
                             "write one with `mocapedit solve STAGE -o EDITS`")
    try:
        parsed = json.loads(data["report"])
    except (TypeError, ValueError) as exc:
        raise MocapEditError(f"{layer.identifier}: customLayerData mocapedit.report is not valid JSON: {exc}") from None
    root = layer.pseudoRoot
    return StoredReport(
        file=layer.identifier, report=Report.from_dict(parsed), version=str(data.get("version", "")),
        inputs=[str(x) for x in data.get("inputs", [])], content_hash=str(data.get("contentHash", "")),
        meters_per_unit=float(root.GetInfo("metersPerUnit")) if root.HasInfo("metersPerUnit") else None,
        up_axis=str(root.GetInfo("upAxis")) if root.HasInfo("upAxis") else None)
