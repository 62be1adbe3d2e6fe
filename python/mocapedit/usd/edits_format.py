"""The format of what mocapedit records in a layer: ``customLayerData["mocapedit"]``.

Every layer mocapedit writes carries it: the edits layer (version, input layers, content hash,
options, statistics and the whole solve report as compact JSON text), the tag layers of
``detect-stationary`` / ``detect-contacts`` (their settings) and imported BVH clips (their
source). This module holds the keys and the one way to write and read them.
"""
from __future__ import annotations

import json
import math
import os

import numpy as np
from pxr import Sdf, Usd, Vt

from mocapedit import __version__
from mocapedit.model.errors import MocapEditError
from mocapedit.model.report import finite_values
from mocapedit.usd.errors import usd_messages

__all__ = ["KEY", "VERSION", "INPUTS", "CONTENT_HASH", "OPTIONS", "STATS", "REPORT",
           "write", "layer_value", "report_text", "data", "edits_layer", "content_hash", "recorded",
           "stored_report", "read_report"]

#: The customLayerData entry that holds mocapedit's data.
KEY = "mocapedit"
#: Keys inside it.
VERSION = "version"          # mocapedit's version that wrote the layer
INPUTS = "inputs"            # the input stage's layers (edits layer)
CONTENT_HASH = "contentHash"  # hash of what the solve read (edits layer)
OPTIONS = "options"          # the solve options as text (edits layer)
STATS = "stats"              # solve statistics (edits layer)
REPORT = "report"            # the solve report, compact JSON text (edits layer)


def write(layer: Sdf.Layer, entries: dict) -> None:
    """Sets the layer's ``customLayerData["mocapedit"]``: the version, then ``entries``."""
    layer.customLayerData = {KEY: {VERSION: __version__, **entries}}


def layer_value(value):
    """A value made fit for customLayerData: lists of numbers or strings become Vt arrays;
    entries of a dictionary that are None are left out (USD cannot hold an empty value: it
    warns and skips them as it writes), and so are numbers that are not finite (a figure with
    nothing to measure: ``nan`` in a layer means nothing to a reader)."""
    if isinstance(value, dict):
        return {str(k): layer_value(v) for k, v in value.items()
                if v is not None and not (isinstance(v, (float, np.floating)) and not math.isfinite(v))}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        if all(isinstance(v, str) for v in value):
            return Vt.StringArray(list(value))
        if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in value):
            return Vt.IntArray([int(v) for v in value])
        return Vt.DoubleArray([float(v) for v in value])
    if isinstance(value, np.generic):
        return value.item()
    return value


def report_text(report: dict) -> str:
    """The report as stored in the layer: compact JSON, sorted keys, non-finite numbers as null."""
    return json.dumps(finite_values(report), sort_keys=True, separators=(",", ":"), allow_nan=False)


def data(layer: Sdf.Layer | None) -> dict | None:
    """The layer's ``customLayerData["mocapedit"]``, or None when it has none."""
    found = dict(layer.customLayerData or {}).get(KEY) if layer else None
    return found if isinstance(found, dict) else None


def edits_layer(stage: Usd.Stage) -> Sdf.Layer | None:
    """The edits layer a stage uses (its mocapedit data has a content hash), or None."""
    for layer in sorted(stage.GetUsedLayers(), key=lambda l: l.identifier):
        if CONTENT_HASH in (data(layer) or {}):
            return layer
    return None


def content_hash(layer: Sdf.Layer) -> str | None:
    """The content hash an edits layer records, or None."""
    return (data(layer) or {}).get(CONTENT_HASH)


def recorded(path: str) -> tuple[str | None, str | None]:
    """(content hash, options text) recorded in the edits layer at ``path``; (None, None) when
    there is none or it cannot be read (an unreadable old output is solved again)."""
    if not os.path.isfile(path):
        return None, None
    try:
        layer = Sdf.Layer.OpenAsAnonymous(path)
    except Exception:  # pxr raises Tf.ErrorException
        return None, None
    found = data(layer) or {}
    return found.get(CONTENT_HASH), found.get(OPTIONS)


def stored_report(layer: Sdf.Layer) -> dict | None:
    """The solve report an edits layer stores, parsed, or None when it stores none."""
    found = data(layer) or {}
    return json.loads(found[REPORT]) if REPORT in found else None


def _with_report(layer: Sdf.Layer) -> dict | None:
    found = data(layer)
    return found if found is not None and REPORT in found else None


def read_report(path_or_layer) -> dict:
    """The report of an edits layer, or of the edits layer a stage sub-layers.

    ``path_or_layer``: a file path or an ``Sdf.Layer``. Returns ``{"file": identifier of the
    edits layer, "report": the parsed report, "version", "inputs" (list of str), "contentHash",
    "metersPerUnit" and "upAxis" (None when the layer does not say)}``.

    Raises:
      MocapEditError: the file cannot be read or holds no mocapedit report.
    """
    if isinstance(path_or_layer, Sdf.Layer):
        layer, path = path_or_layer, path_or_layer.identifier
    else:
        path = os.fspath(path_or_layer)
        if not os.path.exists(path):
            raise MocapEditError(f"{path}: no such file")
        if os.path.isdir(path):
            raise MocapEditError(f"{path}: is a folder; give an edits layer or a composed stage file")
        try:
            layer = Sdf.Layer.FindOrOpen(path)
        except Exception as exc:  # pxr raises Tf.ErrorException
            raise MocapEditError(f"{path}: cannot be read as a USD layer: "
                                 f"{'; '.join(usd_messages(str(exc)))}") from None
        if layer is None:
            raise MocapEditError(f"{path}: cannot be read as a USD layer")
    found = _with_report(layer)
    if found is None:
        # A composed stage: the edits layer is one of the layers it uses.
        stage = Usd.Stage.Open(layer)
        for used in sorted(stage.GetUsedLayers(), key=lambda l: l.identifier):
            found = _with_report(used)
            if found is not None:
                layer = used
                break
    if found is None:
        raise MocapEditError(f"{path}: holds no mocapedit report (customLayerData mocapedit.report); "
                             "write one with `mocapedit solve STAGE -o EDITS`")
    try:
        parsed = json.loads(found[REPORT])
    except (TypeError, ValueError) as exc:
        raise MocapEditError(f"{layer.identifier}: customLayerData mocapedit.report is not valid JSON: "
                             f"{exc}") from None
    root = layer.pseudoRoot
    return {"file": layer.identifier, "report": parsed, "version": str(found.get(VERSION, "")),
            "inputs": [str(x) for x in found.get(INPUTS, [])], "contentHash": str(found.get(CONTENT_HASH, "")),
            "metersPerUnit": float(root.GetInfo("metersPerUnit")) if root.HasInfo("metersPerUnit") else None,
            "upAxis": str(root.GetInfo("upAxis")) if root.HasInfo("upAxis") else None}
