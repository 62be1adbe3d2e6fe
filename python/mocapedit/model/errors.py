"""Errors raised for bad input. Each names the prim and property (or file and line)."""
from __future__ import annotations


class MocapEditError(Exception):
    """Bad input: the message names the prim and property, or the file and line.

    The processor writes nothing when it raises this; the CLI prints the message and
    exits with status 1.
    """

    def __init__(self, message: str, prim: str | None = None, prop: str | None = None):
        super().__init__(message)
        self.prim = prim
        self.prop = prop


def prim_error(prim_path, message: str, prop: str | None = None) -> MocapEditError:
    where = f"<{prim_path}>" + (f".{prop}" if prop else "")
    return MocapEditError(f"{where}: {message}", prim=str(prim_path), prop=prop)
