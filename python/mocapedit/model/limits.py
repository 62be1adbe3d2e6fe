"""Hard limits on the work that input values ask for.

A value that is valid on its own can still ask for more than any machine has: a
``sampleStep`` of 1e-7 time codes asks for billions of collision samples, a time
constraint at 1e308 for a clip stretched over forever. Each limit below stops such a
solve before the work starts, with an error that names the property and says what
value would do. The limits are far beyond any real shot (tens of thousands of agents,
clips of hours at 120 fps).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from mocapedit.model.errors import MocapEditError, prim_error
from mocapedit.model.data import SolveSettings, StageData

#: Largest magnitude of a shot time code a constraint may name (at 120 fps, 96 days).
MAX_TIME_CODE = 1e9
#: Most collision-avoidance iterations a solve may ask for.
MAX_ITERATIONS = 1000
#: Most (agent, shot time) samples the overlap checks may take over a shot.
MAX_SAMPLES = 20_000_000
#: Largest extra clearance (metres) collision avoidance keeps between capsules: ``margin``.
MAX_MARGIN_M = 10.0
#: Most delay (seconds) collision avoidance may give one walker: ``maxWait``.
MAX_WAIT_SECONDS = 3600.0
#: Largest distance (metres) from the stage origin a position or relative constraint may name
#: (beyond any georeferenced world: the Earth's radius is 6.4e6 m; far below any overflow).
MAX_DISTANCE_M = 1e8
#: A retimed clip may play over at most this many times its source duration ...
MAX_STRETCH = 100.0
#: ... or this many time codes more than its source, whichever is larger.
MAX_EXTRA_TIME = 100_000.0


#: MocapSolveSettings properties by their Python names (``solve(max_wait=...)``).
SETTING_NAMES = {"collision_avoidance": "collisionAvoidance", "max_iterations": "maxIterations",
                 "sample_step": "sampleStep", "margin": "margin", "match_speed": "matchSpeed",
                 "collision_strategy": "collisionStrategy", "min_time_interval": "minTimeInterval",
                 "max_wait": "maxWait", "foot_locking": "footLocking", "pivot_on_feet": "pivotOnFeet"}


def setting_problem(s: SolveSettings) -> tuple[str, str] | None:
    """(property, what is wrong) for the first solve setting of ``s`` out of its range, or
    None: what a MocapSolveSettings prim and ``solve()``'s keyword arguments are both held to."""
    finite = lambda x: isinstance(x, (int, float)) and math.isfinite(x)  # noqa: E731
    if not (finite(s.max_wait) and s.max_wait >= 0):
        return "maxWait", f"must be a finite number of seconds, 0 or more, got {s.max_wait:g}"
    if s.max_wait > MAX_WAIT_SECONDS:
        return "maxWait", (f"{s.max_wait:g} s is more than the {MAX_WAIT_SECONDS:g} s a walker may wait; no wait "
                           "longer than the shot is ever taken: use the shot's length at most")
    if s.max_iterations < 0:
        return "maxIterations", "must not be negative"
    if not finite(s.sample_step):
        return "sampleStep", f"must be a finite number, got {s.sample_step:g}"
    if not s.sample_step > 0:
        return "sampleStep", f"must be positive, got {s.sample_step:g}"
    if not (finite(s.margin) and s.margin >= 0):
        return "margin", f"must not be negative, got {s.margin:g}"
    if not (finite(s.min_time_interval) and 0.0 < s.min_time_interval <= 1.0):
        return "minTimeInterval", (f"must be in (0, 1] (a fraction of the source frame interval), "
                                   f"got {s.min_time_interval:g}")
    return None


def check_overrides(settings: SolveSettings, overrides: dict) -> None:
    """Sets ``solve()``'s keyword arguments on ``settings``; raises MocapEditError naming the
    argument for an unknown name, a value of the wrong type, or one out of range."""
    kinds = {f.name: f.type for f in dataclasses.fields(SolveSettings)}
    for key, value in overrides.items():
        if key not in SETTING_NAMES:
            raise MocapEditError(f"unknown solve setting '{key}' (the settings are {', '.join(SETTING_NAMES)})")
        kind = kinds[key]
        ok = {"bool": isinstance(value, (bool, np.bool_)),
              "int": isinstance(value, (int, np.integer)) and not isinstance(value, bool),
              "float": isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool),
              "str": isinstance(value, str)}[kind]
        if not ok:
            what = {"bool": "True or False", "int": "a whole number", "float": "a number", "str": "a string"}[kind]
            raise MocapEditError(f"solve({key}={value!r}): must be {what} (MocapSolveSettings.{SETTING_NAMES[key]})")
        setattr(settings, key, {"float": float, "int": int, "bool": bool}.get(kind, str)(value))
    problem = setting_problem(settings)
    if problem is not None:
        prop, message = problem
        key = next(k for k, v in SETTING_NAMES.items() if v == prop)
        if key in overrides:
            raise MocapEditError(f"solve({key}={overrides[key]!r}): {message}")


