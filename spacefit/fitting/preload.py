"""Modules a fit needs only at its end, imported on a thread of their own while it solves.

A fit's report (:mod:`spacefit.fitting.report`) draws its figures with matplotlib: its modules take a fit
process 0.3 s of CPU to import (docs/measurements/performance.md), and nothing of the solve needs them. The
solve leaves a core idle most of the time (its renders run on one thread, JAX's programs on one, and the
process's Python waits on them without the interpreter's lock), so :func:`preload` imports them meanwhile,
and the report waits for them (``.result()``) only where it would have imported them. Only modules of that
kind go here: what the solve itself imports (JAX's, Mitsuba's, the files' readers) shares modules with them
and is imported first, before the thread starts.
"""

from __future__ import annotations

import importlib
import threading
from concurrent.futures import Future


def preload(*modules: str) -> Future[None]:
    """Import ``modules`` in order on a new thread; the returned future's ``result()`` waits for them and
    raises what their import raised (an error surfaces where the caller would have imported them)."""
    loaded: Future[None] = Future()

    def load() -> None:
        try:
            for name in modules:
                importlib.import_module(name)
        except BaseException as err:  # handed to the caller, who raises it
            loaded.set_exception(err)
        else:
            loaded.set_result(None)

    threading.Thread(target=load, name="spacefit-preload").start()
    return loaded
