"""Shared fixtures: the synthetic cases (one source: spacefit/synthetic/, package data) and their references, rendered
once per test session; Ctrl-C at its default in every test process."""

from __future__ import annotations

import functools
import os
import shutil
import signal
import tempfile

import pytest

# XLA compiles the tests' programs with LLVM's optimisations off (level 0), as spacefit already compiles its
# programs that call back into Python (spacefit.fitting.compile_cache.CALLBACK_COMPILER_OPTIONS): most of a test's
# fit is compiling its programs once, not running them. Set before JAX starts its CPU backend, so the test
# processes, the commands they start and the docs build's kernels inherit it; a level in the caller's XLA_FLAGS
# (e.g. --xla_backend_optimization_level=2, XLA's own) is kept.
XLA_LEVEL = "--xla_backend_optimization_level"
if XLA_LEVEL not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {XLA_LEVEL}=0".strip()

import spacefit as sf  # noqa: E402
from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV

# Hermetic: no test reads or writes the user's cache of JAX's compiled programs (the tests of that cache give
# their own folder). A session compiles into a new folder of its own, made by the first process (pytest-xdist's
# controller) and inherited by its test processes and the commands they start: a program compiled by one test is
# read back by the next that builds the same one (a fifth of test_fit and test_noise_model's CPU). Removed at the end.
SESSION_CACHE_ENV = "SPACEFIT_TEST_JAX_CACHE"
MADE_HERE = SESSION_CACHE_ENV not in os.environ
if MADE_HERE:
    os.environ[SESSION_CACHE_ENV] = tempfile.mkdtemp(prefix="spacefit-test-jax-")
os.environ[JAX_CACHE_ENV] = os.environ[SESSION_CACHE_ENV]


def pytest_sessionfinish(session: pytest.Session) -> None:
    """The session's folder of compiled programs removed by the process that made it."""
    if MADE_HERE:
        shutil.rmtree(os.environ[SESSION_CACHE_ENV], ignore_errors=True)

# The tests of Ctrl-C stand for a terminal's foreground job. A shell starts a background job (`nohup make test &`)
# with SIGINT ignored, which every child inherits and spacefit keeps ignored, as POSIX tools do: at its default
# here, the test processes and the commands they start take Ctrl-C (and an interrupted suite stops) as in a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@functools.cache
def reference(name: str, noise_percent: float = 0.0):
    """Case ``name``'s reference (and noise sigma), rendered once per session."""
    return sf.load_case(name).reference(noise_percent)
