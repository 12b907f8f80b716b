"""Errors that servoscope reports to its users.

:class:`ServoscopeError` means *bad input*: the command line prints
``servoscope: error: <message>`` on one line and exits with status 2. Any other
exception is an internal error (exit status 1).
"""

from __future__ import annotations

__all__ = ["ServoscopeError"]


class ServoscopeError(Exception):
    """Bad input from the user: a file, a manifest entry or an option.

    The message names the offending file or option and says what is wrong, in
    one line.
    """
