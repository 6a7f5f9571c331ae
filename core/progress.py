"""Progress and cancellation of long work in ``core``: one callback shape, one exception.

A long function takes ``progress(fraction, message)`` (fraction in [0, 1] of
that function's own work, message one line for a person) and ``cancelled()``
(True once the user asked to stop), both optional. It calls :func:`check`
between bounded steps, which raises :class:`Cancelled`, so an operator can run
it in a worker thread and stop it with Esc without leaving anything half-done.
"""

from __future__ import annotations

from collections.abc import Callable

Progress = Callable[[float, str], None]
CancelCheck = Callable[[], bool]


class Cancelled(Exception):
    """Raised between steps once ``cancelled()`` returns True."""


def check(cancelled: CancelCheck | None) -> None:
    """Raise :class:`Cancelled` if ``cancelled`` is given and returns True."""
    if cancelled is not None and cancelled():
        raise Cancelled("cancelled by the user")


def report(progress: Progress | None, fraction: float, message: str) -> None:
    """Call ``progress(fraction, message)`` if given."""
    if progress is not None:
        progress(float(fraction), message)
