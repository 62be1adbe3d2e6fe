"""Progress output for long runs (solve, import, preview).

On a terminal each task draws one bar that it redraws in place (count, percentage,
rate and time left) and replaces with a summary line when it is done. Anywhere else (a
log file, a farm job) a task prints plain lines: nothing while it is young, then one
line every few seconds with the same figures, and one line when it is done, so logs stay
short. ``quiet`` silences everything; the commands set it with ``--quiet``.
"""
from __future__ import annotations

import sys
import time

#: Seconds between redraws of a bar on a terminal.
TTY_INTERVAL = 0.1
#: Seconds between plain progress lines (the first comes after this long too).
LINE_INTERVAL = 5.0
BAR_WIDTH = 24


def format_duration(seconds: float) -> str:
    """'0.42 s', '12 s', '3:05', '1:02:03'."""
    if seconds < 10:
        return f"{seconds:.2f} s"
    if seconds < 60:
        return f"{seconds:.0f} s"
    s = int(round(seconds))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


def format_rate(per_second: float, unit: str = "") -> str:
    if per_second >= 100:
        text = f"{per_second:,.0f}"
    elif per_second >= 1:
        text = f"{per_second:.3g}"
    else:
        text = f"{per_second:.2g}"
    return f"{text} {unit}/s".replace("  ", " ") if unit else f"{text}/s"


def counted(count: int, plural: str) -> str:
    """``count`` things, said in the singular for one: ``counted(1, "agent pairs")`` is "1 agent pair"."""
    return f"{count} {plural[:-1] if count == 1 and plural.endswith('s') else plural}"


class Progress:
    """Reports named tasks to a stream (stderr by default). ``quiet`` silences everything.

    Args:
      stream: where to write; a terminal gets bars, anything else plain lines
      quiet: print nothing
      interval: seconds between updates (default: 0.1 on a terminal, 5 otherwise)
      tty: force bars (True) or plain lines (False); default: ask the stream
      clock: a function returning seconds (for tests); default ``time.perf_counter``
      min_interval: the former name of ``interval``
    """

    def __init__(self, stream=None, quiet: bool = False, interval: float | None = None,
                 tty: bool | None = None, clock=None, min_interval: float | None = None):
        interval = min_interval if interval is None else interval
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)()) if tty is None else tty
        self.interval = interval if interval is not None else (TTY_INTERVAL if self.tty else LINE_INTERVAL)
        self.clock = clock or time.perf_counter

    def task(self, name: str, total: int, unit: str = "") -> "Task":
        """A task of ``total`` steps; call ``update(count)`` or ``advance()``, then ``done()``."""
        return Task(self, name, total, unit)

    def message(self, text: str) -> None:
        if not self.quiet:
            print(text, file=self.stream, flush=True)


class Task:
    def __init__(self, progress: Progress, name: str, total: int, unit: str = ""):
        self.p, self.name, self.total, self.unit = progress, name, max(int(total), 0), unit
        self.start = progress.clock()
        self.last = self.start
        self.count = 0
        self.drawn = False
        self.finished = False

    def __enter__(self) -> "Task":
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.done()
        elif self.drawn and self.p.tty and not self.p.quiet:
            print(file=self.p.stream, flush=True)   # keep the bar; the error goes below it

    def figures(self, now: float | None = None) -> dict:
        """count, total, fraction, elapsed seconds, rate per second and seconds left (or None)."""
        now = self.p.clock() if now is None else now
        elapsed = max(now - self.start, 0.0)
        rate = self.count / elapsed if elapsed > 0 and self.count > 0 else None
        left = (self.total - self.count) / rate if rate and self.total >= self.count else None
        frac = min(self.count / self.total, 1.0) if self.total else 1.0
        return {"count": self.count, "total": self.total, "fraction": frac, "elapsed": elapsed,
                "rate": rate, "left": left}

    def advance(self, steps: int = 1, extra: str = "") -> None:
        self.update(self.count + steps, extra)

    def update(self, count: int, extra: str = "") -> None:
        self.count = int(count)
        p = self.p
        if p.quiet or self.finished:
            return
        now = p.clock()
        if now - self.last < p.interval or self.count >= self.total:
            return
        self.last = now
        self._draw(now, extra)

    def _draw(self, now: float, extra: str) -> None:
        p, f = self.p, self.figures(now)
        parts = [f"{f['count']}/{f['total']}", f"{100.0 * f['fraction']:.0f}%"]
        if f["rate"]:
            parts.append(format_rate(f["rate"], self.unit))
        if f["left"] is not None:
            parts.append(f"{format_duration(f['left'])} left")
        if extra:
            parts.append(extra)
        if p.tty:
            filled = int(f["fraction"] * BAR_WIDTH)
            bar = "#" * filled + "-" * (BAR_WIDTH - filled)
            print(f"\r\033[K{self.name:<20} [{bar}] " + "  ".join(parts), end="", file=p.stream, flush=True)
        else:
            print(f"{self.name}: " + ", ".join(parts), file=p.stream, flush=True)
        self.drawn = True

    def done(self, extra: str = "", count: int | None = None) -> None:
        """Prints the task's summary line: count, time taken and rate. ``count``: the steps
        done when a task stops before its total (which was then only an upper bound)."""
        p = self.p
        if self.finished:
            return
        self.finished = True
        if p.quiet:
            return
        now = p.clock()
        self.count = max(self.count, self.total) if count is None else int(count)
        f = self.figures(now)
        line = f"{self.name}: {counted(self.count, self.unit) if self.unit else self.count} in {format_duration(f['elapsed'])}"
        if f["rate"] and f["elapsed"] >= 0.01:
            line += f" ({format_rate(f['rate'], self.unit)})"
        if extra:
            line += f", {extra}"
        if p.tty:
            print("\r\033[K", end="", file=p.stream)
        print(line, file=p.stream, flush=True)


class Silent(Progress):
    """A Progress that prints nothing (the API's default)."""

    def __init__(self):
        super().__init__(quiet=True)
