"""The solve report: per agent, per constraint, and the solver's notes. JSON-ready."""
from __future__ import annotations

import json
from dataclasses import dataclass, field


@dataclass
class Report:
    input: str = ""
    output: str | None = None
    agents: dict[str, dict] = field(default_factory=dict)        # agent path -> figures
    constraints: list[dict] = field(default_factory=list)        # one entry per constraint prim
    notes: list[str] = field(default_factory=list)               # solver choices, fallbacks, warnings
    stats: dict = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)      # seconds per phase

    def agent(self, path: str) -> dict:
        return self.agents.setdefault(path, {})

    def note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def to_dict(self) -> dict:
        return {"input": self.input, "output": self.output, "stats": self.stats,
                "timings": self.timings, "notes": self.notes, "constraints": self.constraints,
                "agents": self.agents}

    def to_layer_dict(self) -> dict:
        """What the edits layer stores: everything but the timings and the file names, so
        the same input gives the same bytes wherever it is written."""
        return {"stats": self.stats, "notes": self.notes, "constraints": self.constraints,
                "agents": self.agents}

    @classmethod
    def from_dict(cls, data: dict) -> "Report":
        return cls(input=data.get("input", ""), output=data.get("output"), agents=dict(data.get("agents", {})),
                   constraints=list(data.get("constraints", [])), notes=list(data.get("notes", [])),
                   stats=dict(data.get("stats", {})), timings=dict(data.get("timings", {})))

    def to_json(self, indent: int = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, sort_keys=True, default=_plain)

    def summary(self) -> str:
        """What ``mocapedit solve`` prints: the same figures, in the same words, as the
        summary of ``mocapedit report``."""
        s = self.stats
        lines = [f"agents: {s.get('agents', 0)} read, {s.get('editedAgents', 0)} edited; "
                 f"clips: {s.get('clips', 0)}; constraints: {s.get('constraints', 0)}"]
        lines.extend(overview(s, self.constraints))
        lines.extend(plausibility_lines(s.get("plausibility")))
        lines.extend(foot_locking_lines(s))
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


def describe_left(intervals: int, region_frames: int) -> str:
    """What collision avoidance left, in the words progress, notes and reports share."""
    text = f"{intervals} collision interval{'s' if intervals != 1 else ''}"
    if region_frames:
        text += f" and {region_frames} frame{'s' if region_frames != 1 else ''} inside avoid regions"
    return text + " left"


def overview(stats: dict, constraints: list[dict]) -> list[str]:
    """The lines on constraints and overlaps that the solve summary and the report share.

    Constraint figures leave out the soft collision rows; residuals of time and sync
    constraints are in time codes, the others in stage units."""
    lines = []
    checked = [c for c in constraints if c.get("kind") != "collision"]
    if checked:
        unmet = [c for c in checked if not c.get("met", True)]
        hard = [c.get("residual") or 0.0 for c in checked if c.get("hard")]
        lines.append(f"constraints reported: {len(checked)}, met: {len(checked) - len(unmet)}, "
                     f"not met: {len(unmet)}" + (f"; worst hard residual {_num(max(hard))}" if hard else ""))
    if "collisionsPerIteration" in stats:
        iterations = stats.get("collisionIterations", 0)
        lines.append("collision avoidance: " + describe_left(stats.get("remainingOverlaps", 0),
                                                             stats.get("regionFramesLeft", 0)) +
                     f" after {iterations} iteration{'s' if iterations != 1 else ''}")
    elif "remainingOverlaps" in stats:
        lines.append(f"overlapping agent pairs left: {stats['remainingOverlaps']}")
    return lines


def foot_locking_lines(stats: dict) -> list[str]:
    """The shot's foot locking figures, as ``solve`` prints them and the report shows them."""
    if "footContactsLocked" not in stats:
        return []
    return [f"feet: {stats['footContactsLocked']} contacts locked on {stats.get('footLockedAgents', 0)} agents; "
            f"skate {_num(stats.get('footSkateSource'))} source, {_num(stats.get('footSkateUnlocked'))} after the "
            f"edits, {_num(stats.get('footSkateEdited'))} locked (stage units/s, mean over agents); "
            f"largest pelvis drop {_num(stats.get('maxPelvisDrop'))}, "
            f"largest foot correction {_num(stats.get('maxFootCorrection'))}"]


