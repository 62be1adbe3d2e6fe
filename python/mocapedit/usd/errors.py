"""USD's own errors as a user reads them: what the CLI prints when USD refuses a file."""
from __future__ import annotations

import contextlib
import re

from pxr import Tf

__all__ = ["USD_ERRORS", "usd_error_text", "usd_messages", "usd_diagnostics_held"]

#: The exceptions USD raises (Tf errors turned into Python exceptions).
USD_ERRORS = (Tf.ErrorException,)


#: One error in Tf's text: ``Error in '<C++ function>' at line N in file F : '<message>'``.
_TF_ERROR = re.compile(r"Error in '[^']*' at line \d+ in file [^\n]*? : '(.*?)'\s*(?=Error in '|\Z)", re.S)
#: What USD adds after the error that says what was wrong with a layer.
_GENERIC = re.compile(r"Failed to open layer @.*@|Failed to open stage", re.S)


def usd_messages(text: str) -> list[str]:
    """The messages of the errors in Tf's text of a USD failure, without their C++ source
    locations, most specific first: a parse error names the file, line and column
    (``shot.usda:7:1: Expected ) ...``) and comes before USD's "Failed to open layer"."""
    found = [" ".join(m.split()) for m in _TF_ERROR.findall(text)]
    if not found:
        lines = [line.strip() for line in text.splitlines() if line.strip()]
        # Other Tf texts start with a header line and list each error as "... -- message".
        found = [l.split(" -- ", 1)[-1] for l in lines if not l.startswith(("Error in", "Traceback"))]
    specific = [m for m in found if m and not _GENERIC.fullmatch(m)]
    return specific or [m for m in found if m]


def usd_error_text(exc: BaseException) -> str | None:
    """The message of a USD (Tf) error, or None when ``exc`` is not one."""
    if isinstance(exc, USD_ERRORS):
        return "; ".join(usd_messages(str(exc))) or str(exc).strip()
    return None


@contextlib.contextmanager
def usd_diagnostics_held():
    """Holds the warnings and status messages USD would print to stderr (with the C++
    function and source line of each) while the block runs, and yields the list they go
    to (their texts), for the caller to report as it sees fit: opening a stage whose
    sub-layer is missing prints "Warning: in _ReportErrors at line 3326 of stage.cpp"
    before the reader's own error says which file is missing and where."""
    from pxr import UsdUtils

    held: list[str] = []
    delegate = UsdUtils.CoalescingDiagnosticDelegate()
    try:
        yield held
    finally:
        held.extend(d.commentary for d in delegate.TakeUncoalescedDiagnostics())
        del delegate
