"""Freed memory goes back to the system between the phases of a solve."""
from __future__ import annotations

import ctypes.util
import sys

import numpy as np
import pytest

from mocapedit.pipeline import memory


def _resident_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 1e6


@pytest.mark.skipif(not sys.platform.startswith("linux") or "libc.so" not in (ctypes.util.find_library("c") or ""),
                    reason="glibc only")
def test_freed_arrays_go_back_to_the_system():
    # 300 MB in 48 KB arrays (below glibc's mmap threshold: they live in the heap), the last
    # one kept, as a phase that keeps a small result of its work.
    arrays = [np.ones(6000) for _ in range(6250)]
    keep = arrays[-1]
    del arrays
    before = _resident_mb()
    memory.give_back()
    after = _resident_mb()
    assert before - after > 150.0, (before, after)
    assert keep.sum() == 6000
