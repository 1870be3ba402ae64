"""JAX's 64-bit mode, scoped: spacefit computes in float64 where it needs to and leaves the
process's JAX configuration as it found it.

The W-M heights and their derivatives in D and G, the solvers' unconstrained coordinates and the
covariance are computed in float64 and only rounded to float32 where Mitsuba takes them.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar

import numpy as np

if TYPE_CHECKING:
    from jax import Array

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


def on_device(values: Any, dtype: np.dtype | type) -> Array:
    """``values`` (an array, a sequence of numbers) as a JAX array of ``dtype``, converted by NumPy. JAX (0.10)
    makes a program of one operation for ``jnp.asarray`` of a NumPy array without a dtype or of one to convert,
    traced, lowered and read from its cache in every process (8 to 11 ms of CPU each, a warm fit's set-up three of
    them; docs/measurements/performance.md); a NumPy array of the dtype asked is only copied. The same values:
    both round to nearest, bit for bit (subnormals and overflow too). On the device even while JAX traces (not a
    value of the program traced: arrays held for programs' operands, made where a program is first traced)."""
    import jax  # on first call: as float64's
    import jax.numpy as jnp

    with jax.ensure_compile_time_eval():
        return jnp.asarray(np.asarray(values, dtype=dtype), dtype=dtype)
