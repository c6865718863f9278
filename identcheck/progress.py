"""Progress lines for long work, at most one a second, so that a loop over thousands of items says where it
is without flooding the terminal (the verbs pass ``print``-like callbacks down to the work)."""
from __future__ import annotations

import time


class Progress:
    """A throttled progress line: ``line(message)`` reports at most once every ``every_s`` seconds (a ``message``
    may be a callable, built only when reported); ``force=True`` reports anyway (the last item).
    ``first_after_s``: stay silent for that long, so work that ends quickly prints nothing. ``report`` None:
    silent."""

    def __init__(self, report=None, first_after_s: float = 0.0, every_s: float = 1.0):
        self.report = report
        self.start = time.monotonic()
        self.every_s = every_s
        self._said = first_after_s - every_s

    @property
    def elapsed(self) -> float:
        return time.monotonic() - self.start

    def __call__(self, message, force: bool = False) -> None:
        if not self.report:
            return
        now = self.elapsed
        if force or now - self._said >= self.every_s:
            self._said = now
            self.report(message() if callable(message) else message)