def plausibility_lines(p: dict | None) -> list[str]:
    """The shot's worst plausibility figures (``stats["plausibility"]``), as ``solve`` prints them."""
    if not p or not p.get("agents"):
        return []
    lo, hi = p["lengthRatioRange"]
    wlo, whi = p["timeWarpRange"]
    return [
        f"plausibility of {p['agents']} moved agents: largest extra turn {p['maxExtraTurnPerFrameAt60fps']:.1f} "
        f"deg/frame at 60 fps ({p['maxExtraFacingRateAgent']}), {p['spinningAgents']} spinning (over 15)",
        f"  largest walking direction change {p['maxDirectionDeviation']:.1f} deg"
        + (f" ({p['maxDirectionDeviationAgent']})" if p.get("maxDirectionDeviationAgent") else "")
        + (f", {p['maxTurnedDirectionDeviation']:.1f} deg against the edit's own turn"
           + (f" ({p['maxTurnedDirectionDeviationAgent']})" if p.get("maxTurnedDirectionDeviationAgent") else "")
           if "maxTurnedDirectionDeviation" in p else "")
        + f", {p['reversingAgents']} reversing"
        + (" (over 90 against the edit's turn, or turned over 135)" if "maxEditTurn" in p else " (over 90)"),
        f"  path length ratio mean {p['meanLengthRatio']:.3f} ({lo:.3f}..{hi:.3f}); time warp {wlo:.3f}..{whi:.3f}; "
        f"foot skate ratio mean {p['meanFootSkateRatio']:.2f} (max {p['maxFootSkateRatio']:.2f})"]


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


def _layer_report(layer) -> dict | None:
    data = dict(layer.customLayerData or {}).get("mocapedit")
    if not isinstance(data, dict) or "report" not in data:
        return None
    return data


def load(path: str) -> StoredReport:
    """Reads the report from an edits layer, or from the edits layer a stage sub-layers.

    Raises:
      MocapEditError: the file cannot be read or holds no mocapedit report.
    """
    import os

    from pxr import Sdf, Usd

    from mocapedit.model.errors import MocapEditError
    if not os.path.exists(path):
        raise MocapEditError(f"{path}: no such file")
    try:
        layer = Sdf.Layer.FindOrOpen(path)
    except Exception as exc:  # pxr raises Tf.ErrorException
        raise MocapEditError(f"{path}: cannot be read as a USD layer: {str(exc).strip().splitlines()[-1]}") from None
    if layer is None:
        raise MocapEditError(f"{path}: cannot be read as a USD layer")
    data = _layer_report(layer)
    if data is None:
        # A composed stage: the edits layer is one of the layers it uses.
        stage = Usd.Stage.Open(layer)
        for used in sorted(stage.GetUsedLayers(), key=lambda l: l.identifier):
            data = _layer_report(used)
            if data is not None:
                layer = used
                break
    if data is None:
        raise MocapEditError(f"{path}: holds no mocapedit report (customLayerData mocapedit.report); "
                             "write one with `mocapedit solve STAGE -o EDITS`")
    try:
        parsed = json.loads(data["report"])
    except (TypeError, ValueError) as exc:
        raise MocapEditError(f"{layer.identifier}: customLayerData mocapedit.report is not valid JSON: {exc}") from None
    root = layer.pseudoRoot
    return StoredReport(
        file=layer.identifier, report=Report.from_dict(parsed), version=str(data.get("version", "")),
        inputs=[str(x) for x in data.get("inputs", [])], content_hash=str(data.get("contentHash", "")),
        meters_per_unit=float(root.GetInfo("metersPerUnit")) if root.HasInfo("metersPerUnit") else None,
        up_axis=str(root.GetInfo("upAxis")) if root.HasInfo("upAxis") else None)


def select(stored: StoredReport, patterns: list[str] | None = None) -> StoredReport:
    """The report restricted to agents whose path matches one of the fnmatch ``patterns``."""
    if not patterns:
        return stored
    from fnmatch import fnmatchcase
    keep = lambda p: p is not None and any(fnmatchcase(p, pat) for pat in patterns)  # noqa: E731
    r = stored.report
    sub = Report(input=r.input, output=r.output, stats=r.stats, notes=r.notes, timings=r.timings,
                 agents={p: v for p, v in r.agents.items() if keep(p)},
                 constraints=[c for c in r.constraints if keep(c.get("agent")) or keep(c.get("target"))])
    return StoredReport(**{**stored.__dict__, "report": sub})


_UNIT_NAMES = {1.0: "m", 0.01: "cm", 0.001: "mm", 0.1: "dm", 1000.0: "km"}
_TIME_KINDS = ("time", "sync")
_KNOWN_FIGURES = ("frames", "edited", "lengthRatio", "maxDisplacement", "meanDisplacement", "shapeChange",
                  "footSkateSource", "footSkateEdited", "footSkateUnlocked", "footContactsLocked", "maxPelvisDrop",
                  "maxFootCorrection", "minSeparation", "minInterval", "solver", "notes",
                  "plausibility", "trajectoryJoint")


