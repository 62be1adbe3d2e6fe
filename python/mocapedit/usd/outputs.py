"""Where mocapedit writes: output paths checked against the input, files written whole.

Every command and the Python API write through this module, so three promises hold
everywhere:

- **The input is never overwritten.** :func:`check_outputs` resolves each output's real
  path and refuses one that names the input or any layer it uses (sub-layers,
  references, payloads, value clips), two outputs that name the same file, a folder, or
  an extension the file cannot be written as. It runs before any work.
- **Nothing is written half.** :class:`Writes` writes each file to a temporary beside its
  target and renames all of them into place only when every one is complete.
- **No temporary outlives its process.** Temporaries are removed when the write fails,
  at exit, and on SIGTERM/SIGHUP (the CLI turns those into :class:`Terminated`). A
  process killed outright (SIGKILL) cannot clean up: the next write to the same folder
  removes the temporaries of processes that are gone (:func:`sweep_stale`).
"""
from __future__ import annotations

import atexit
import contextlib
import errno
import os
import secrets
import signal
import socket
import time
from dataclasses import dataclass
from typing import Callable, Iterable

from mocapedit.model.errors import MocapEditError

#: Extensions USD can write a layer as (``.usdz`` is a package USD cannot write to in place).
LAYER_EXTENSIONS = (".usda", ".usdc", ".usd")
#: Marks a temporary of ours: ``.<stem>.mocapedit~<host>~<pid>~<random><ext>``.
TEMP_MARK = ".mocapedit~"
#: A temporary left by a process on another machine is swept once it is this old (seconds).
FOREIGN_TEMP_AGE = 24 * 3600.0

_live: set[str] = set()
_committed: list[str] = []


def committed() -> list[str]:
    """Files this process has renamed into place, in order (complete files)."""
    return list(_committed)


def record_committed(path: str) -> None:
    """Counts a complete file another process (a batch's worker) put in place for this one."""
    path = os.path.abspath(path)
    if path not in _committed:
        _committed.append(path)


class Terminated(BaseException):
    """Raised in the main thread when the process is asked to stop (SIGTERM, SIGHUP).

    A BaseException, like KeyboardInterrupt, so that ``except Exception`` blocks do not
    swallow it while ``finally`` blocks still remove temporaries.
    """

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


@dataclass(frozen=True)
class Output:
    """One file a command is asked to write."""
    path: str
    option: str              # how the user named it: "-o", "--composed", "--report", ...
    kind: str = "layer"      # "layer" (USD), "text", "image", or "any"
    extensions: tuple[str, ...] = ()   # for "image" and "text": the accepted extensions
    stem: str = ".edits"     # what a name the input does not use might end in, before its extension


def _real(path: str) -> str:
    return os.path.realpath(os.path.abspath(path))


def _same_file(a: str, b: str) -> bool:
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)   # hard links, bind mounts
    except OSError:
        return False


def input_files(stage) -> list[str]:
    """Real paths of every file a stage reads: its layers and the assets they name.

    Takes the layers the stage has opened, and walks the root layer's dependencies as
    USD resolves them, so unloaded payloads and value-clip files are included.
    """
    files = {_real(layer.realPath) for layer in stage.GetUsedLayers() if layer.realPath}
    root = stage.GetRootLayer()
    if root.realPath:
        files.update(dependency_files(root.realPath))
    return sorted(files)


def dependency_files(path: str) -> list[str]:
    """Real paths of the layer file ``path`` and of every file it depends on, as USD
    resolves them (sub-layers, references, payloads, value clips), without composing a
    stage. A dependency USD cannot open is left for the reader to report."""
    from pxr import UsdUtils

    from mocapedit.usd.errors import usd_diagnostics_held

    files = {_real(path)}
    try:
        with usd_diagnostics_held():   # what cannot be resolved is the reader's to report
            layers, assets, _unresolved = UsdUtils.ComputeAllDependencies(path)
    except Exception:
        layers, assets = [], []
    files.update(_real(l.realPath) for l in layers if l.realPath)
    files.update(_real(a) for a in assets if a)
    return sorted(files)


def _check_extension(out: Output) -> None:
    ext = os.path.splitext(out.path)[1].lower()
    if out.kind == "layer":
        if ext == ".usdz":
            raise MocapEditError(f"{out.option} {out.path}: USD cannot write a .usdz package here; "
                                 f"give a .usda (text) or .usdc (binary) file and package it afterwards")
        if ext not in LAYER_EXTENSIONS:
            raise MocapEditError(f"{out.option} {out.path}: a USD layer is written as "
                                 f"{', '.join(LAYER_EXTENSIONS)}, not '{ext or 'no extension'}'")
    elif out.extensions and ext not in out.extensions:
        raise MocapEditError(f"{out.option} {out.path}: this file is written as "
                             f"{' or '.join(out.extensions)}, not '{ext or 'no extension'}'")


