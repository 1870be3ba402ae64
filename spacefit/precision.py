"""JAX's 64-bit mode, scoped: spacefit computes in float64 where it needs to and leaves the
process's JAX configuration as it found it.

The W-M heights and their derivatives in D and G, the solvers' unconstrained coordinates and the
covariance are computed in float64 and only rounded to float32 where Mitsuba takes them.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")


def float64(fn: Callable[P, R]) -> Callable[P, R]:
    """Run ``fn`` with JAX's 64-bit mode on (``jax.enable_x64``), restoring the caller's mode after."""

    @functools.wraps(fn)
    def wrapped(*args: P.args, **kwargs: P.kwargs) -> R:
        import jax  # on first call: a cached render imports spacefit's geometry without needing JAX

        with jax.enable_x64(True):
            return fn(*args, **kwargs)

    return wrapped
