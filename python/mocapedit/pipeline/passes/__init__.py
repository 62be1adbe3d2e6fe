"""The solve passes, in the order they run (:data:`PASSES`). Each reads the
:class:`~mocapedit.pipeline.context.SolveContext` and what earlier passes put in it, and adds its own.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

from mocapedit.pipeline.context import SolveContext
from mocapedit.pipeline.passes import collisions, feet, layering, path, stance, time


class Pass(NamedTuple):
    name: str                             # as the report's timings name it
    run: Callable[[SolveContext], None]


#: The passes of a solve, in order: layers are checked before any work; path edits, then time
#: edits (which may match the speed along the edited paths), collision avoidance on the edited
#: and warped paths, the turn taken between steps and the body pivoting on its planted feet
#: (stance), layering on the warped pose, and foot locking after every other edit.
PASSES: tuple[Pass, ...] = (
    Pass("layering-check", layering.check_layers),
    Pass("path", path.run),
    Pass("time", time.run),
    Pass("collisions", collisions.run),
    Pass("stance", stance.run),
    Pass("layering", layering.run),
    Pass("foot locking", feet.run),
)
