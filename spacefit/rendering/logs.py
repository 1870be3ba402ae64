"""What Mitsuba and Dr.Jit say around a render: Mitsuba's log held to errors (:func:`errors_only`) and
Dr.Jit's count of the kernels it launched and compiled (:func:`kernel_log`)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from spacefit.rendering.backend import dr, mi, on_drjit_thread


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


@on_drjit_thread
def _drjit_thread_history(on: bool) -> bool:
    """Switch Dr.Jit's kernel history on or off on the process's Dr.Jit thread; the switch's state before."""
    before = bool(dr.flag(dr.JitFlag.KernelHistory))
    dr.set_flag(dr.JitFlag.KernelHistory, on)
    return before


@contextmanager
def kernel_log() -> Iterator[dict[str, float]]:
    """Count the Dr.Jit kernels launched inside the block; the yielded dict is filled on exit.

    Keys: ``launched`` (JIT kernels launched from traced code: Dr.Jit does not count a replayed frozen pass's), ``new`` (not in Dr.Jit's in-memory cache: compiled, or read
    from its on-disk one, ``~/.drjit``), ``compiled`` (in neither), all over the process's threads;
    ``generated`` (kernels whose code was generated, cached or not: a replayed frozen pass generates
    none) and ``compile_s`` (wall time of their code generation and compilation, s), both of the
    kernels launched on the calling thread and on the process's Dr.Jit thread
    (:func:`~spacefit.rendering.backend.on_drjit_thread`), where a fit's and a light curve's renders run.
    Dr.Jit's kernel history is the process's, but only a thread whose flag asks for it adds to it (its
    flags are per thread): the block switches the flag on in those two threads, and a frozen pass sees
    it off (:mod:`spacefit.rendering.frozen`), so that it records and replays inside the block as it
    would outside (Dr.Jit keys its recordings on the flags). A kernel recompiled at every call of a
    loop shows as ``new`` growing with the calls (``compiled`` too while the disk cache lacks it).
    """
    stats: dict[str, float] = {}
    dr.kernel_history_clear()
    launched, read, compiled = dr.detail.launch_stats()  # since the process started: launches, disk-cache reads, compilations
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        before = _drjit_thread_history(True)
        try:
            yield stats
        finally:
            _drjit_thread_history(before)
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            now = dr.detail.launch_stats()
            stats.update(launched=now[0] - launched, new=now[1] - read + now[2] - compiled, compiled=now[2] - compiled,
                         generated=len(jit), compile_s=sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in jit) / 1e3)
