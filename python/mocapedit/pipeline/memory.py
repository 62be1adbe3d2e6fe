"""Giving freed memory back to the system between the phases of a solve.

A phase of a large solve allocates and frees gigabytes of arrays (collision avoidance's per-frame
work, foot locking's runs of agents, the writer's samples). glibc keeps what was freed in its
heap for the process's next allocations, so the resident size only grows, and each phase's own
peak lands on top of what the phases before it freed. ``malloc_trim`` hands the free pages back.
Elsewhere than glibc (macOS, musl), this does nothing.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.lru_cache(maxsize=1)
def _trim():
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        return libc.malloc_trim if libc is not None and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


def give_back() -> None:
    """Returns the heap's free pages to the system (glibc ``malloc_trim(0)``), if it can."""
    trim = _trim()
    if trim is not None:
        trim(0)


__all__ = ["give_back"]
