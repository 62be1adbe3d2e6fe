"""USD's own errors as a user reads them: what the CLI prints when USD refuses a file."""
from __future__ import annotations

from pxr import Tf

__all__ = ["USD_ERRORS", "usd_error_text"]

#: The exceptions USD raises (Tf errors turned into Python exceptions).
USD_ERRORS = (Tf.ErrorException,)


def usd_error_text(exc: BaseException) -> str | None:
    """The message of a USD (Tf) error, or None when ``exc`` is not one."""
    if isinstance(exc, USD_ERRORS):
        lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
        # Tf's text starts with a header line and lists each error with its C++ source location.
        messages = [l.split(" -- ", 1)[-1] for l in lines if not l.startswith(("Error in", "Traceback"))]
        return "; ".join(messages) or str(exc).strip()
    return None