def check_settings(data: StageData) -> None:
    """Raises MocapEditError when the solve settings ask for more work than the limits allow."""
    s = data.settings
    where = s.path or "MocapSolveSettings"
    if s.max_iterations > MAX_ITERATIONS:
        raise prim_error(where, f"{s.max_iterations} is more than the {MAX_ITERATIONS} collision iterations a "
                         "solve may take; a crowd that is not clear after a few dozen will not be clear after "
                         "more (look at the report's remaining collisions)", "maxIterations")
    too_many = sample_step_problem(data, s.sample_step)
    if too_many:
        raise prim_error(where, too_many, "sampleStep")
    widest = data.info.metres(MAX_MARGIN_M)
    if s.margin > widest:
        raise prim_error(where, f"{s.margin:g} stage units is more than {MAX_MARGIN_M:g} m ({widest:g} stage units) "
                         "of extra clearance: no crowd keeps its walkers that far apart", "margin")


def check_region_sizes(data: StageData) -> None:
    """Raises MocapEditError for an avoid region whose radius, size or margin is larger than
    :data:`MAX_DISTANCE_M` (a slip of units: such a region holds the whole crowd)."""
    far = data.info.metres(MAX_DISTANCE_M)
    for region in data.avoid_regions:
        used = [("margin", region.margin)]
        if region.geometry is None:
            used.append(("radius", region.radius) if region.shape == "circle" else
                        ("size", float(np.max(np.abs(region.size), initial=0.0))))
        for prop, value in used:
            if math.isfinite(value) and value > far:
                raise prim_error(region.path, f"{value:g} stage units is more than {MAX_DISTANCE_M:g} m ({far:g} "
                                 "stage units): check its units", prop)


def check_constraint_positions(data: StageData) -> None:
    """Raises MocapEditError for a position or relative constraint further from the stage origin
    than :data:`MAX_DISTANCE_M` (a value that far only comes from a slip, and its arithmetic
    would overflow)."""
    far = data.info.metres(MAX_DISTANCE_M)
    for constraints, prop in ((data.position_constraints, "position"), (data.relative_constraints, "offset")):
        for c in constraints:
            value = np.asarray(getattr(c, prop), dtype=np.float64)
            if np.all(np.isfinite(value)) and float(np.abs(value).max(initial=0.0)) > far:
                raise prim_error(c.path, f"{tuple(float(v) for v in value)} lies more than {MAX_DISTANCE_M:g} m "
                                 f"({far:g} stage units) from the stage origin: check its units", prop)


def sample_step_problem(data: StageData, step: float) -> str | None:
    """What is wrong with ``step`` time codes between the overlap checks' samples of the
    shot ``data`` (more samples than :data:`MAX_SAMPLES`), or None when it is fine."""
    samples = sum(float(a.sample_times[-1] - a.sample_times[0]) / step + 1.0
                  for a in data.agents.values() if len(a.sample_times))
    if samples <= MAX_SAMPLES:
        return None
    least = step * samples / MAX_SAMPLES
    return (f"{step:g} time codes between samples asks for {samples:.3g} collision samples over "
            f"{len(data.agents)} agents, more than the {MAX_SAMPLES:.0e} a solve may take; use at least "
            f"{_round_up(least):g}")


def check_constraint_times(data: StageData) -> None:
    """Raises MocapEditError for a time or sync value beyond :data:`MAX_TIME_CODE`."""
    for c in data.time_constraints:
        if math.isfinite(c.time) and abs(c.time) > MAX_TIME_CODE:
            raise prim_error(c.path, f"{c.time:g} is beyond the +-{MAX_TIME_CODE:g} time codes a shot may span",
                             "time")
    for c in data.sync_constraints:
        if math.isfinite(c.offset) and abs(c.offset) > MAX_TIME_CODE:
            raise prim_error(c.path, f"{c.offset:g} is beyond the +-{MAX_TIME_CODE:g} time codes a shot may span",
                             "offset")


def check_time_map(agent_path: str, source_times: np.ndarray, time_map: np.ndarray, constraints: list) -> None:
    """Raises MocapEditError when a warped clip would play over far longer than its source.

    ``constraints`` are the time and sync constraints that hold the agent; the error names them.
    """
    source = float(source_times[-1] - source_times[0])
    warped = float(time_map[-1] - time_map[0])
    allowed = max(MAX_STRETCH * source, source + MAX_EXTRA_TIME)
    if warped > allowed:
        prim = constraints[0].path if constraints else agent_path
        prop = "time" if constraints and hasattr(constraints[0], "time") else "offset"
        named = ", ".join(f"<{c.path}>" for c in constraints)
        raise prim_error(prim, f"the constraints {named} stretch <{agent_path}>'s clip of {source:g} time codes "
                         f"over {warped:.3g}; at most {allowed:.3g} can be baked; check the times", prop)


def _round_up(x: float) -> float:
    """x rounded up to two significant digits."""
    if x <= 0:
        return x
    scale = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.ceil(x / scale) * scale
