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
        s = self.stats
        lines = [f"agents: {s.get('agents', 0)} read, {s.get('editedAgents', 0)} edited; "
                 f"clips: {s.get('clips', 0)}; constraints: {s.get('constraints', 0)}"]
        if self.constraints:
            worst = max((c.get("residual", 0.0) for c in self.constraints), default=0.0)
            lines.append(f"worst constraint residual: {worst:.3g}")
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


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
