"""Warnings and progress lines on stderr (stdout stays clean for ``--json``)."""
from __future__ import annotations

import sys
import time


def warn(message: str) -> None:
    """Print ``motor-comp: warning: <message>`` on stderr."""
    print(f'motor-comp: warning: {message}', file=sys.stderr, flush=True)


class Progress:
    """A percentage line on stderr, refreshed at most 5 times a second.

    Parameters
    ----------
    label : str
        What is being processed (a file name).
    total : int
        Total amount of work (bytes).
    enabled : bool
        Print anything at all (callers pass ``--progress`` or ``stderr.isatty()``).
    """

    def __init__(self, label: str, total: int, *, enabled: bool) -> None:
        self.label = label
        self.total = max(int(total), 1)
        self.enabled = enabled
        self._last = 0.0
        self._shown = False
        self._t0 = time.monotonic()

    def update(self, done: int) -> None:
        """Report ``done`` units of ``total``."""
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.2:
            return
        self._last = now
        self._shown = True
        pct = 100.0 * min(done, self.total) / self.total
        print(f'\r{self.label}: {pct:5.1f} % ({done / 1e6:.1f} of {self.total / 1e6:.1f} MB)',
              end='', file=sys.stderr, flush=True)

    def finish(self) -> None:
        """Terminate the progress line (only if one was printed)."""
        if self.enabled and self._shown:
            dt = time.monotonic() - self._t0
            print(f'\r{self.label}: 100.0 % ({self.total / 1e6:.1f} MB in {dt:.1f} s)',
                  file=sys.stderr, flush=True)
