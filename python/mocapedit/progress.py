"""Progress output for long runs: a bar on a terminal, plain lines otherwise."""
from __future__ import annotations

import sys
import time


class Progress:
    """Reports named tasks to a stream. ``quiet`` silences everything."""

    def __init__(self, stream=None, quiet: bool = False, min_interval: float = 0.5):
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.min_interval = min_interval

    def task(self, name: str, total: int) -> "Task":
        return Task(self, name, total)

    def message(self, text: str) -> None:
        if not self.quiet:
            print(text, file=self.stream, flush=True)


class Task:
    def __init__(self, progress: Progress, name: str, total: int):
        self.p, self.name, self.total = progress, name, max(int(total), 0)
        self.start = time.perf_counter()
        self.last = -1e9
        self.count = 0

    def update(self, count: int, extra: str = "") -> None:
        self.count = count
        p = self.p
        if p.quiet:
            return
        now = time.perf_counter()
        if now - self.last < p.min_interval and count < self.total:
            return
        self.last = now
        if p.tty:
            width = 30
            frac = count / self.total if self.total else 1.0
            bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
            print(f"\r{self.name:<24} [{bar}] {count}/{self.total} {extra}", end="", file=p.stream, flush=True)
        else:
            print(f"{self.name}: {count}/{self.total} {extra}".rstrip(), file=p.stream, flush=True)

    def done(self, extra: str = "") -> None:
        p = self.p
        if p.quiet:
            return
        elapsed = time.perf_counter() - self.start
        if p.tty:
            print("\r\033[K", end="", file=p.stream)
        print(f"{self.name}: {self.total} done in {elapsed:.2f} s {extra}".rstrip(), file=p.stream, flush=True)


class Silent(Progress):
    def __init__(self):
        super().__init__(quiet=True)
