"""The solve report: per agent, per constraint, the shot's figures and the solver's notes.

Every entry is a dataclass whose fields name their JSON key once (``key("lengthRatio")``); the
edits layer and ``--report`` files store :meth:`Report.to_dict`, and :meth:`Report.from_dict`
reads it back. A field left ``None`` is not written (unless the key is always written, as a
constraint's ``target``); keys this version does not know are kept in ``extra`` and written back.
Readers that go by the stored names (``entry.get("met")``) get the same values.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

from mocapedit.model.progress import counted


def key(name: str, always: bool = False, default: Any = None):
    """A report field stored under JSON key ``name``; ``always``: written even when None."""
    return field(default=default, metadata={"key": name, "always": always})


class Entry:
    """What every report entry shares: JSON keys by field, conversion, and access by key."""
    extra: dict
    _NESTED: ClassVar[dict[str, type]] = {}

    @classmethod
    def keys_of(cls, *attrs: str) -> list[str]:
        """The JSON keys of the given fields."""
        names = {attr: name for name, (attr, _) in cls._keys().items()}
        return [names[a] for a in attrs]

    @classmethod
    def _keys(cls) -> dict[str, tuple[str, bool]]:
        """JSON key -> (field name, always written)."""
        cached = cls.__dict__.get("_key_cache")
        if cached is None:
            cached = {f.metadata["key"]: (f.name, f.metadata["always"]) for f in fields(cls) if "key" in f.metadata}
            cls._key_cache = cached
        return cached

    def to_dict(self) -> dict:
        out = dict(self.extra)
        for name, (attr, always) in self._keys().items():
            value = getattr(self, attr)
            if value is None and not always:
                continue
            out[name] = value.to_dict() if isinstance(value, Entry) else value
        return out

    @classmethod
    def from_dict(cls, data: dict):
        """The entry of a stored dict. A key stored as null (a figure that was not finite) stays
        null when written back, though the field reads None like an absent one."""
        keys = cls._keys()
        known, extra = {}, {}
        for name, value in data.items():
            if name not in keys or (value is None and not keys[name][1]):
                extra[name] = value
            elif name in cls._NESTED and isinstance(value, dict):
                known[keys[name][0]] = cls._NESTED[name].from_dict(value)
            else:
                known[keys[name][0]] = value
        return cls(**known, extra=extra)

    # Access by the stored key, for readers that go by the names of the JSON.
    def get(self, name: str, default=None):
        attr = self._keys().get(name)
        value = getattr(self, attr[0]) if attr else self.extra.get(name)
        return default if value is None else value

    def __contains__(self, name: str) -> bool:
        return self.get(name) is not None

    def __getitem__(self, name: str):
        value = self.get(name)
        if value is None:
            raise KeyError(name)
        return value

    def __setitem__(self, name: str, value) -> None:
        attr = self._keys().get(name)
        if attr:
            setattr(self, attr[0], value)
        else:
            self.extra[name] = value

    def update(self, figures: dict) -> None:
        """Sets figures given by their stored keys (as the measuring functions name them)."""
        for name, value in figures.items():
            self[name] = value


@dataclass
class AgentPlausibility(Entry):
    """How plausible an edited agent's motion is (:func:`mocapedit.inspect.metrics.plausibility_of`)."""
    max_facing_rate: float = key("maxFacingRate")                     # degrees per second
    source_max_facing_rate: float = key("sourceMaxFacingRate")
    max_extra_facing_rate: float = key("maxExtraFacingRate")
    spin_frames: int = key("spinFrames")
    max_direction_deviation: float = key("maxDirectionDeviation")      # degrees
    max_turned_direction_deviation: float = key("maxTurnedDirectionDeviation")
    max_edit_turn: float = key("maxEditTurn")
    max_turn_off_curve: float = key("maxTurnOffCurve")                 # on a path curve only
    reverses: bool = key("reverses")
    length_ratio: float = key("lengthRatio")
    time_warp: list = key("timeWarp")                                  # [slowest, fastest]
    foot_skate_ratio: float = key("footSkateRatio")
    #: Source frames where the largest extra turn and direction change happen (previews mark them).
    worst_turn_frame: int = key("worstTurnFrame")
    worst_direction_frame: int = key("worstDirectionFrame")
    extra: dict = field(default_factory=dict)


