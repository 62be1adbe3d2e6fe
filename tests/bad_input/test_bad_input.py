"""Every bad input through the command line: exit 1, a message naming the prim and property
(or the file and line), no traceback, nothing written, the input unchanged.

Most cases run ``mocapedit.cli.main.main`` in-process (a fresh folder each); a sample runs the
installed ``mocapedit`` command as a subprocess.
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import re
import traceback

import pytest

from bad_cases import CASES
from conftest import run_cli
from mocapedit.cli import main as cli

SUBPROCESS_SAMPLE = {"pin-frame-string", "pin-frame-double", "layer-missing-sublayer", "layer-up-axis",
                     "bvh-frame-time-huge", "stationary-reversed", "nodding-other-rig-before-collisions",
                     "output-is-input"}


def _snapshot(folder) -> dict[str, str]:
    """Every file and folder below ``folder`` -> the SHA-256 of its bytes ('dir' for folders)."""
    return {str(p.relative_to(folder)): "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*"))}


def _run_in_process(argv: list[str]) -> tuple[int, str]:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = cli.main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:  # what a user would see as a traceback
            traceback.print_exc(file=err)
            code = "raised"
    return code, err.getvalue()


def check(case, tmp_path, subprocess: bool) -> None:
    folder = tmp_path / "case"
    folder.mkdir()
    argv = case.make(folder)
    before = _snapshot(folder)
    if subprocess:
        proc = run_cli(*argv, cwd=folder)
        code, err = proc.returncode, proc.stderr
    else:
        code, err = _run_in_process(argv)
    assert "Traceback" not in err and "RuntimeWarning" not in err, err
    # USD's own diagnostics name C++ functions and source lines; the error says it better.
    assert "Warning: in " not in err and "pxrInternal" not in err, err
    assert code == 1, err
    lines = [line for line in err.splitlines() if line.startswith("mocapedit: error: ")]
    assert lines, err
    assert re.search(case.needle, lines[-1]), f"{case.needle!r} not in: {lines[-1]}"
    after = _snapshot(folder)
    assert after == before, (f"written or changed: {sorted(set(after.items()) ^ set(before.items()))}")
    for name in case.outputs:
        assert not (folder / name).exists() or name in before


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_cleanly(case, tmp_path):
    check(case, tmp_path, subprocess=False)


@pytest.mark.parametrize("case", [c for c in CASES if c.id in SUBPROCESS_SAMPLE],
                         ids=[c.id for c in CASES if c.id in SUBPROCESS_SAMPLE])
def test_bad_input_through_the_installed_command(case, tmp_path):
    check(case, tmp_path, subprocess=True)


def test_the_suite_covers_enough_cases():
    assert len(CASES) >= 120
    assert len([c for c in CASES if c.id in SUBPROCESS_SAMPLE]) == len(SUBPROCESS_SAMPLE)
