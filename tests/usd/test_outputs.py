"""Output safety: the input is never overwritten, nothing is written half, no temporary
outlives its process, and every failure reaches the user as one line, never a traceback."""
from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pxr import Usd

from mocapedit.cli import main as cli
from mocapedit.data import examples, walker
from mocapedit.usd import outputs
from mocapedit.model.errors import MocapEditError
from mocapedit.pipeline.processor import solve

from conftest import run_cli, write_toy_stage


def _digests(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if outputs.TEMP_MARK in p.name]


@pytest.fixture
def shot(tmp_path):
    """A stage that references a clip layer, in a folder of its own."""
    folder = tmp_path / "shot"
    folder.mkdir()
    clip = walker.walk(frames=48, name="walk")
    specs = [examples.AgentSpec(f"a{i}", clip, (3.0 * i, 0.0, 0.0), 0.0) for i in range(2)]
    stage = examples.build_crowd_stage(folder / "shot.usda", specs)
    examples.add_position_constraint(stage, "/Edits/pin", "/World/Crowd/a0", 47, (0.5, 0.0, 2.0))
    stage.GetRootLayer().Save()
    return folder


@pytest.mark.parametrize("args", [
    ["solve", "shot.usda", "-o", "shot.usda"],
    ["solve", "shot.usda", "-o", "./sub/../shot.usda"],
    ["solve", "shot.usda", "-o", "e.usda", "--composed", "shot.usda"],
    ["solve", "shot.usda", "-o", "e.usda", "--composed", "clips/walk.usda"],
    ["solve", "shot.usda", "-o", "clips/walk.usda"],
    ["solve", "shot.usda", "-o", "e.usda", "--report", "shot.usda"],
    ["solve", "shot.usda", "-o", "e.usda", "--composed", "e.usda"],
    ["solve", "shot.usda", "-o", "e.usda", "--report", "e.usda"],
    ["detect-stationary", "shot.usda", "-o", "shot.usda"],
    ["detect-stationary", "shot.usda", "-o", "t.usda", "--composed", "clips/walk.usda"],
    ["preview", "shot.usda", "-o", "shot.usda"],
])
def test_no_command_overwrites_its_input_or_writes_one_file_twice(shot, args):
    (shot / "sub").mkdir()
    before = _digests(shot)
    r = run_cli(*args, cwd=shot)
    assert r.returncode == 1, r.stderr
    assert r.stderr.startswith("mocapedit: error: ") and "Traceback" not in r.stderr
    assert _digests(shot) == before, "a file was written or changed"


def test_a_symlink_to_the_input_is_the_input(shot):
    os.symlink("shot.usda", shot / "alias.usda")
    r = run_cli("solve", "shot.usda", "-o", "alias.usda", cwd=shot)
    assert r.returncode == 1 and "input uses" in r.stderr


def test_the_python_api_refuses_to_overwrite_the_stage_it_was_given(shot):
    stage = Usd.Stage.Open(str(shot / "shot.usda"))
    before = _digests(shot)
    with pytest.raises(MocapEditError, match="input uses"):
        solve(stage, output=stage.GetRootLayer().realPath)
    with pytest.raises(MocapEditError, match="input uses"):
        solve(stage, output=str(shot / "e.usda"), composed=str(shot / "clips" / "walk.usda"))
    assert _digests(shot) == before


@pytest.mark.parametrize("output,message", [
    (".", "is a folder"),
    ("x.usdz", ".usdz"),
    ("out.txt", "'.txt'"),
    ("noext", "no extension"),
    ("./missing/../x.usda", "missing does not exist"),
    ("shot.usda/x.usda", "is a file, not a folder"),
    ("/proc/x.usda", "/proc/x.usda"),
])
def test_bad_output_paths_are_one_line_errors(shot, output, message):
    before = _digests(shot)
    r = run_cli("solve", "shot.usda", "-o", output, cwd=shot)
    assert r.returncode == 1, r.stderr
    assert "mocapedit: error: " in r.stderr and message in r.stderr and "Traceback" not in r.stderr
    assert _digests(shot) == before


def test_import_bvh_does_not_overwrite_its_bvh(tmp_path):
    from bvhgen import walk_idle_walk, write_bvh
    bvh = tmp_path / "walk.bvh"
    rig, values, _ = walk_idle_walk()
    write_bvh(bvh, rig, values)
    before = bvh.read_bytes()
    r = run_cli("import-bvh", str(bvh), "-o", str(bvh))
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert bvh.read_bytes() == before