@dataclass
class ShotPlausibility(Entry):
    """The shot's worst plausibility figures (:func:`mocapedit.inspect.metrics.worst_plausibility`)."""
    agents: int = key("agents")
    max_extra_facing_rate: float = key("maxExtraFacingRate")
    max_extra_turn_per_frame_at_60fps: float = key("maxExtraTurnPerFrameAt60fps")
    max_extra_facing_rate_agent: str = key("maxExtraFacingRateAgent")
    spinning_agents: int = key("spinningAgents")
    max_direction_deviation: float = key("maxDirectionDeviation")
    max_direction_deviation_agent: str | None = key("maxDirectionDeviationAgent", always=True)
    max_turned_direction_deviation: float = key("maxTurnedDirectionDeviation")
    max_turned_direction_deviation_agent: str | None = key("maxTurnedDirectionDeviationAgent", always=True)
    max_edit_turn: float = key("maxEditTurn")
    reversing_agents: int = key("reversingAgents")
    mean_length_ratio: float = key("meanLengthRatio")
    length_ratio_range: tuple = key("lengthRatioRange")
    time_warp_range: tuple = key("timeWarpRange")
    mean_foot_skate_ratio: float = key("meanFootSkateRatio")
    max_foot_skate_ratio: float = key("maxFootSkateRatio")
    extra: dict = field(default_factory=dict)


@dataclass
class AgentEntry(Entry):
    """One agent's figures. Lengths in stage units, times in seconds unless said."""
    frames: int = key("frames")
    edited: bool = key("edited")
    trajectory_joint: str = key("trajectoryJoint")          # when the hip is projected to the ground
    length_ratio: float = key("lengthRatio")                # edited path length over the source's
    max_displacement: float = key("maxDisplacement")
    mean_displacement: float = key("meanDisplacement")
    shape_change: float = key("shapeChange")
    solver: str = key("solver")
    min_interval: float = key("minInterval")                # time codes, after the time warp
    min_separation: float = key("minSeparation")            # nearest clearance to another agent
    delay: float = key("delay")                             # waited for collision avoidance
    # Mean foot speed while in contact (stage units per second).
    foot_skate_source: float = key("footSkateSource")
    foot_skate_unlocked: float = key("footSkateUnlocked")   # after the edits, before foot locking
    foot_skate_edited: float = key("footSkateEdited")       # as the edits layer plays it
    foot_contacts_locked: int = key("footContactsLocked")
    foot_steps: int = key("footSteps")                      # steps foot locking made a standing foot take
    max_pelvis_drop: float = key("maxPelvisDrop")
    max_foot_correction: float = key("maxFootCorrection")   # of a planted foot
    plausibility: AgentPlausibility = key("plausibility")
    notes: list[str] = key("notes")
    extra: dict = field(default_factory=dict)
    _NESTED: ClassVar[dict[str, type]] = {"plausibility": AgentPlausibility}

    def add_notes(self, *texts: str) -> list[str]:
        """Appends notes (the list exists afterwards, even for none); returns it."""
        if self.notes is None:
            self.notes = []
        self.notes.extend(texts)
        return self.notes


@dataclass
class ConstraintEntry(Entry):
    """How a constraint (or a collision left, or an avoid region's push) ended. Residuals of time
    and sync constraints are in time codes, the others in stage units."""
    prim: str | None = key("prim", always=True)
    kind: str = key("kind", always=True)   # position, relative, stationary, path-curve, time, sync, collision, avoid-region
    agent: str | None = key("agent", always=True)
    frame: int | None = key("frame", always=True)
    target: str | None = key("target", always=True)
    target_frame: int | None = key("targetFrame", always=True)
    hard: bool = key("hard", always=True, default=False)
    residual: float | None = key("residual", always=True, default=0.0)
    met: bool = key("met", always=True, default=True)
    position: list[float] | None = key("position")           # world position of the handle
    time: float | None = key("time")                         # collision: shot time of the deepest overlap
    held_by_constraints: bool | None = key("heldByConstraints")  # collision: hard constraints hold both
    extra: dict = field(default_factory=dict)


