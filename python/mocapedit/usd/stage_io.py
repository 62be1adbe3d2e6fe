"""The stage-side pieces of a solve: opening its input, the provenance the edits layer records
(the input's layers and a hash of their content), and what the processor asks of a layer.

The processor hands stages and layers through without importing pxr; these functions are the
USD calls it needs.
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass

from pxr import Sdf, Usd, Vt

from mocapedit.model.errors import MocapEditError
from mocapedit.usd import edits_format, reader


@dataclass
class SolveInput:
    """The stage a solve reads and how the caller named it."""
    stage: Usd.Stage
    name: str                  # the path given, or the root layer's identifier
    file: str | None           # the root layer's file on disk; None for a stage only in memory

    @property
    def unsaved(self) -> bool:
        """Whether a layer of the stage's layer stack holds changes not saved to its file."""
        return any(layer.dirty for layer in self.stage.GetLayerStack(includeSessionLayers=False))

    @property
    def default_prim(self) -> str | None:
        return self.stage.GetRootLayer().defaultPrim or None


def open_input(stage_or_path) -> SolveInput:
    """A ``Usd.Stage`` as given, a stage on an ``Sdf.Layer`` (its root layer), or the stage
    file at a path (``str`` or ``os.PathLike``) opened by the reader."""
    if isinstance(stage_or_path, Sdf.Layer):
        stage_or_path = Usd.Stage.Open(stage_or_path)
    if isinstance(stage_or_path, Usd.Stage):
        stage = stage_or_path
        return SolveInput(stage, stage.GetRootLayer().identifier, stage.GetRootLayer().realPath)
    if not isinstance(stage_or_path, (str, os.PathLike)):
        raise MocapEditError(f"the input is a {type(stage_or_path).__name__}; give a Usd.Stage, an Sdf.Layer "
                             f"or the path of a stage file")
    name = os.fspath(stage_or_path)
    if isinstance(name, bytes):
        raise MocapEditError(f"the input path {name!r} is bytes; give it as a str")
    return SolveInput(reader.open_stage(name), name, name)


def is_anonymous(identifier: str) -> bool:
    """True for the identifier of an in-memory (anonymous) layer."""
    return Sdf.Layer.IsAnonymousLayerIdentifier(identifier)


def content_hash(stage: Usd.Stage) -> str:
    """SHA-256 over the content of every layer the input uses, in identifier order: a layer
    with unsaved changes by what it holds in memory (a text layer as the bytes it would save as)."""
    session = stage.GetSessionLayer()
    digests = []
    for layer in stage.GetUsedLayers():
        if layer == session:
            continue
        h = hashlib.sha256()
        if layer.realPath and os.path.isfile(layer.realPath) and not layer.dirty:
            h.update(os.path.basename(layer.realPath).encode())
            with open(layer.realPath, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        elif layer.realPath and os.path.splitext(layer.realPath)[1].lower() == ".usda":
            # Changed in memory: what it would save as (the file's bytes once saved).
            h.update(os.path.basename(layer.realPath).encode())
            h.update(layer.ExportToString().encode())
        else:
            h.update(layer.ExportToString().encode())
        digests.append(h.hexdigest())
    # Anonymous identifiers change from run to run: order by content, not by name.
    return hashlib.sha256("".join(sorted(digests)).encode()).hexdigest()


def input_layers(stage: Usd.Stage) -> list[str]:
    """The input's layer identifiers, root first; anonymous (in-memory) layers are left out."""
    root = stage.GetRootLayer().identifier
    others = sorted(l.identifier for l in stage.GetUsedLayers()
                    if l != stage.GetSessionLayer() and not l.anonymous and l.identifier != root)
    return [root] + others


def provenance(stage: Usd.Stage, options: str) -> dict:
    """What the edits layer records of its input (``customLayerData`` mocapedit ``inputs``,
    ``contentHash``, ``options``), as the writer authors it."""
    return {edits_format.INPUTS: Vt.StringArray(input_layers(stage)),
            edits_format.CONTENT_HASH: content_hash(stage), edits_format.OPTIONS: options}