def check_outputs(outputs: Iterable[Output], inputs: Iterable[str] = ()) -> None:
    """Raises MocapEditError unless every output can be written without losing a file.

    Args:
      outputs: the files to write; ``None`` paths are skipped.
      inputs: every file the job reads (see :func:`input_files`).

    Raises:
      MocapEditError: an output names an input, another output or a folder; its folder
        cannot be made; its extension is not one the file can be written as.
    """
    outputs = [o for o in outputs if o.path is not None]
    inputs = list(inputs)
    for out in outputs:
        if not isinstance(out.path, (str, os.PathLike)) or isinstance(os.fspath(out.path), bytes):
            raise MocapEditError(f"{out.option}: the output path is {out.path!r}, a {type(out.path).__name__}; "
                                 f"give it as a str (or a pathlib.Path)")
    for i, out in enumerate(outputs):
        if not str(out.path).strip():
            raise MocapEditError(f"{out.option}: the output path is empty")
        if os.path.isdir(out.path):
            raise MocapEditError(f"{out.option} {out.path}: is a folder; give the name of a file to write")
        if os.path.exists(out.path) and not os.path.isfile(out.path):
            raise MocapEditError(f"{out.option} {out.path}: is not a regular file (a pipe or a device); mocapedit "
                                 "writes whole files and renames them into place: give the name of a file")
        for source in inputs:
            if _same_file(out.path, source):
                ext = os.path.splitext(out.path)[1] if out.kind == "layer" or not out.extensions else out.extensions[0]
                raise MocapEditError(
                    f"{out.option} {out.path}: names a file the input uses ({source}); mocapedit never "
                    f"overwrites its input: choose another name, e.g. one ending in {out.stem}{ext}")
        _check_extension(out)
        for other in outputs[:i]:
            if _same_file(out.path, other.path):
                raise MocapEditError(f"{out.option} {out.path}: {other.option} names the same file; "
                                     f"give each output its own name")
        _check_folder(out)


def _check_folder(out: Output) -> None:
    """The folder must exist or be makeable, and be writable."""
    folder = os.path.dirname(out.path) or "."
    # Walk up the path as the kernel does (a missing folder before '..' is an error there).
    probe = folder
    while probe and not os.path.exists(probe):
        parent = os.path.dirname(probe)
        if os.path.basename(probe) in ("..", "."):
            raise MocapEditError(f"{out.option} {out.path}: folder {os.path.dirname(probe) or '.'} "
                                 f"does not exist")
        if parent == probe:
            break
        probe = parent
    if probe and os.path.exists(probe) and not os.path.isdir(probe):
        raise MocapEditError(f"{out.option} {out.path}: {probe} is a file, not a folder")
    if probe and os.path.isdir(probe) and not os.access(probe, os.W_OK | os.X_OK):
        raise MocapEditError(f"{out.option} {out.path}: the folder {probe} is not writable")
    if not os.path.isdir(folder) and probe and os.path.isdir(probe):
        # Made when the file is written. Some file systems (/proc, read-only mounts) refuse
        # whatever the permissions say: try a file where the first folder would be made (a
        # folder made and removed here would race with another process writing into it).
        try:
            remove_temporary(temporary_beside(os.path.join(probe, "folder")))
        except OSError as exc:
            raise MocapEditError(f"{out.option} {out.path}: cannot make the folder {folder} in {probe} "
                                 f"({exc.strerror or exc})") from None
    if os.path.isdir(folder):
        # The only sure test (read-only mounts, ACLs, root on a network share) is to try.
        try:
            remove_temporary(temporary_beside(out.path))
        except OSError as exc:
            raise MocapEditError(f"{out.option} {out.path}: cannot write in its folder "
                                 f"({exc.strerror or exc})") from None


# --- temporaries ------------------------------------------------------------------------------

def _host() -> str:
    return socket.gethostname().replace("~", "-") or "host"


_hold_depth = 0
_held_signal: int | None = None


def request_stop(signum: int) -> None:
    """What a signal handler calls to stop the run: raises :class:`Terminated` (or
    KeyboardInterrupt for SIGINT) now, or, inside a few statements that must not be cut in
    two, as soon as they are done."""
    global _held_signal
    if _hold_depth:
        _held_signal = signum
        return
    _raise_stop(signum)


def _raise_stop(signum: int) -> None:
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


@contextlib.contextmanager
def _signals_held():
    """Holds a stop request (see :func:`request_stop`) for a few statements that must not be
    cut in two: creating a temporary and recording it, removing one, renaming a set of files
    into place. (A signal mask would not do: the kernel hands a process's signal to any thread
    that does not block it, and Python runs the handler in the main thread at once.)"""
    global _hold_depth, _held_signal
    _hold_depth += 1
    try:
        yield
    finally:
        _hold_depth -= 1
        if _hold_depth == 0 and _held_signal is not None:
            signum, _held_signal = _held_signal, None
            _raise_stop(signum)