@dataclass
class Stats(Entry):
    """The shot's figures: counts, and each pass's run-wide figures."""
    agents: int = key("agents")
    edited_agents: int = key("editedAgents")
    clips: int = key("clips")
    constraints: int = key("constraints")
    groups: int = key("groups")
    avoid_regions: int = key("avoidRegions")
    animation_layers: int = key("animationLayers")
    path_components: int = key("pathComponents")
    layered_agents: int = key("layeredAgents")
    layered_joint_samples: int = key("layeredJointSamples")
    collision_strategy: str = key("collisionStrategy")
    collision_iterations: int = key("collisionIterations")
    collisions_per_iteration: list[int] = key("collisionsPerIteration")  # before each solve, then after the last
    remaining_overlaps: int = key("remainingOverlaps")
    region_frames_left: int = key("regionFramesLeft")
    min_separation: float = key("minSeparation")
    delayed_agents: int = key("delayedAgents")
    largest_delay: float = key("largestDelay")                # seconds
    collision_stalled: bool = key("collisionStalled")
    foot_locked_agents: int = key("footLockedAgents")
    foot_locking_not_needed: int = key("footLockingNotNeeded")
    foot_contacts_locked: int = key("footContactsLocked")
    foot_steps: int = key("footSteps")
    foot_skate_source: float = key("footSkateSource")         # means over the agents with contacts
    foot_skate_unlocked: float = key("footSkateUnlocked")
    foot_skate_edited: float = key("footSkateEdited")
    max_pelvis_drop: float = key("maxPelvisDrop")
    max_foot_correction: float = key("maxFootCorrection")
    plausibility: ShotPlausibility = key("plausibility")
    extra: dict = field(default_factory=dict)
    _NESTED: ClassVar[dict[str, type]] = {"plausibility": ShotPlausibility}


@dataclass
class Report:
    input: str = ""
    output: str | None = None
    agents: dict[str, AgentEntry] = field(default_factory=dict)       # agent path -> figures
    constraints: list[ConstraintEntry] = field(default_factory=list)  # one entry per constraint prim
    notes: list[str] = field(default_factory=list)                    # solver choices, fallbacks, warnings
    stats: Stats = field(default_factory=Stats)
    timings: dict[str, float] = field(default_factory=dict)           # seconds per phase

    def agent(self, path: str) -> AgentEntry:
        entry = self.agents.get(path)
        if entry is None:
            entry = self.agents[path] = AgentEntry()
        return entry

    def note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def to_dict(self) -> dict:
        return {"input": self.input, "output": self.output, "timings": self.timings, **self.to_layer_dict()}

    def to_layer_dict(self) -> dict:
        """What the edits layer stores: everything but the timings and the file names, so
        the same input gives the same bytes wherever it is written."""
        return {"stats": self.stats.to_dict(), "notes": self.notes,
                "constraints": [c.to_dict() for c in self.constraints],
                "agents": {path: entry.to_dict() for path, entry in self.agents.items()}}

    @classmethod
    def from_dict(cls, data: dict) -> "Report":
        return cls(input=data.get("input", ""), output=data.get("output"),
                   agents={p: AgentEntry.from_dict(e) for p, e in dict(data.get("agents", {})).items()},
                   constraints=[ConstraintEntry.from_dict(c) for c in data.get("constraints", [])],
                   notes=list(data.get("notes", [])), stats=Stats.from_dict(dict(data.get("stats", {}))),
                   timings=dict(data.get("timings", {})))

    def to_json(self, indent: int = 2) -> str:
        return json.dumps(finite_values(self.to_dict()), indent=indent, sort_keys=True, default=_plain,
                          allow_nan=False)

    def summary(self) -> str:
        """What ``mocapedit solve`` prints: the same figures, in the same words, as the
        summary of ``mocapedit report``."""
        s = self.stats
        lines = [f"agents: {s.agents or 0} read, {s.edited_agents or 0} edited; "
                 f"clips: {s.clips or 0}; constraints: {s.constraints or 0}"]
        lines.extend(overview(s, self.constraints))
        lines.extend(plausibility_lines(s.plausibility))
        lines.extend(foot_locking_lines(s))
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


def describe_left(intervals: int, region_frames: int) -> str:
    """What collision avoidance left, in the words progress, notes and reports share."""
    text = f"{intervals} collision interval{'s' if intervals != 1 else ''}"
    if region_frames:
        text += f" and {region_frames} frame{'s' if region_frames != 1 else ''} inside avoid regions"
    return text + " left"


