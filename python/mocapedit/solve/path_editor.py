"""Interactive path editing: factor once for a set of handled frames, then drag handles.

::

    from mocapedit.solve.path_editor import PathEditor
    from mocapedit.usd import reader

    shot = reader.read_stage(reader.open_stage("shot.usda"))
    editor = PathEditor.for_agent(shot, "/World/Crowd/agent_0007", frames=[0, 60, 119])
    ground = editor.move(1, (2.0, -3.5))      # handle 1 (frame 60) to ground (u, v); (F, 2)
    heading = editor.heading                  # (F,) radians, the rest heading turned by the edit

The editor builds the same two-step problem as ``mocapedit solve`` (shape terms, edge
terms, stationary ranges, hard or soft handles; see :mod:`mocapedit.solve.path_edit`) and
factors it once. Each move re-solves only step 2: step 1 is linear in the handle
positions, so its response to each handle is precomputed. Positions are ground-plane
coordinates in stage units (:mod:`mocapedit.geometry.ground`); use ``to_world`` for 3D points.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from mocapedit import _solver
from mocapedit.geometry import ground, trajectory
from mocapedit.solve import path_edit
from mocapedit.solve.path_edit import MIN_BASELINE_M

#: Defaults in metres, as the path pass uses them.
RIGID_MIN_EXTENT_M = 0.02
STILL_M = 1e-5


class PathEditor:
    """One agent's path with handles at fixed frames, re-solved as the handles move.

    Args:
      rest: (F,2) ground path to edit (stage units).
      frames: (H,) handled frames (0-based).
      positions: (H,2) initial handle positions; default the rest path at those frames.
      weights: (H,) per handle: ``inf`` (default) for hard, else a soft weight.
      stationary: inclusive (first, last) frame ranges that move rigidly.
      heading: (F,) headings of the rest path (default: its tangent headings).
      meters_per_unit: for the default tolerances.
      fps: frames per second of the path, for the windows that turn the heading.
    """

    def __init__(self, rest, frames: Sequence[int], positions=None, weights=None,
                 stationary: Sequence[tuple[int, int]] = (), heading=None, meters_per_unit: float = 1.0,
                 fps: float = 24.0):
        rest = np.ascontiguousarray(rest, dtype=np.float64)
        frames = [int(f) for f in frames]
        if rest.ndim != 2 or rest.shape[1] != 2 or len(rest) < 2:
            raise ValueError(f"rest must be an (F, 2) path of at least two frames, got {rest.shape}")
        for f in frames:
            if not 0 <= f < len(rest):
                raise ValueError(f"frame {f} is outside 0..{len(rest) - 1}")
        unit = 1.0 / meters_per_unit
        self.settings = path_edit.Settings(min_baseline=MIN_BASELINE_M * unit,
                                           rigid_min_extent=RIGID_MIN_EXTENT_M * unit, still=STILL_M * unit,
                                           **path_edit.turn_settings(fps, meters_per_unit))
        ranges = sorted((int(a), int(b)) for a, b in stationary)
        if heading is None:
            heading = trajectory.headings(rest, ranges, meters_per_unit)
        self.agent = path_edit.AgentInput(path="agent", rest=rest, source=rest, source_heading=np.asarray(heading),
                                          stationary=ranges, stationary_refs=[str(r) for r in ranges])
        weights = np.full(len(frames), np.inf) if weights is None else np.asarray(weights, dtype=np.float64)
        positions = rest[frames] if positions is None else np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        if len(weights) != len(frames) or len(positions) != len(frames):
            raise ValueError(f"expected {len(frames)} handle positions and weights")
        self.frames = frames
        handles = [path_edit.Handle("agent", f, p, w, f"handle {k}")
                   for k, (f, p, w) in enumerate(zip(frames, positions, weights))]
        self.problem = path_edit.ComponentProblem([self.agent], handles, [], [], self.settings,
                                                  precompute_responses=True)
        self._data = self.problem.data
        self._positions = self.problem.handle_positions()
        self._links = np.zeros((len(self.problem.link_vertex), 2))
        self._links[:] = self.problem._link_offsets(None)
        self._spot = self.problem.settles
        self._result = None
        self._solve()

    @classmethod
    def for_agent(cls, data, agent: str, frames: Sequence[int], positions=None, weights=None) -> "PathEditor":
        """An editor for an agent of a stage read by :func:`mocapedit.usd.reader.read_stage`
        (``data``: a :class:`~mocapedit.model.data.StageData`): its source ground path and the
        stationary ranges of its clip."""
        if agent not in data.agents:
            raise ValueError(f"<{agent}> is not an agent of the stage")
        a = data.agents[agent]
        traj = trajectory.extract(a, data.clip_of(a), data.info.up_axis, data.info.meters_per_unit)
        editor = cls(traj.ground, frames, positions, weights, [(f, l) for _, f, l in a.stationary],
                     heading=traj.heading, meters_per_unit=data.info.meters_per_unit,
                     fps=data.info.time_codes_per_second)
        editor.up_axis, editor.source_height = data.info.up_axis, traj.height
        return editor

    def _solve(self) -> None:
        if self._spot:
            # A path about one spot: its spot links turn with the body, settled by re-solving.
            self._result = self.problem.solve_positions(self._positions)[0]
        else:
            self._result = _solver.path_edit_solve(self._data, self._positions, self._links)
        self._heading = None

    def move(self, handle: int, position) -> np.ndarray:
        """Moves one handle (index into ``frames``) to a ground position; returns the (F,2) path."""
        self._positions[handle] = position
        if self._spot:
            self._solve()
            return self._result.positions
        # As _solve, inlined: a drag calls this for every mouse move.
        self._result = result = _solver.path_edit_solve(self._data, self._positions, self._links)
        self._heading = None
        return result.positions

    def set_positions(self, positions) -> np.ndarray:
        """Moves every handle at once: (H,2) ground positions; returns the (F,2) path."""
        self._positions[:len(self.frames)] = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        self._solve()
        return self.ground

    @property
    def positions(self) -> np.ndarray:
        """(H,2) current handle positions."""
        return self._positions[:len(self.frames)].copy()

    @property
    def ground(self) -> np.ndarray:
        """(F,2) edited ground path."""
        return np.asarray(self._result.positions)

    @property
    def heading(self) -> np.ndarray:
        """(F,) headings of the edited path (held through stationary ranges)."""
        if self._heading is None:
            self._heading = self.problem._agents(self._result)["agent"].heading
        return self._heading

    @property
    def solver(self) -> str:
        return self._result.step1.solver

    up_axis = "Y"
    source_height = None

    def to_world(self, height=None) -> np.ndarray:
        """(F,3) world points of the edited path at a height (default: the source root's
        height when the editor was made ``for_agent``, else 0)."""
        if height is None:
            height = 0.0 if self.source_height is None else self.source_height
        return ground.from_ground(self.ground, height, self.up_axis)