def test_outputs_are_written_together_and_the_report_is_one_of_them(shot):
    r = run_cli("solve", "shot.usda", "-o", "out/e.usda", "--composed", "out/c.usda", "--report", "out/r.json",
                cwd=shot)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (shot / "out").iterdir()) == ["c.usda", "e.usda", "r.json"]
    assert Usd.Stage.Open(str(shot / "out" / "c.usda")).GetPrimAtPath("/World/Crowd/a0")


def test_a_failing_write_leaves_no_target_and_no_temporary(tmp_path):
    def write(tmp):
        Path(tmp).write_text("half")
        raise OSError("disk full")

    with pytest.raises(OSError):
        with outputs.Writes() as w:
            w.add(str(tmp_path / "a.usda"), outputs.write_text("whole"))
            w.add(str(tmp_path / "b.usda"), write)
    assert list(tmp_path.iterdir()) == [], "the first file must not be renamed into place either"


def test_a_failing_write_removes_the_folders_it_made_and_keeps_the_others(tmp_path):
    """A write into folders that did not exist makes them; when it fails, they go again (an
    import of a folder of BVH files whose second file is broken left an empty folder), and a
    folder that was there before, or that something else put a file in meanwhile, stays."""
    def write(tmp):
        raise OSError("disk full")

    (tmp_path / "kept").mkdir()
    with pytest.raises(OSError):
        with outputs.Writes() as w:
            w.add(str(tmp_path / "kept" / "new" / "deeper" / "a.usda"), outputs.write_text("whole"))
            (tmp_path / "kept" / "new" / "other.txt").write_text("someone else's")
            w.add(str(tmp_path / "made" / "b.usda"), write)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"]
    assert sorted(p.name for p in (tmp_path / "kept" / "new").iterdir()) == ["other.txt"]


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_temporaries_of_dead_processes_are_swept_and_live_ones_kept(tmp_path):
    host = outputs._host()
    dead = tmp_path / f".e{outputs.TEMP_MARK}{host}~{_dead_pid()}~00000000.usda"
    alive = tmp_path / f".e{outputs.TEMP_MARK}{host}~{os.getppid()}~00000000.usda"
    foreign_old = tmp_path / f".e{outputs.TEMP_MARK}otherhost~1~00000000.usda"
    foreign_new = tmp_path / f".e{outputs.TEMP_MARK}otherhost~2~00000000.usda"
    unrelated = tmp_path / ".e.usda.swp"
    for p in (dead, alive, foreign_old, foreign_new, unrelated):
        p.write_text("x")
    old = time.time() - outputs.FOREIGN_TEMP_AGE - 60
    os.utime(foreign_old, (old, old))
    outputs.save_with(str(tmp_path / "e.usda"), outputs.write_text("done"))
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(p.name for p in (alive, foreign_new, unrelated)) + ["e.usda"]


