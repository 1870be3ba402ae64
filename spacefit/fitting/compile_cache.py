"""JAX's compiled programs kept on disk across processes, so a fit compiles its solver once per machine.

A fit's solver, losses and image model are XLA programs that JAX compiles on first use in each process
(about 6 s of the 8-parameter observation fit, issue 33). :func:`use_compile_cache` points JAX's
persistent compilation cache at ``$SPACEFIT_JAX_CACHE_DIR`` (default: ``jax`` in spacefit's cache folder,
:func:`spacefit.geometry.cache.cache_dir`; ``off`` disables it) before the first fit compiles anything.
This is the one piece of JAX's configuration a fit changes for the whole process (its cache folder and
the floors on what is written): JAX opens its cache once per process and has no scoped setting for it.

JAX writes no entry for a program that calls back into Python (``jax.pure_callback``). An image fit's
renders are made before the programs that take them (:mod:`spacefit.fitting.outside`; the solver's step of the
Gauss-Newton family, the noise floor's residuals, the standard errors' tangents, the frames' scene values), so a
second process reads every program of the 8-parameter observation fit from the cache (222 of 222, measured in
docs/measurements/performance.md), and a pass's step too: its frames' own arrays (references, masks) are its operands
(:meth:`~spacefit.fitting.frame_models.FrameModels.operands`), not fetched by a callback. What still calls back (Adam's
and BFGS's steps, a rendered light curve's model, a residual function traced whole, e.g. by ``jax.jacfwd``) is
compiled in every process, Adam's with LLVM's optimisations off (:data:`CALLBACK_COMPILER_OPTIONS`), as are the other
solvers' steps that call back.

A stale entry cannot be used: JAX names each entry by a hash of the program itself (its StableHLO), the
jax and jaxlib versions, the backend and device kind and the compile options, so changed code, another
JAX or another machine looks up another entry and compiles afresh. The folder is trusted code (JAX's
warning): it is the user's own cache folder, like ``~/.drjit`` for Dr.Jit's kernels. Entries are not
evicted (JAX's size limit needs the ``filelock`` package); delete the folder to clear it.

References:
    JAX documentation, "Persistent compilation cache", https://docs.jax.dev/en/latest/persistent_compilation_cache.html
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

from spacefit.geometry.cache import DISABLED, cache_dir

ENV = "SPACEFIT_JAX_CACHE_DIR"
# Programs that compile faster than this are not written. JAX's default, 1 s, would leave out every cacheable
# program of a fit on the CPU (0.01-0.07 s each); reading an entry back takes about a quarter of compiling it.
MIN_COMPILE_S = 0.0
# XLA's options for the programs that call back into Python for their renders (``jax.pure_callback``):
# JAX's cache refuses them, so every process compiles them, and each runs a few times a fit, its time
# mostly the renders'. LLVM's optimisations off (level 0, default 2): the solver's step, when it called back,
# compiled in 2.9 s of CPU in place of 4.1 s and ran 0.04 s slower a call (0.26 s, load 12; performance.md).
# JAX takes compiler options on a top-level jit only (one called from Python, not traced inside another).
CALLBACK_COMPILER_OPTIONS = {"xla_backend_optimization_level": 0}


def jit_calling_back(fn: Callable[..., Any], **jit_kwargs: Any) -> Callable[..., Any]:
    """``jax.jit(fn)`` for a function that calls back into Python for its renders, compiled with
    :data:`CALLBACK_COMPILER_OPTIONS`."""
    return jax.jit(fn, compiler_options=CALLBACK_COMPILER_OPTIONS, **jit_kwargs)


def compile_cache_dir() -> Path | None:
    """The folder of JAX's compiled programs, or None when ``SPACEFIT_JAX_CACHE_DIR`` (or spacefit's whole cache) is off."""
    configured = os.environ.get(ENV, "").strip()
    if configured.lower() == DISABLED:
        return None
    if configured:
        return Path(configured).expanduser()
    base = cache_dir()
    return None if base is None else base / "jax"


def use_compile_cache() -> Path | None:
    """Point JAX's persistent compilation cache at :func:`compile_cache_dir` unless the process chose
    one already (``jax_compilation_cache_dir`` set, e.g. by ``JAX_COMPILATION_CACHE_DIR``) or it is off;
    the folder in use, or None. It takes effect for programs compiled after the call: JAX opens its
    cache at the first compilation that finds a folder set, and keeps it for the process."""
    chosen = jax.config.jax_compilation_cache_dir
    if chosen:
        return Path(chosen)
    folder = compile_cache_dir()
    if folder is None:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_S)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)  # no size floor: CPU programs are small
    return folder