def overview(stats: Stats, constraints: list[ConstraintEntry]) -> list[str]:
    """The lines on constraints and overlaps that the solve summary and the report share.

    Constraint figures leave out the soft collision rows; residuals of time and sync
    constraints are in time codes, the others in stage units."""
    lines = []
    checked = [c for c in constraints if c.kind != "collision"]
    if checked:
        unmet = [c for c in checked if not c.met]
        hard = [c.residual or 0.0 for c in checked if c.hard]
        lines.append(f"constraints reported: {len(checked)}, met: {len(checked) - len(unmet)}, "
                     f"not met: {len(unmet)}" + (f"; worst hard residual {_num(max(hard))}" if hard else ""))
    if stats.collisions_per_iteration is not None:
        iterations = stats.collision_iterations or 0
        lines.append("collision avoidance: " + describe_left(stats.remaining_overlaps or 0,
                                                             stats.region_frames_left or 0) +
                     f" after {iterations} iteration{'s' if iterations != 1 else ''}")
    elif stats.remaining_overlaps is not None:
        lines.append(f"overlapping agent pairs left: {stats.remaining_overlaps}")
    return lines


def foot_locking_lines(stats: Stats) -> list[str]:
    """The shot's foot locking figures, as ``solve`` prints them and the report shows them."""
    if stats.foot_contacts_locked is None:
        return []
    steps = f", {stats.foot_steps} steps taken" if stats.foot_steps else ""
    # Agents whose feet the edits left as planted as the source's keep their legs: their
    # contacts count, their legs are not changed.
    kept = f", left as they were on {stats.foot_locking_not_needed} (as planted as the source's)" \
        if stats.foot_locking_not_needed else ""
    return [f"feet: {counted(stats.foot_contacts_locked, 'contacts')}; legs locked on "
            f"{counted(stats.foot_locked_agents or 0, 'agents')}{kept}{steps}; "
            f"skate {_num(stats.foot_skate_source)} source, {_num(stats.foot_skate_unlocked)} after the "
            f"edits, {_num(stats.foot_skate_edited)} locked (stage units/s, mean over agents); "
            f"largest pelvis drop {_num(stats.max_pelvis_drop)}, "
            f"largest foot correction {_num(stats.max_foot_correction)}"]


def plausibility_lines(p: ShotPlausibility | None) -> list[str]:
    """The shot's worst plausibility figures (``stats.plausibility``), as ``solve`` prints them;
    a figure that was not measured (NaN, or null as a stored report reads back) reads "-"."""
    if p is None or not p.agents:
        return []
    lo, hi = p.length_ratio_range or (None, None)
    wlo, whi = p.time_warp_range or (None, None)
    return [
        f"plausibility of {counted(p.agents, 'moved agents')}: largest extra turn {_fixed(p.max_extra_turn_per_frame_at_60fps, 1)} "
        f"deg/frame at 60 fps ({p.max_extra_facing_rate_agent}), {p.spinning_agents} spinning (over 15)",
        ("  no walking direction to compare (no moved agent's source walks)" if not _known(p.max_direction_deviation)
         else f"  largest walking direction change {p.max_direction_deviation:.1f} deg"
         + (f" ({p.max_direction_deviation_agent})" if p.max_direction_deviation_agent else "")
         + (f", {p.max_turned_direction_deviation:.1f} deg against the edit's own turn"
            + (f" ({p.max_turned_direction_deviation_agent})" if p.max_turned_direction_deviation_agent else "")
            if _known(p.max_turned_direction_deviation) else ""))
        + f", {p.reversing_agents} reversing"
        + (" (over 90 against the edit's turn, or turned over 135 from the source's way, or from its"
           " path curve's on one)" if p.max_edit_turn is not None else " (over 90)"),
        f"  path length ratio mean {_fixed(p.mean_length_ratio, 3)} ({_fixed(lo, 3)}..{_fixed(hi, 3)}); "
        f"time warp {_fixed(wlo, 3)}..{_fixed(whi, 3)}; "
        f"foot skate ratio mean {_fixed(p.mean_foot_skate_ratio, 2)} (max {_fixed(p.max_foot_skate_ratio, 2)})"]


def _fixed(value, digits: int) -> str:
    return f"{value:.{digits}f}" if _known(value) else "-"


