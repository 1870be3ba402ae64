"""Interruptions (Ctrl-C, SIGTERM) that wait for the end of the current step.

A signal that lands inside a render raises inside Mitsuba or inside a JAX callback, where it
surfaces as some other error and the step's work is lost. Long loops (a fit's steps, a sweep's
points) instead ask :class:`Deferred` after each unit of work whether to stop; a second signal
interrupts at once.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that the same clean-up runs (a fit reports its best point)."""


class Deferred:
    """Records the first SIGINT / SIGTERM; :meth:`check` raises KeyboardInterrupt (:class:`Terminated`
    for SIGTERM) at a safe point."""

    def __init__(self) -> None:
        self.requested: int | None = None

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.requested is not None:
            raise KeyboardInterrupt  # asked twice: stop now
        self.requested = signum

    def check(self) -> None:
        """Raise KeyboardInterrupt (Terminated for SIGTERM) if a signal arrived since the loop began."""
        if self.requested == signal.SIGTERM:
            raise Terminated
        if self.requested is not None:
            raise KeyboardInterrupt


@contextmanager
def deferred_interrupts() -> Iterator[Deferred]:
    """Within the block, SIGINT and SIGTERM are recorded instead of raised (main thread only; in other
    threads, where signal handlers cannot be set, they keep their behaviour); the caller's handlers
    come back after."""
    state = Deferred()
    if threading.current_thread() is not threading.main_thread():
        yield state
        return
    previous = {s: signal.signal(s, state._handle) for s in SIGNALS}
    try:
        yield state
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
