"""Dr.Jit / Mitsuba start-up: the system libLLVM and the variant (llvm_ad_rgb or cuda_ad_rgb).

Mitsuba has one global variant. spacefit selects its own only around its Mitsuba calls
(:func:`variant_scope`) and gives the caller's back after, so a user's own Mitsuba code keeps its
variant. Mitsuba (3.9) has no call back to no variant: a process that never set one finds spacefit's.

Dr.Jit's LLVM backend loads the system's libLLVM at run time. Debian 12's default libLLVM 15 aborts
at the first render ("LLVM ERROR: Cannot select: ... fminimum"), and so did 16 here; 19 works.
Unless the user has set ``DRJIT_LIBLLVM_PATH``, the newest libLLVM >= ``MIN_LLVM_MAJOR`` found is used. This module must be
imported before ``drjit``; the rendering package does so.
"""

from __future__ import annotations

import functools
import glob
import os
import re
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import ParamSpec, TypeVar

MIN_LLVM_MAJOR = 19
LLVM_GLOBS = ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*")


@functools.cache  # the file system's search takes milliseconds, and every render's variant scope asks
def find_libllvm() -> tuple[str | None, int]:
    """Path and major version of the newest system libLLVM (None, 0 when there is none), searched once per process."""
    best: tuple[str | None, int] = (None, 0)
    for pattern in LLVM_GLOBS:
        for path in glob.glob(pattern):
            match = re.search(r"libLLVM[-.](?:so\.)?(\d+)", os.path.basename(path))
            if match and int(match.group(1)) > best[1]:
                best = (path, int(match.group(1)))
    return best


def configure_llvm() -> None:
    """Point Dr.Jit at a libLLVM new enough for it (>= MIN_LLVM_MAJOR), unless ``DRJIT_LIBLLVM_PATH`` is set."""
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return
    path, major = find_libllvm()
    if path is not None and major >= MIN_LLVM_MAJOR:
        os.environ["DRJIT_LIBLLVM_PATH"] = path


configure_llvm()

import drjit as dr  # noqa: E402  (after configure_llvm, which must run first)

from spacefit.rendering import syntax_cache  # noqa: E402

syntax_cache.install()  # before Mitsuba's AD integrators are first imported, at the first variant set

import mitsuba as mi  # noqa: E402

from spacefit.errors import InputError  # noqa: E402


def llvm_problem() -> str | None:
    """Why the LLVM backend cannot render here, or None when it can."""
    path, major = find_libllvm()
    if "DRJIT_LIBLLVM_PATH" not in os.environ and major < MIN_LLVM_MAJOR:
        found = f"found libLLVM {major} ({path})" if path else "found no libLLVM"
        return (
            f"Dr.Jit needs libLLVM >= {MIN_LLVM_MAJOR} on the CPU and {found}. "
            "Install it with: sudo apt-get update && sudo apt-get install -y libllvm19"
        )
    return None


def resolve_variant(requested: str = "auto") -> str:
    """The Mitsuba variant spacefit renders with: cuda_ad_rgb when a CUDA GPU is usable, else
    llvm_ad_rgb, or ``requested`` when it is usable here (else :class:`InputError`). Sets nothing."""
    if requested == "auto":
        requested = "cuda_ad_rgb" if dr.has_backend(dr.JitBackend.CUDA) else "llvm_ad_rgb"
    if requested.startswith("llvm") and (problem := llvm_problem()):
        raise InputError(problem)
    if requested.startswith("cuda") and not dr.has_backend(dr.JitBackend.CUDA):
        raise InputError("`render.variant` 'cuda_ad_rgb' needs an NVIDIA GPU with its driver, and none is usable here; "
                         "use 'auto' or 'llvm_ad_rgb'.")
    if requested not in mi.variants():
        raise InputError(f"`render.variant` {requested!r} is not built into this Mitsuba; it has {mi.variants()}.")
    return requested


_scope_lock = threading.Lock()
_scope_depth = 0  # variant scopes open now, in any thread
_caller_variant: str | None = None  # the variant before the outermost scope opened


@contextmanager
def variant_scope(requested: str = "auto") -> Iterator[str]:
    """Set spacefit's Mitsuba variant (:func:`resolve_variant`) for the calls inside, yielding it,
    and give the caller's back when the outermost scope ends; scopes open in several threads at once
    switch nothing on the way out until the last one ends, and a nested scope of another variant
    gives its outer scope's back. A caller who keeps another variant pays a switch each way per
    outermost scope (about 0.01 s of CPU a pair: Mitsuba reloads its AD integrators, from
    :mod:`~spacefit.rendering.syntax_cache`, docs/reference/api.md); a caller with spacefit's variant, or none, pays nothing."""
    global _scope_depth, _caller_variant
    with _scope_lock:
        entry = mi.variant()
        outermost = _scope_depth == 0
        if outermost:
            _caller_variant = entry
        _scope_depth += 1
    variant = entry
    try:
        variant = resolve_variant(requested)
        if entry != variant:
            mi.set_variant(variant)
        yield variant
    finally:
        with _scope_lock:
            _scope_depth -= 1
            if _scope_depth == 0:
                back = _caller_variant
            elif not outermost and entry != variant:
                back = entry  # a nested scope of another variant: its outer scope's
            else:
                back = None
            if back is not None and mi.variant() != back:
                mi.set_variant(back)


P = ParamSpec("P")
R = TypeVar("R")


def in_variant(method: Callable[P, R]) -> Callable[P, R]:
    """Run a method of an object with a ``variant`` attribute inside :func:`variant_scope` of that variant."""

    @functools.wraps(method)
    def scoped(*args: P.args, **kwargs: P.kwargs) -> R:
        with variant_scope(args[0].variant):  # type: ignore[attr-defined]
            return method(*args, **kwargs)

    return scoped


# Dr.Jit keeps its AD and tracing state per thread (isolation scopes, symbolic-loop recordings), and
# XLA runs a program's host callbacks on whichever thread of its pool is free: a light curve of 4 to
# 24 points, its renders' forward-mode columns made on one thread after their primal images on
# another, failed at random with "ad_add_special(): internal error!", a forward-propagation "outside
# of the current dr.isolate_grad() scope" or a segmentation fault (never when every call ran on one
# thread). Every derivative render of the bridge therefore runs on this process's one Dr.Jit thread.
_drjit_thread: tuple[int, ThreadPoolExecutor] | None = None  # (the process that started it, the thread)
_on_drjit_thread = threading.local()


def _start_drjit_thread() -> None:
    _on_drjit_thread.here = True


def on_drjit_thread(method: Callable[P, R]) -> Callable[P, R]:
    """Run ``method`` on the process's one Dr.Jit thread (the calling thread waits; a call made on
    that thread runs at once): the renders of every JAX callback, whatever XLA thread calls them."""

    @functools.wraps(method)
    def on_thread(*args: P.args, **kwargs: P.kwargs) -> R:
        global _drjit_thread
        if getattr(_on_drjit_thread, "here", False):
            return method(*args, **kwargs)
        with _scope_lock:
            if _drjit_thread is None or _drjit_thread[0] != os.getpid():  # none yet, or one of the parent of a forked process
                _drjit_thread = (os.getpid(), ThreadPoolExecutor(1, "spacefit-drjit", _start_drjit_thread))
            pool = _drjit_thread[1]
        return pool.submit(method, *args, **kwargs).result()

    return on_thread
