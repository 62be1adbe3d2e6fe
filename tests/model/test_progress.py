"""Progress output: bars on a terminal, sparse plain lines elsewhere, silence when quiet."""
from __future__ import annotations

import io

from mocapedit.model.progress import Progress, counted, format_duration, format_rate


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _run(progress, clock, steps=100, dt=0.2):
    task = progress.task("solve paths", steps, "agents")
    for i in range(steps):
        clock.now += dt
        task.update(i + 1)
    task.done("3 fallbacks")


def test_plain_lines_are_sparse_and_give_rate_and_time_left():
    clock, stream = Clock(), io.StringIO()
    _run(Progress(stream=stream, tty=False, clock=clock), clock)
    lines = stream.getvalue().splitlines()
    # 20 s of work, a line every 5 s after the first 5 s, then the summary.
    assert len(lines) == 4, lines
    assert lines[0] == "solve paths: 25/100, 25%, 5 agents/s, 15 s left"
    assert lines[-1] == "solve paths: 100 agents in 20 s (5 agents/s), 3 fallbacks"
    assert "\r" not in stream.getvalue()


def test_a_short_task_prints_only_its_summary():
    clock, stream = Clock(), io.StringIO()
    _run(Progress(stream=stream, tty=False, clock=clock), clock, steps=3, dt=0.01)
    assert stream.getvalue().splitlines() == ["solve paths: 3 agents in 0.03 s (100 agents/s), 3 fallbacks"]


def test_one_of_a_thing_is_said_in_the_singular():
    clock, stream = Clock(), io.StringIO()
    _run(Progress(stream=stream, tty=False, clock=clock), clock, steps=1, dt=0.01)
    assert stream.getvalue().startswith("solve paths: 1 agent in 0.01 s")
    assert counted(1, "agent pairs") == "1 agent pair" and counted(0, "agents") == "0 agents"
    assert counted(2, "agents") == "2 agents"


def test_terminal_bar_is_redrawn_in_place_and_replaced_by_the_summary():
    clock, stream = Clock(), io.StringIO()
    _run(Progress(stream=stream, tty=True, clock=clock), clock, steps=10, dt=0.5)
    text = stream.getvalue()
    frames = [f for f in text.split("\r\033[K") if f]
    assert frames[0].startswith("solve paths") and "[##" in frames[0] and "left" in frames[0]
    assert frames[-1] == "solve paths: 10 agents in 5.00 s (2 agents/s), 3 fallbacks\n"
    assert text.count("\n") == 1


def test_quiet_prints_nothing():
    clock, stream = Clock(), io.StringIO()
    p = Progress(stream=stream, quiet=True, tty=True, clock=clock)
    _run(p, clock)
    p.message("hello")
    assert stream.getvalue() == ""


def test_formats():
    assert format_duration(0.421) == "0.42 s"
    assert format_duration(42.4) == "42 s"
    assert format_duration(185) == "3:05"
    assert format_duration(3723) == "1:02:03"
    assert format_rate(12345.6, "frames") == "12,346 frames/s"
    assert format_rate(0.25) == "0.25/s"


def test_task_as_context_manager_finishes_once():
    clock, stream = Clock(), io.StringIO()
    p = Progress(stream=stream, tty=False, clock=clock)
    with p.task("import", 2) as task:
        task.advance()
        task.advance()
        clock.now = 1.0
    task.done()
    assert stream.getvalue() == "import: 2 in 1.00 s (2/s)\n"
