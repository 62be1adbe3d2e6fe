"""Plausibility of edited motion in the solver: the C++ ``PlausibilityJob`` and its measures
(``_solver.plausibility``, ``joint_facing``, ``turning_rates``, ``direction_deviation``,
``edit_turn``), as keyword wrappers.

:mod:`mocapedit.inspect.metrics` defines the measures (what they mean, their thresholds) and
calls these; the job measures many agents at once, each owning a run of source samples and a
run of edited samples (offsets), so a crowd's report costs one call.

Conventions: the facing joint's world matrices are ``(..., 4, 4)`` (row-vector convention);
ground points ``(..., 2)`` in stage units; seconds; radians in, degrees out.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapedit import _solver
from mocapedit.geometry.ground import up_index, up_token


def _up(up_axis) -> int:
    return up_index(up_token(up_axis))


def joint_facing(matrices, up_axis) -> np.ndarray:
    """(..., T) heading of a joint's facing (not unwrapped) from its world matrices (..., T, 4, 4)."""
    return _solver.joint_facing(matrices=matrices, up_axis=_up(up_axis))


def turning_rates(facing, seconds) -> np.ndarray:
    """(..., T-1) unsigned turning rate (degrees per second) of a facing (..., T) at increasing seconds."""
    return _solver.turning_rates(facing=facing, seconds=seconds)


def direction_deviation(source, edited, seconds, min_speed: float, chord: float, turn=None) -> np.ndarray:
    """(..., T) degrees between the edited and the source walking direction (chords of ``chord`` seconds)."""
    return _solver.direction_deviation(source=source, edited=edited, seconds=seconds, min_speed=float(min_speed),
                                       chord=float(chord), turn=turn)


def edit_turn(source, edited, seconds, min_speed: float, span: float) -> np.ndarray:
    """(..., T) radians: the turn an edit gives a walk (chords of ``span`` seconds centred on each sample)."""
    return _solver.edit_turn(source=source, edited=edited, seconds=seconds, min_speed=float(min_speed),
                             span=float(span))


@dataclass
class PlausibilityFigures:
    """The job's figures, one value per agent (see :class:`mocapedit.inspect.metrics.Plausibility`)."""
    max_facing_rate: np.ndarray
    source_max_facing_rate: np.ndarray
    max_extra_facing_rate: np.ndarray
    worst_turn_frame: np.ndarray
    spin_frames: np.ndarray
    max_direction_deviation: np.ndarray
    worst_direction_frame: np.ndarray
    max_turned_deviation: np.ndarray
    max_edit_turn: np.ndarray
    length_ratio: np.ndarray
    time_warp_min: np.ndarray
    time_warp_max: np.ndarray


@dataclass
class Thresholds:
    """What the measures call walking, a walking direction, an edit's turn and a spin."""
    walking_speed: float      # stage units per second
    chord: float              # seconds
    edit_turn_span: float     # seconds
    spin_rate: float          # degrees per second


def plausibility(source_offsets, edited_offsets, source_seconds, source_hip, edited_seconds, edited_hip,
                 up_axis, thresholds: Thresholds, edited_frames=None) -> PlausibilityFigures:
    """Runs the solver's PlausibilityJob: agent ``a`` owns source samples ``source_offsets[a]`` ..
    ``source_offsets[a + 1] - 1`` of ``source_seconds`` (S,) and ``source_hip`` (S, 4, 4), and
    edited samples likewise (``edited_frames`` (E,): the source frame each plays, or None)."""
    out = _solver.plausibility(
        source_offsets=np.asarray(source_offsets, dtype=np.int64), edited_offsets=np.asarray(edited_offsets, np.int64),
        source_seconds=source_seconds, source_hip=source_hip, edited_seconds=edited_seconds, edited_hip=edited_hip,
        edited_frames=edited_frames, up_axis=_up(up_axis), walking_speed=float(thresholds.walking_speed),
        chord=float(thresholds.chord), edit_turn_span=float(thresholds.edit_turn_span),
        spin_rate=float(thresholds.spin_rate))
    return PlausibilityFigures(**{name: getattr(out, name) for name in PlausibilityFigures.__dataclass_fields__})


__all__ = ["joint_facing", "turning_rates", "direction_deviation", "edit_turn", "plausibility", "Thresholds",
           "PlausibilityFigures"]