@pytest.fixture
def slow_shot(tmp_path):
    """A shot whose edits layer takes a while to write: every agent's end is pulled aside, so
    foot locking bakes its legs."""
    from mocapedit.usd import evaluate
    clip = walker.walk(frames=240, name="walk")
    specs = [examples.AgentSpec(f"a{i:03d}", clip, (4.0 * (i % 20), 0.0, 40.0 * (i // 20)), 0.0)
             for i in range(120)]
    stage = examples.build_crowd_stage(tmp_path / "big.usda", specs)
    for i in range(120):
        agent = f"/World/Crowd/a{i:03d}"
        start, end = evaluate.agent_root_positions(stage, agent, [0.0, 239.0])
        examples.add_position_constraint(stage, f"/Edits/start{i:03d}", agent, 0, tuple(map(float, start)))
        examples.add_position_constraint(stage, f"/Edits/end{i:03d}", agent, 239,
                                         tuple(map(float, end + (1.0, 0.0, 0.0))))
    stage.GetRootLayer().Save()
    return tmp_path


def _start_solve(folder: Path) -> subprocess.Popen:
    exe = Path(sys.executable).with_name("mocapedit")
    return subprocess.Popen([str(exe), "solve", "big.usda", "-o", "out.usda", "--composed", "view.usda", "-q"],
                            cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_temporary(folder: Path, proc: subprocess.Popen, exporting: bool = False,
                        timeout: float = 60.0) -> bool:
    """Waits until a temporary appears (the output checks make and remove one first); with
    ``exporting``, until USD writes its own beside ours (the middle of the write)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        found = _temporaries(folder)
        if found and (not exporting or any(p.suffix != ".usda" for p in found)):
            return True
        time.sleep(0.001)
    return False


@pytest.mark.slow
@pytest.mark.parametrize("when", ["reading", "checking", "writing"])
def test_sigterm_removes_temporaries_and_writes_nothing(slow_shot, when):
    before = _digests(slow_shot)
    proc = _start_solve(slow_shot)
    if when == "reading":
        time.sleep(1.0)
    else:
        assert _wait_for_temporary(slow_shot, proc, exporting=when == "writing"), "the solve ended before it wrote"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert not _temporaries(slow_shot)
    assert "Traceback" not in err
    if (slow_shot / "out.usda").exists() or (slow_shot / "view.usda").exists():
        # The signal came after the last rename (or as the process ended): both files are whole.
        assert proc.returncode in (0, 128 + signal.SIGTERM, -signal.SIGTERM), err
        assert Usd.Stage.Open(str(slow_shot / "view.usda")).GetPrimAtPath("/World/Crowd/a000")
        return
    if proc.returncode == -signal.SIGTERM:
        # Killed while Python was still starting, before the CLI took over SIGTERM.
        assert _digests(slow_shot) == before
        return
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "nothing was written" in err
    assert _digests(slow_shot) == before


@pytest.mark.slow
def test_after_sigkill_mid_write_the_next_run_leaves_no_temporary(slow_shot):
    proc = _start_solve(slow_shot)
    assert _wait_for_temporary(slow_shot, proc, exporting=True), "the solve ended before it wrote"
    proc.kill()
    proc.communicate(timeout=60)
    assert not (slow_shot / "out.usda").exists() and not (slow_shot / "view.usda").exists()
    proc = _start_solve(slow_shot)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert not _temporaries(slow_shot)
    assert Usd.Stage.Open(str(slow_shot / "view.usda")).GetPrimAtPath("/World/Crowd/a000")


def test_an_internal_error_is_one_message_and_the_traceback_waits_for_debug(monkeypatch, capsys, toy_stage):
    from mocapedit.cli.commands import report

    def broken(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(report, "run", broken)
    assert cli.main(["report", str(toy_stage)]) == cli.EXIT_INTERNAL
    err = capsys.readouterr().err
    assert "internal error: ZeroDivisionError: a bug" in err and "Traceback" not in err and "--debug" in err
    assert cli.main(["report", str(toy_stage), "--debug"]) == cli.EXIT_INTERNAL
    assert "Traceback" in capsys.readouterr().err


def test_a_closed_pipe_ends_the_command_quietly(tmp_path):
    stage = write_toy_stage(tmp_path / "shot.usda", agents=40)
    assert run_cli("solve", stage, "-o", tmp_path / "e.usda", "-q").returncode == 0
    exe = Path(sys.executable).with_name("mocapedit")
    r = subprocess.run(f"'{exe}' report --all '{tmp_path / 'e.usda'}' | head -n 1", shell=True,
                       capture_output=True, text=True)
    assert r.stdout.count("\n") == 1
    assert "Traceback" not in r.stderr and "Error" not in r.stderr, r.stderr


_STOP_INSIDE = """
import argparse, gc, os, signal, sys, time, weakref
from mocapedit.cli import main as cli

class Stop:
    # Python prints and drops what a __del__ or a weakref callback raises ("Exception ignored
    # in ..."): a signal handled there must still stop the run, and quietly.
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(100000):
            pass

def run(args):
    if args.where == "weakref":
        class Thing: pass
        thing = Thing()
        ref = weakref.ref(thing, lambda r: Stop.__del__(None))
        del thing
    else:
        Stop()
    for _ in range(300):
        time.sleep(0.01)
    print("finished")
    return 0

parser = argparse.ArgumentParser()
parser.add_argument("where")
parser.set_defaults(run=run)
cli.build_parser = lambda: parser
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.parametrize("where", ["del", "weakref"])
def test_a_signal_handled_where_python_drops_exceptions_still_stops_quietly(tmp_path, where):
    script = tmp_path / "stop_inside.py"
    script.write_text(_STOP_INSIDE)
    proc = subprocess.run([sys.executable, str(script), where], capture_output=True, text=True, timeout=120)
    assert "finished" not in proc.stdout
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert "Traceback" not in proc.stderr and "ignored" not in proc.stderr, proc.stderr
    assert "stopped by signal 15" in proc.stderr


def test_a_pipe_is_refused_before_any_work(tmp_path):
    """A report named as a FIFO was replaced by a regular file (a reader on the pipe got nothing)."""
    fifo = tmp_path / "report.json"
    os.mkfifo(fifo)
    with pytest.raises(MocapEditError, match=r"report\.json: is not a regular file"):
        outputs.check_outputs([outputs.Output(str(fifo), "--report", kind="text", extensions=(".json",))])
    assert fifo.is_fifo()
