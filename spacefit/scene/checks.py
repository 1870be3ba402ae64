"""What every scene-file section shares: the base :class:`Section` that coerces what a TOML file or
Python gives to its fields' types and checks it on construction, and the value checks the sections use.

A section coerces lists to tuples and integers to floats where a number belongs, then checks every
value, naming ``section.key``, the value and the allowed range (:func:`spacefit.errors.check_range`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_flag, check_range, check_vector, quote

Vec3 = tuple[float, float, float]
# Mitsuba traces in float32 (7 significant digits): beyond 100 km from the origin a position is
# coarser than 1 cm and a metre-sized target is no longer resolved; the observer of a far target is
# rendered near and rescaled (light curves), or seen with a long focal length.
MAX_COORDINATE_M = 1e5


class Section:
    """A scene-file section: coerced to its fields' types and checked on construction."""

    SECTION: ClassVar[str] = ""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
            value = coerce(f"{self.SECTION}.{f.name}", getattr(self, f.name), default)
            object.__setattr__(self, f.name, value)
        self.check()

    def check(self) -> None:
        """Check the coerced values (each section's own ranges)."""


def check_position(name: str, value: Sequence[float]) -> None:
    """Check a position (m): 3 finite numbers, each within :data:`MAX_COORDINATE_M` of the origin."""
    v = check_vector(name, value)
    if np.abs(v).max() > MAX_COORDINATE_M:
        raise InputError(f"`{name}` must lie within {MAX_COORDINATE_M:g} m of the origin on each axis (float32 "
                         f"tracing), got {quote(list(value))}; render far targets near and rescale, or lengthen the focal length.")


def deg2rad(values: Sequence[float]) -> tuple[float, ...]:
    """Degrees (user-facing) to radians (everything inside)."""
    return tuple(math.radians(v) for v in values)


def plain(value: Any) -> Any:
    """A value as TOML writes it: tuples as lists."""
    return list(value) if isinstance(value, tuple) else value


def check_int(name: str, value: Any, lo: int, hi: int) -> int:
    """``value`` as an integer in [``lo``, ``hi``], refused as ``name`` otherwise (a bool is no integer here)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"`{name}` must be an integer in [{lo}, {hi}], got {quote(value)}.")
    return int(check_range(name, value, lo, hi))


_NUMBER = (int, float, np.integer, np.floating)


def coerce(name: str, value: Any, default: Any) -> Any:
    """Convert a TOML or Python value to the type of the field's default (numbers, vectors, strings)."""
    if isinstance(default, bool):
        return check_flag(name, value)
    if isinstance(default, int):
        return int(value) if isinstance(value, np.integer) else value  # range and integrality: each section's check
    if isinstance(default, float):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, _NUMBER):
            raise InputTypeError(f"`{name}` must be a number, got {quote(value)}.")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise InputTypeError(f"`{name}` must be a string, got {quote(value)}.")
        return value
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise InputTypeError(f"`{name}` must be a list, got {quote(value)}.")
    if default and isinstance(default[0], str):
        return tuple(str(v) for v in value)
    if default and len(value) != len(default):
        raise InputError(f"`{name}` must have {len(default)} entries, got {list(value)}.")
    if not all(isinstance(v, _NUMBER) and not isinstance(v, (bool, np.bool_)) for v in value):
        raise InputError(f"`{name}` must hold numbers, got {list(value)}.")
    return tuple(v if isinstance(d, int) and not isinstance(d, bool) else float(v) for v, d in zip(value, default or value))
