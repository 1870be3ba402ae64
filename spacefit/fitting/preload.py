"""Modules a fit needs only at its end, imported on a thread of their own while it solves.

A fit's report (:mod:`spacefit.fitting.report`) draws its figures with matplotlib: its modules cost the main
thread of the 8-parameter observation fit's process 0.35 s of CPU (load 12; docs/measurements/performance.md),
and nothing of the solve needs them. The solve's main thread mostly waits, without the interpreter's lock, on
the Dr.Jit thread's renders and XLA's programs, so :func:`preload` imports them meanwhile, and the report waits
for them (``.result()``) only where it would have imported them. Only modules of that kind go here: what the
solve imports (JAX's, Mitsuba's, the files' readers) shares modules with them and is imported before the thread
starts, so that no two threads import one module's dependencies in opposite orders.
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
