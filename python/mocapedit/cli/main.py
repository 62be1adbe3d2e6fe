"""Command line: ``mocapedit <command> ...``. Each command lives in ``mocapedit.cli.commands``."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from mocapedit import __version__
from mocapedit.model.errors import MocapEditError

DESCRIPTION = """\
Edit the motion capture of crowd agents in a USD shot stage without re-simulating.

Author small prims on the stage (MocapPositionConstraint, MocapTimeConstraint,
MocapAgentGroup, MocapAnimationLayer, ... from the mocapEdit schema), then run
`mocapedit solve shot.usda -o shot.edits.usda`. The input is never modified: the
result is a new layer that, placed over the input, plays the edited crowd in any
USD tool. Run `mocapedit <command> --help` for each command."""


DEBUG_HELP = "on an internal error, also print the Python traceback (for a bug report)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mocapedit", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"mocapedit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    from mocapedit.cli import commands
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    for command in sub.choices.values():
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    return parser


EXIT_BAD_INPUT = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 3


def _stop(signum, frame):
    # An exception raised inside an import is caught and printed by USD's module set-up
    # (Tf.PreparePythonModule) instead of stopping the run: try again once it is done.
    f = frame
    while f is not None:
        if f.f_code.co_filename.startswith("<frozen importlib"):
            _send_again(signum)
            return
        f = f.f_back
    from mocapedit.usd.outputs import request_stop
    request_stop(signum)


def _send_again(signum: int) -> None:
    """Delivers ``signum`` to this process again in a moment (a daemon thread: a run that ends
    first is not held up by it)."""
    import os
    import threading
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signum))
    timer.daemon = True
    timer.start()


def _quiet_unraisable(previous):
    """A stop raised while Python runs a ``__del__``, a weakref callback or a garbage
    collector callback is printed as "Exception ignored" and dropped, and the run would go on.
    Such a stop is sent again, to land in the run's own code, and nothing is printed."""
    from mocapedit.usd.outputs import Terminated

    def hook(unraisable):
        exc = unraisable.exc_value
        if isinstance(exc, Terminated):
            _send_again(exc.signum)
        elif isinstance(exc, KeyboardInterrupt):
            import signal
            _send_again(signal.SIGINT)
        else:
            previous(unraisable)
    return hook


def _install_signal_handlers() -> None:
    """SIGTERM and SIGHUP (what farm schedulers and closed terminals send) stop the run
    the way Ctrl-C does: temporaries are removed and nothing is written half."""
    import signal
    import threading
    if threading.current_thread() is not threading.main_thread():
        return
    for name in ("SIGTERM", "SIGHUP", "SIGINT"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _stop)
    sys.unraisablehook = _quiet_unraisable(sys.unraisablehook)


def main(argv: list[str] | None = None) -> int:
    """Runs one command. Exit status: 0 done, 1 bad input or a file that cannot be read or
    written (the message says which), 2 bad usage, 3 internal error, 130/143 interrupted."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return EXIT_USAGE
    from mocapedit.usd.outputs import Terminated
    unraisablehook = sys.unraisablehook
    _install_signal_handlers()
    try:
        import numpy as np
        # Degenerate input (a zero-length path, an agent standing still) is handled where it
        # matters; numpy's floating-point warnings would only be noise on the user's terminal.
        from mocapedit.solve import threads
        threads.check_environment()
        with np.errstate(all="ignore"):
            return int(args.run(args) or 0)
    except MocapEditError as exc:
        return _error(str(exc))
    except BrokenPipeError:
        # The reader went away (``mocapedit report ... | head``): stop quietly.
        _silence_stdout()
        return 141
    except OSError as exc:
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        return _error(f"{where}{exc.strerror or exc}")
    except KeyboardInterrupt:
        print(f"mocapedit: interrupted; {_what_was_written()}", file=sys.stderr)
        return 130
    except Terminated as exc:
        print(f"mocapedit: stopped by signal {exc.signum}; {_what_was_written()}", file=sys.stderr)
        return 128 + exc.signum
    except MemoryError:
        return _error("out of memory; solve fewer agents at once or raise MocapSolveSettings.sampleStep")
    except Exception as exc:
        from mocapedit.usd.errors import usd_error_text
        usd = usd_error_text(exc)
        if usd is not None:
            return _error(f"USD: {usd}")
        if getattr(args, "debug", False):
            import traceback
            traceback.print_exc()
        print(f"mocapedit: internal error: {type(exc).__name__}: {exc}\n"
              "This is a bug in mocapedit, not in your input. Please report it with the command you ran"
              + ("" if getattr(args, "debug", False) else " and the traceback that --debug prints") + ".",
              file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        sys.unraisablehook = unraisablehook


def _what_was_written() -> str:
    """After an interruption: which complete files are in place (each is whole, or absent)."""
    from mocapedit.usd.outputs import committed
    done = committed()
    return "nothing was written" if not done else "complete before the stop: " + ", ".join(done)


def _error(message: str) -> int:
    print(f"mocapedit: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _silence_stdout() -> None:
    import os
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