def temporary_beside(path: str) -> str:
    """Creates an empty temporary file in ``path``'s folder and returns its path.

    The name marks it as ours and names this host and process, so that a later run can
    tell a temporary whose writer is gone (see :func:`sweep_stale`). It keeps ``path``'s
    extension (USD picks the file format from it).
    """
    directory, base = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(base)
    umask = os.umask(0)
    os.umask(umask)
    for _ in range(100):
        tmp = os.path.join(directory, f".{stem}{TEMP_MARK}{_host()}~{os.getpid()}~{secrets.token_hex(4)}{ext}")
        with _signals_held():
            try:
                fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666 & ~umask)
            except FileExistsError:
                continue
            os.close(fd)
            _live.add(tmp)
        return tmp
    raise OSError(errno.EEXIST, f"could not create a temporary file beside {path}")


def remove_temporary(tmp: str) -> None:
    with _signals_held():
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        _live.discard(tmp)


def _remove_live() -> None:
    for tmp in list(_live):
        try:
            remove_temporary(tmp)
        except OSError:
            pass


atexit.register(_remove_live)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep_stale(path: str) -> list[str]:
    """Removes temporaries beside ``path`` that a process now gone left behind.

    A temporary of this host is stale when its process no longer runs; one of another
    host (a shared file system) when it is older than :data:`FOREIGN_TEMP_AGE`.
    Returns the removed paths.
    """
    directory, base = os.path.split(os.path.abspath(path))
    prefix = f".{os.path.splitext(base)[0]}{TEMP_MARK}"
    removed = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    host, now = _host(), time.time()
    for name in names:
        if not name.startswith(prefix):
            continue
        # Ours end in the target's extension; USD's own temporary beside ours (while it
        # exports) ends in a random suffix instead. Both name our process.
        fields = name[len(prefix):].split("~")
        if len(fields) != 3 or not fields[1].isdigit():
            continue
        full = os.path.join(directory, name)
        if full in _live:
            continue
        owner, pid = fields[0], int(fields[1])
        try:
            if owner == host:
                stale = not _alive(pid) or pid == os.getpid()
            else:
                stale = now - os.path.getmtime(full) > FOREIGN_TEMP_AGE
            if stale:
                os.unlink(full)
                removed.append(full)
        except OSError:
            continue
    return removed


class Writes:
    """Files written together: each to a temporary, all renamed into place at the end.

    ::

        with Writes() as w:
            w.add("out.usda", lambda tmp: layer.Export(tmp))
            w.add("report.json", write_text("..."))
        # here both files are in place, or (on any exception) neither was touched

    A file's folder is made when needed. On an exception or a signal every temporary is
    removed, no target is touched, and the folders it made are removed again.
    """

    def __init__(self):
        self._pending: list[tuple[str, str]] = []
        self._made: list[str] = []      # folders made for the files, outermost first

    def __enter__(self) -> "Writes":
        return self

    def add(self, path: str, write: Callable[[str], object]) -> None:
        """Writes one file through ``write(temporary path)``; it is renamed at commit."""
        folder = os.path.dirname(os.path.abspath(path))
        missing = []
        while folder and not os.path.exists(folder):
            missing.append(folder)
            folder = os.path.dirname(folder)
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self._made.extend(reversed(missing))
        sweep_stale(path)
        try:
            tmp = temporary_beside(path)
        except OSError as exc:
            raise OSError(exc.errno, f"cannot create a file in its folder ({exc.strerror})", path) from None
        self._pending.append((tmp, path))
        write(tmp)

    def commit(self) -> None:
        with _signals_held():
            for tmp, path in self._pending:
                os.replace(tmp, path)
                _live.discard(tmp)
                _committed.append(os.path.abspath(path))
            self._pending = []

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.commit()
        for tmp, _ in self._pending:
            remove_temporary(tmp)
        self._pending = []
        if exc_type is not None:
            for folder in reversed(self._made):
                try:
                    os.rmdir(folder)     # only when empty: nothing else was put there meanwhile
                except OSError:
                    pass
        self._made = []
        return False


def write_text(text: str) -> Callable[[str], None]:
    """A writer for :meth:`Writes.add` that writes ``text`` as UTF-8."""
    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
    return write


def save_with(path: str, write: Callable[[str], object]) -> None:
    """Writes one file through ``write(temporary path)`` beside it and a rename into place."""
    with Writes() as w:
        w.add(path, write)


def save_text(path: str, text: str) -> None:
    """Writes a text file (a report, a summary) whole, through a temporary and a rename."""
    save_with(path, write_text(text))
