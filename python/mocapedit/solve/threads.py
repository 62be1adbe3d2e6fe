"""How many threads the solver's jobs may use at once in this process: its thread budget.

The ``MOCAPEDIT_THREADS`` environment variable (a positive whole number) sets it as the process
starts solving, else the machine's hardware threads do; :func:`set_budget` changes it. Each job
splits its work in two at most, so the budget matters where a process shares a machine's cores
with others: a farm slot of one core, or one of several Dask workers on a machine
(``mocapedit batch`` gives each worker of its local cluster its share). With a budget of 1 every
job runs on the calling thread; the results are the same, byte for byte.
"""
from __future__ import annotations

import os

from mocapedit import _solver
from mocapedit.model.errors import MocapEditError

__all__ = ["ENVIRONMENT", "budget", "check_environment", "set_budget"]

ENVIRONMENT = "MOCAPEDIT_THREADS"
#: More threads than any machine this runs on has: a typing slip.
MOST = 4096


def check_environment(environ=None) -> int | None:
    """The budget ``MOCAPEDIT_THREADS`` asks for (None when it is unset or empty).

    Raises:
      MocapEditError: it is not a whole number from 1 to :data:`MOST` (the solver would
        otherwise ignore it and use every hardware thread).
    """
    text = (os.environ if environ is None else environ).get(ENVIRONMENT, "").strip()
    if not text:
        return None
    try:
        threads = int(text)
    except ValueError:
        threads = 0
    if not 1 <= threads <= MOST:
        raise MocapEditError(f"{ENVIRONMENT}={text!r}: give the number of threads the solver may use, a whole "
                             f"number from 1 to {MOST} (1 on a farm slot of one core), or unset it to use them all")
    return threads


def budget() -> int:
    """The thread budget of this process."""
    return int(_solver.thread_budget())


def set_budget(threads: int) -> None:
    """Sets the thread budget of this process; 0 goes back to ``MOCAPEDIT_THREADS`` or the hardware's."""
    _solver.set_thread_budget(int(threads))
