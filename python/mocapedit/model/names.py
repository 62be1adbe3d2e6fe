"""Valid, unique USD identifiers from arbitrary names (joint names, prim paths)."""
from __future__ import annotations

import re

_NOT_IDENTIFIER = re.compile(r"[^A-Za-z0-9_]")


def unique_identifier(text: str, taken: set[str], fallback: str) -> str:
    """A USD identifier for ``text``, not in ``taken`` (and added to it).

    Characters outside ``[A-Za-z0-9_]`` become ``_``, a leading digit gets a ``_`` in front,
    an empty result becomes ``fallback``, and a name already taken gets ``_2``, ``_3``, ...
    """
    base = _NOT_IDENTIFIER.sub("_", text) or fallback
    if base[0].isdigit():
        base = "_" + base
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    taken.add(name)
    return name
