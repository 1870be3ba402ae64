"""Shared fixtures: the synthetic cases (one source: spacefit/synthetic/, package data) and their references, rendered
once per test session; Ctrl-C at its default in every test process."""

from __future__ import annotations

import functools
import os
import signal

import spacefit as sf
from spacefit.fitting.compile_cache import ENV as JAX_CACHE_ENV

# Hermetic: no test reads or writes the user's cache of JAX's compiled programs (the tests of that cache give
# their own folder); set before any test process or command starts, so that they all inherit it.
os.environ[JAX_CACHE_ENV] = "off"

# The tests of Ctrl-C stand for a terminal's foreground job. A shell starts a background job (`nohup make test &`)
# with SIGINT ignored, which every child inherits and spacefit keeps ignored, as POSIX tools do: at its default
# here, the test processes and the commands they start take Ctrl-C (and an interrupted suite stops) as in a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@functools.cache
def reference(name: str, noise_percent: float = 0.0):
    """Case ``name``'s reference (and noise sigma), rendered once per session."""
    return sf.load_case(name).reference(noise_percent)
