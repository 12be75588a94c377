"""SIGINT deferred while a part or the destination is written (:mod:`gnipy.streaming`): Ctrl-C
never lands inside an HDF5 call."""

from __future__ import annotations

import signal
import threading


class DeferredInterrupt:
    """While active, SIGINT only sets `pending` (the HDF5 call under way completes); `check()`
    raises `KeyboardInterrupt` between calls. Installed only in the main thread and only where
    SIGINT has Python's default handler (an ignored SIGINT or the caller's own handler is left
    alone)."""

    def __init__(self):
        self.pending = False
        self._old = None

    def _handler(self, signum, frame):
        self.pending = True

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            try:
                if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                    self._old = signal.signal(signal.SIGINT, self._handler)
            except (ValueError, OSError):  # pragma: no cover - not the main interpreter
                self._old = None
        return self

    def check(self) -> None:
        """Raise `KeyboardInterrupt` if SIGINT came while active."""
        if self.pending:
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
            self._old = None
        return False