def _num(value, digits: int = 4) -> str:
    if value is None:
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
    lines.append(f"agents: {s.get('agents', len(r.agents))} read, {s.get('editedAgents', 0)} edited; "
                 f"constraints: {s.get('constraints', 0)}; groups: {s.get('groups', 0)}; "
                 f"avoid regions: {s.get('avoidRegions', 0)}; animation layers: {s.get('animationLayers', 0)}")
    lines.extend(overview(s, r.constraints))
    others = {k: v for k, v in sorted(s.items()) if k not in (
        "agents", "editedAgents", "clips", "constraints", "groups", "avoidRegions", "animationLayers",
        "remainingOverlaps", "plausibility", "footContactsLocked", "footLockedAgents", "footSkateSource",
        "footSkateEdited", "footSkateUnlocked", "maxPelvisDrop", "maxFootCorrection")}
    lines.extend(plausibility_lines(s.get("plausibility")))
    lines.extend(foot_locking_lines(s))
    if others:
        lines.append("stats: " + ", ".join(f"{k} {_num(v)}" for k, v in others.items()))
    lines.extend(f"note: {n}" for n in r.notes)

    by_agent: dict[str, list[dict]] = {}
    for c in r.constraints:
        by_agent.setdefault(c.get("agent") or "(no agent)", []).append(c)
    shown = 0
    for path in sorted(set(r.agents) | set(by_agent)):
        fig = r.agents.get(path, {})
        cons = by_agent.get(path, [])
        interesting = fig.get("edited") or cons or fig.get("notes") or (fig.get("minSeparation") or 0) < 0
        if not (show_all or interesting):
            continue
        shown += 1
        lines.append("")
        state = "edited" if fig.get("edited") else "not edited"
        lines.append(f"{path}  ({state}" + (f", {fig['frames']} frames" if "frames" in fig else "") + ")")
        parts = []
        if "lengthRatio" in fig:
            parts.append(f"length ratio {_num(fig['lengthRatio'])}")
        if "maxDisplacement" in fig or "meanDisplacement" in fig:
            parts.append(f"displacement max {_num(fig.get('maxDisplacement'))}, mean {_num(fig.get('meanDisplacement'))}")
        if "shapeChange" in fig:
            parts.append(f"shape change {_num(fig['shapeChange'])}")
        if "plausibility" in fig:
            p = fig["plausibility"]
            parts.append(f"extra turn {_num(p['maxExtraFacingRate'] / 60.0)} deg/frame at 60 fps"
                         f" ({p['spinFrames']} spinning frames), walking direction change "
                         f"{_num(p['maxDirectionDeviation'])} deg, foot skate ratio {_num(p['footSkateRatio'])}")
        if "footSkateSource" in fig or "footSkateEdited" in fig:
            a, b = fig.get("footSkateSource"), fig.get("footSkateEdited")
            change = f" ({'+' if b - a >= 0 else ''}{_num(b - a)})" if a is not None and b is not None else ""
            locked = f" (before locking {_num(fig['footSkateUnlocked'])})" if "footSkateUnlocked" in fig else ""
            parts.append(f"foot skate {_num(a)} -> {_num(b)}{change}{locked}")
        if "footContactsLocked" in fig:
            parts.append(f"contacts locked {fig['footContactsLocked']}, pelvis drop {_num(fig.get('maxPelvisDrop'))}, "
                         f"foot correction {_num(fig.get('maxFootCorrection'))}")
        if "minSeparation" in fig:
            sep = fig["minSeparation"]
            parts.append(f"min separation {_num(sep)}" + ("  OVERLAP" if sep is not None and sep < 0 else ""))
        if "minInterval" in fig:
            parts.append(f"min interval {_num(fig['minInterval'])}")
        if "solver" in fig:
            parts.append(f"solver {fig['solver']}")
        extra = {k: v for k, v in sorted(fig.items()) if k not in _KNOWN_FIGURES}
        parts.extend(f"{k} {_num(v) if not isinstance(v, (list, dict)) else json.dumps(v)}" for k, v in extra.items())
        if parts:
            lines.append("  " + "; ".join(parts))
        if cons:
            rows = [["constraint", "kind", "frame", "target", "residual", "strength", "met"]]
            for c in cons:
                target = c.get("target")
                if target and c.get("targetFrame") is not None:
                    target = f"{target}@{c['targetFrame']}"
                res = _num(c.get("residual"))
                rows.append([str(c.get("prim", "-")), str(c.get("kind", "-")), _num(c.get("frame")),
                             target or "-", res + (" tc" if c.get("kind") in _TIME_KINDS else ""),
                             "hard" if c.get("hard") else "soft",
                             "yes" if c.get("met", True) else "NO"])
            lines.extend(_table(rows))
        for n in fig.get("notes", []) or []:
            lines.append(f"  note: {n}")
    hidden = len(set(r.agents) | set(by_agent)) - shown
    if hidden and not show_all:
        lines.append("")
        lines.append(f"({hidden} agents without edits, constraints or overlaps not shown; --all shows them)")
    return "\n".join(lines)