def finite_values(value):
    """``value`` (nested dicts, lists, numpy arrays and scalars) as plain Python with every number
    that is not finite made None: what strict JSON can hold."""
    if isinstance(value, dict):
        return {str(k): finite_values(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_values(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):   # numpy arrays and scalars
        return finite_values(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _plain(value):
    try:
        import numpy as np
        if isinstance(value, np.generic):
            return value.item()
        if isinstance(value, np.ndarray):
            return value.tolist()
    except ImportError:  # pragma: no cover
        pass
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


# ---- reading a report back from an edits layer, and printing it --------------------------

@dataclass
class StoredReport:
    """A report read back from an edits layer, with the layer's provenance and units."""
    file: str
    report: Report
    version: str = ""
    inputs: list[str] = field(default_factory=list)
    content_hash: str = ""
    meters_per_unit: float | None = None
    up_axis: str | None = None

    def to_dict(self) -> dict:
        out = {"file": self.file, "version": self.version, "inputs": self.inputs,
               "contentHash": self.content_hash, "metersPerUnit": self.meters_per_unit, "upAxis": self.up_axis}
        out.update(self.report.to_layer_dict())
        return out


def select(stored: StoredReport, patterns: list[str] | None = None) -> StoredReport:
    """The report restricted to agents whose path matches one of the fnmatch ``patterns``."""
    if not patterns:
        return stored
    from fnmatch import fnmatchcase
    keep = lambda p: p is not None and any(fnmatchcase(p, pat) for pat in patterns)  # noqa: E731
    r = stored.report
    sub = Report(input=r.input, output=r.output, stats=r.stats, notes=r.notes, timings=r.timings,
                 agents={p: v for p, v in r.agents.items() if keep(p)},
                 constraints=[c for c in r.constraints if keep(c.agent) or keep(c.target)])
    return StoredReport(**{**stored.__dict__, "report": sub})


_UNIT_NAMES = {1.0: "m", 0.01: "cm", 0.001: "mm", 0.1: "dm", 1000.0: "km"}
_TIME_KINDS = ("time", "sync")
#: Agent figures that ``format_text`` lists as they are, by key (the others have their own words).
_LISTED_FIGURES = ("delay",)
#: Shot figures that ``format_text`` shows in their own lines, by field.
_SHOWN_STATS = ("agents", "edited_agents", "clips", "constraints", "groups", "avoid_regions", "animation_layers",
                "remaining_overlaps", "plausibility", "foot_contacts_locked", "foot_locked_agents",
                "foot_skate_source", "foot_skate_edited", "foot_skate_unlocked", "max_pelvis_drop",
                "max_foot_correction", "foot_steps")


def _or(value, default):
    return default if value is None else value


def _known(value) -> bool:
    """A figure that was measured: not None (null in a stored report) and not NaN."""
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def _num(value, digits: int = 4) -> str:
    if not _known(value):
        return "-"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if value == 0:
        return "0"
    if abs(value) < 1e-3 or abs(value) >= 1e6:
        return f"{value:.2e}"
    return f"{value:.{digits}g}"


def _table(rows: list[list[str]], indent: str = "  ") -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return [indent + "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def format_text(stored: StoredReport, show_all: bool = False) -> str:
    """The report as a human-readable text: a summary, then a table per agent."""
    r = stored.report
    mpu = stored.meters_per_unit
    unit = _UNIT_NAMES.get(mpu, f"x{mpu:g} m" if mpu else "units") if mpu else "stage units"
    s = r.stats
    lines = [f"mocapedit report: {stored.file}" + (f"  (mocapedit {stored.version})" if stored.version else "")]
    if stored.inputs:
        lines.append(f"input: {', '.join(stored.inputs)}")
    lines.append(f"lengths in {unit}" + (f", up axis {stored.up_axis}" if stored.up_axis else "") +
                 "; time residuals in time codes")
    lines.append(f"agents: {_or(s.agents, len(r.agents))} read, {s.edited_agents or 0} edited; "
                 f"constraints: {s.constraints or 0}; groups: {s.groups or 0}; "
                 f"avoid regions: {s.avoid_regions or 0}; animation layers: {s.animation_layers or 0}")
    lines.extend(overview(s, r.constraints))
    shown = set(Stats.keys_of(*_SHOWN_STATS))
    others = {k: v for k, v in sorted(s.to_dict().items()) if k not in shown}
    lines.extend(plausibility_lines(s.plausibility))
    lines.extend(foot_locking_lines(s))
    if others:
        lines.append("stats: " + ", ".join(f"{k} {_num(v)}" for k, v in others.items()))
    lines.extend(f"note: {n}" for n in r.notes)

    by_agent: dict[str, list[ConstraintEntry]] = {}
    for c in r.constraints:
        by_agent.setdefault(c.agent or "(no agent)", []).append(c)
    listed = set(AgentEntry._keys()) - set(_LISTED_FIGURES)
    shown = 0
    for path in sorted(set(r.agents) | set(by_agent)):
        fig = r.agents.get(path) or AgentEntry()
        cons = by_agent.get(path, [])
        interesting = fig.edited or cons or fig.notes or (fig.min_separation or 0) < 0
        if not (show_all or interesting):
            continue
        shown += 1
        lines.append("")
        state = "edited" if fig.edited else "not edited"
        lines.append(f"{path}  ({state}" + (f", {fig.frames} frames" if fig.frames is not None else "") + ")")
        parts = []
        if fig.length_ratio is not None:
            parts.append(f"length ratio {_num(fig.length_ratio)}")
        if fig.max_displacement is not None or fig.mean_displacement is not None:
            parts.append(f"displacement max {_num(fig.max_displacement)}, mean {_num(fig.mean_displacement)}")
        if fig.shape_change is not None:
            parts.append(f"shape change {_num(fig.shape_change)}")
        if fig.plausibility is not None:
            p = fig.plausibility
            walking = (f"walking direction change {_num(p.max_direction_deviation)} deg"
                       if _known(p.max_direction_deviation) else "no walking direction to compare")
            extra = p.max_extra_facing_rate / 60.0 if _known(p.max_extra_facing_rate) else None
            parts.append(f"extra turn {_num(extra)} deg/frame at 60 fps"
                         f" ({p.spin_frames} spinning frames), {walking}, foot skate ratio {_num(p.foot_skate_ratio)}")
        if fig.foot_skate_source is not None or fig.foot_skate_edited is not None:
            a, b = fig.foot_skate_source, fig.foot_skate_edited
            change = f" ({'+' if b - a >= 0 else ''}{_num(b - a)})" if a is not None and b is not None else ""
            locked = (f" (before locking {_num(fig.foot_skate_unlocked)})"
                      if fig.foot_skate_unlocked is not None else "")
            parts.append(f"foot skate {_num(a)} -> {_num(b)}{change}{locked}")
        if fig.foot_contacts_locked is not None:
            steps = f", {fig.foot_steps} steps" if fig.foot_steps else ""
            parts.append(f"contacts locked {fig.foot_contacts_locked}{steps}, pelvis drop {_num(fig.max_pelvis_drop)}, "
                         f"foot correction {_num(fig.max_foot_correction)}")
        if fig.min_separation is not None:
            sep = fig.min_separation
            parts.append(f"min separation {_num(sep)}" + ("  OVERLAP" if sep < 0 else ""))
        if fig.min_interval is not None:
            parts.append(f"min interval {_num(fig.min_interval)}")
        if fig.solver is not None:
            parts.append(f"solver {fig.solver}")
        extra = {k: v for k, v in sorted(fig.to_dict().items()) if k not in listed}
        parts.extend(f"{k} {_num(v) if not isinstance(v, (list, dict)) else json.dumps(v)}" for k, v in extra.items())
        if parts:
            lines.append("  " + "; ".join(parts))
        if cons:
            rows = [["constraint", "kind", "frame", "target", "residual", "strength", "met"]]
            for c in cons:
                target = c.target
                if target and c.target_frame is not None:
                    target = f"{target}@{c.target_frame}"
                res = _num(c.residual)
                rows.append([str(c.prim), str(c.kind), _num(c.frame),
                             target or "-", res + (" tc" if c.kind in _TIME_KINDS else ""),
                             "hard" if c.hard else "soft",
                             "yes" if c.met else "NO"])
            lines.extend(_table(rows))
        for n in fig.notes or []:
            lines.append(f"  note: {n}")
    hidden = len(set(r.agents) | set(by_agent)) - shown
    if hidden and not show_all:
        lines.append("")
        lines.append(f"({hidden} agents without edits, constraints or overlaps not shown; --all shows them)")
    return "\n".join(lines)
