"""Interruptions (Ctrl-C, SIGTERM): at the end of the current step, or at once for a single render.

A signal that lands inside a render raises inside Mitsuba or inside a JAX callback, where it
surfaces as some other error and the step's work is lost. Long loops (a fit's steps, a sweep's
points) instead ask :class:`Deferred` after each unit of work whether to stop; a second signal
interrupts at once. A single render, which has no step to keep, runs in a thread of its own that
the caller abandons on a signal (:func:`run_interruptibly`).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any, TypeVar

SIGNALS = (signal.SIGINT, signal.SIGTERM)
T = TypeVar("T")


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


def caught(signals: tuple[int, ...] = SIGNALS) -> tuple[int, ...]:
    """The ``signals`` this process does not ignore. A process started with a signal ignored keeps it
    ignored, as POSIX tools do: a shell starts a background job (``spacefit fit ... &``) with SIGINT
    ignored, so that the terminal's Ctrl-C does not reach it."""
    return tuple(s for s in signals if signal.getsignal(s) is not signal.SIG_IGN)


@contextmanager
def deferred_interrupts() -> Iterator[Deferred]:
    """Within the block, SIGINT and SIGTERM are recorded instead of raised (main thread only; in other
    threads, where signal handlers cannot be set, they keep their behaviour; an ignored one stays
    ignored, :func:`caught`); the caller's handlers come back after."""
    state = Deferred()
    if threading.current_thread() is not threading.main_thread():
        yield state
        return
    previous = {s: signal.signal(s, state._handle) for s in caught()}
    try:
        yield state
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


# How often the waiting thread of :func:`run_interruptibly` wakes (s): a bound on its reaction to a signal.
POLL_S = 0.05
_abandoned: list[threading.Event] = []  # the ends of work left running by an interruption


def run_interruptibly(work: Callable[[threading.Event], T]) -> T:
    """``work(stop)``'s result, computed in a thread of its own while this (the main) thread waits,
    so that Ctrl-C and SIGTERM stop the caller within :data:`POLL_S` instead of after the render.

    In the main thread, a signal's KeyboardInterrupt surfaces only when Mitsuba's render call
    returns (a pass, seconds to minutes), and then inside Mitsuba's Python code, as a RuntimeError
    with a traceback (Mitsuba's own SIGINT handler only "winds down", which a wavefront render
    ignores, then hands the signal on). Here it is raised in the waiting thread at once:
    KeyboardInterrupt (:class:`Terminated` for SIGTERM, as the caller's handler raises it);
    ``stop`` is set for ``work`` to end at its next check, and the thread is left to finish in the
    background (:func:`abandoned`). Outside the main thread, ``work`` runs in place.
    """
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        return work(stop)
    box: dict[str, Any] = {}
    finished = threading.Event()  # not Thread.join: an interrupted join can leave is_alive() False (CPython < 3.13)

    def target() -> None:
        try:
            box["value"] = work(stop)
        except BaseException as err:  # noqa: BLE001  (handed to the waiting thread, which raises it)
            box["error"] = err
        finally:
            finished.set()

    threading.Thread(target=target, name="spacefit-work", daemon=True).start()
    try:
        while not finished.wait(POLL_S):
            pass
    except BaseException:
        stop.set()
        _abandoned.append(finished)
        raise
    if "error" in box:
        raise box["error"]
    return box["value"]


def abandoned() -> bool:
    """Whether work left behind by an interrupted :func:`run_interruptibly` still runs (the process
    should then end with ``os._exit``: Python's exit would wait for the render to end)."""
    return not all(end.is_set() for end in _abandoned)
