"""Input validation shared by every layer: one error type and the range checks that raise it.

Every bad input a user can give is reported by :class:`InputError` naming the argument, the value
and the allowed range, before any rendering starts.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np


class InputError(ValueError):
    """A user-supplied value is missing, malformed or outside its allowed range."""


def check_finite(name: str, value: object) -> None:
    """Raise :class:`InputError` if ``value`` (scalar or array) holds NaN or infinity."""
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be finite, got {value!r}.")


def check_range(
    name: str,
    value: float,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
) -> float:
    """Check that a finite scalar lies in an interval and return it as ``float``.

    Args:
        name: the argument's name as the user wrote it (e.g. ``"wrinkles.D"``).
        value: the value to check.
        lo, hi: interval bounds; infinite bounds are unchecked.
        lo_open, hi_open: whether the bound itself is excluded.
        unit: unit shown in the message (e.g. ``"m"``).

    Raises:
        InputError: naming ``name``, the value and the interval.
    """
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be a number, got {value!r}.") from None
    check_finite(name, x)
    below = x <= lo if lo_open else x < lo
    above = x >= hi if hi_open else x > hi
    if below or above:
        left = "(" if lo_open else "["
        right = ")" if hi_open else "]"
        suffix = f" {unit}" if unit else ""
        raise InputError(f"`{name}` must be in {left}{lo:g}, {hi:g}{right}{suffix}, got {x:g}.")
    return x


def check_count(name: str, value: object, lo: int = 1) -> None:
    """Raise :class:`InputError` unless ``value`` is an integer >= ``lo`` (None passes: the default)."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo):
        raise InputError(f"`{name}` must be an integer >= {lo}, got {value!r}.")


def check_vector(name: str, value: Sequence[float], size: int = 3) -> np.ndarray:
    """Check that ``value`` is a finite vector of ``size`` numbers and return it as float64."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be {size} numbers, got {value!r}.") from None
    if arr.shape != (size,):
        raise InputError(f"`{name}` must be {size} numbers, got {value!r}.")
    check_finite(name, arr)
    return arr


def check_choice(name: str, value: str, choices: Iterable[str]) -> str:
    """Check that ``value`` is one of ``choices``; the message lists them and suggests the closest."""
    import difflib

    valid = sorted(choices)
    if value in valid:
        return value
    close = difflib.get_close_matches(str(value), valid, n=1)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    raise InputError(f"`{name}` must be one of {', '.join(map(repr, valid))}; got {value!r}.{hint}")
