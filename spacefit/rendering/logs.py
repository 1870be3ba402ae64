"""What Mitsuba and Dr.Jit say around a render: Mitsuba's log held to errors (:func:`errors_only`) and
Dr.Jit's count of the kernels it launched and compiled (:func:`kernel_log`)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from spacefit.rendering.backend import dr, mi


@contextmanager
def errors_only() -> Iterator[None]:
    """Mitsuba logs only errors inside the block. Its SIGINT handler logs "Received interrupt signal,
    winding down.." as a warning, though a wavefront render does not wind down: the signal is the
    caller's to report (:func:`spacefit.interrupts.run_interruptibly`). The logger is one for all
    threads, so the block's own warnings are dropped too: keep it to the render call."""
    logger = mi.logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)
    try:
        yield
    finally:
        logger.set_log_level(level)


@contextmanager
def kernel_log() -> Iterator[dict[str, float]]:
    """Count the Dr.Jit kernels launched inside the block; the yielded dict is filled on exit.

    Keys: ``launched`` (JIT kernels), ``new`` (not in Dr.Jit's in-memory cache: compiled, or read
    from its on-disk one, ``~/.drjit``), ``compiled`` (in neither), all over the process's threads
    (a JAX callback may render on one of XLA's), and ``compile_s`` (wall time of code generation
    and compilation of this thread's kernels: Dr.Jit's kernel history is per thread, s). A kernel
    recompiled at every call of a loop shows as ``new`` growing with the calls (``compiled`` too
    while the disk cache lacks it).
    """
    stats: dict[str, float] = {}
    dr.kernel_history_clear()
    launched, read, compiled = dr.detail.launch_stats()  # since the process started: launches, disk-cache reads, compilations
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        try:
            yield stats
        finally:
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            now = dr.detail.launch_stats()
            stats.update(launched=now[0] - launched, new=now[1] - read + now[2] - compiled, compiled=now[2] - compiled,
                         compile_s=sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in jit) / 1e3)
