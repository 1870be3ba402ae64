"""Input validation shared by every layer: one error type and the range checks that raise it.

Every bad input a user can give is reported by :class:`InputError` naming the argument, the value
and the allowed range, before any rendering starts.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np


class InputError(ValueError):
    """A user-supplied value is missing, malformed or outside its allowed range.

    Every public function checks its inputs before any rendering starts and raises this error with a
    one-line message naming the argument, the value given and the values allowed. It is a
    ``ValueError``, so code that catches those catches it too; a value of the wrong type raises a
    subclass that is also a ``TypeError``.

    Example:
        >>> import spacefit as sf
        >>> try:
        ...     sf.load_case("nope")
        ... except sf.InputError as err:
        ...     print(err)
        `case` must be one of 'default', 'materials', 'panels', 'wrinkles', 'wrinkles_128', 'wrinkles_far'; got 'nope'.
    """


class InputTypeError(InputError, TypeError):
    """A user-supplied value has the wrong type (a string where a number belongs, say)."""


# How far below zero, in noise standard deviations, a radiance image with stated noise may dip: Gaussian
# noise passes 5 sigma once in 3.5 million values, so a 600 x 600 RGB image with 2 % noise was refused
# about one time in four; 8 sigma (6e-16 per value) refuses no honest image.
NEGATIVE_SIGMAS = 8.0
# The longest value a message quotes: a 5-million-number vector must not fill the screen.
MAX_QUOTE = 120


def shorten(text: str, limit: int = MAX_QUOTE) -> str:
    """``text``, cut in the middle to at most ``limit`` characters."""
    if len(text) <= limit:
        return text
    half = (limit - 5) // 2
    return f"{text[:half]} ... {text[-half:]}"


# What a function that takes a scene expects, in an error's words.
A_SCENE = "a spacefit Scene (sf.load_scene(path) reads a file, sf.default_scene() is Table 4-2)"


def quote(value: object) -> str:
    """A value as messages show it: its repr, shortened."""
    try:
        return shorten(repr(value))
    except RecursionError:
        return f"<a {type(value).__name__} nested too deep to show>"


@contextmanager
def inside(where: str) -> Iterator[None]:
    """Name the values checked in this block by their full key: an :class:`InputError` about
    ``alpha_x`` raised inside ``inside("parts.panels")`` is re-raised about ``parts.panels.alpha_x``."""
    try:
        yield
    except InputError as err:
        text = str(err)
        raise type(err)(f"`{where}.{text[1:]}" if text.startswith("`") else f"{where}: {text}") from None


def check_finite(name: str, value: object) -> None:
    """Raise :class:`InputError` if ``value`` (scalar or array) holds NaN or infinity, or is not numbers."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, RecursionError, OverflowError):
        raise InputTypeError(f"`{name}` must be a number or numbers, got {quote(value)}.") from None
    if not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be finite, got {quote(value)}.")


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
    if isinstance(value, (bool, np.bool_)):
        raise InputTypeError(f"`{name}` must be a number, got the boolean {value!r}.")
    if isinstance(value, (str, bytes)):  # float("2.0") would pass: a quoted number in a file is a mistake to name
        raise InputTypeError(f"`{name}` must be a number, not a string: got {quote(value)}.")
    try:
        x = float(value)  # type: ignore[arg-type]  (numpy and JAX scalars convert too)
    except (TypeError, ValueError):
        raise InputTypeError(f"`{name}` must be a number, got {quote(value)}.") from None
    check_finite(name, x)
    below = x <= lo if lo_open else x < lo
    above = x >= hi if hi_open else x > hi
    if below or above:
        left = "(" if lo_open else "["
        right = ")" if hi_open else "]"
        suffix = f" {unit}" if unit else ""
        raise InputError(f"`{name}` must be in {left}{lo:g}, {hi:g}{right}{suffix}, got {x:g}.")
    return x


def check_count(name: str, value: object, lo: int = 1, hi: int | None = None, why: str = "", optional: bool = True) -> None:
    """Raise :class:`InputError` unless ``value`` is an integer in [``lo``, ``hi``] (None passes where
    ``optional``: the default); ``why`` says where the upper limit comes from."""
    if value is None and optional:
        return
    allowed = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"`{name}` must be an integer {allowed}, got {quote(value)}.")
    if value < lo or (hi is not None and value > hi):
        raise InputError(f"`{name}` must be an integer {allowed}{f' ({why})' if why else ''}, got {value!r}.")


def check_flag(name: str, value: object) -> bool:
    """Check that ``value`` is a boolean (Python's or numpy's; TOML's true / false) and return it:
    no string, number or None stands for one (``"false"`` would be true)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputTypeError(f"`{name}` must be true or false, got {quote(value)}.")
    return bool(value)


def check_name_list(name: str, value: object) -> tuple[str, ...]:
    """Check that ``value`` is a list (any sequence but a string) of strings and return it as a tuple."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise InputTypeError(f"`{name}` must be a list of names, got {quote(value)}.")
    for i, item in enumerate(value):
        if not isinstance(item, str):
            raise InputTypeError(f"`{name}[{i}]` must be a name (a string), got {quote(item)}.")
    return tuple(value)


def check_path(name: str, value: object) -> Path:
    """Check that ``value`` is a file or folder path (a non-empty string or ``os.PathLike``) and return it as a Path."""
    if not isinstance(value, (str, os.PathLike)) or not str(value).strip():
        raise InputTypeError(f"`{name}` must be a path (a non-empty string or pathlib.Path), got {quote(value)}.")
    if "\0" in str(value):
        raise InputError(f"`{name}` must not hold a NUL character (no file system allows one), got {quote(value)}.")
    return Path(value)


def read_text_rows(name: str, value: object, what: str) -> list[str]:
    """The lines of the text file ``value`` (argument ``name``, a ``what`` such as ``"BRDF table"``) that
    are neither blank nor ``#`` comments; a file that is not UTF-8 text is refused.

    Raises:
        InputError: not a path, no such file, a folder, or not text.
        OSError: the file cannot be read otherwise (permissions, a device error).
    """
    path = check_path(name, value)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"`{name}`: no {what} file {str(path)!r}.") from None
    except IsADirectoryError:
        raise InputError(f"`{name}`: {str(path)!r} is a folder, not a {what} file.") from None
    except UnicodeDecodeError as err:
        raise InputError(f"{what} {str(path)!r} is not a text file (UTF-8): byte {err.start} is {err.object[err.start:err.start + 1]!r}.") from None
    if "\0" in text:
        raise InputError(f"{what} {str(path)!r} is not a text file: it holds NUL characters.")
    return [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def check_type(name: str, value: object, cls: type | tuple[type, ...], what: str) -> None:
    """Raise :class:`InputTypeError` unless ``value`` is an instance of ``cls``; ``what`` names it (``"an sf.Sensor"``)."""
    if not isinstance(value, cls):
        raise InputTypeError(f"`{name}` must be {what}, got {quote(value)}.")


# The arrays an argument may be: what messages call them -> the NumPy dtype kinds they hold.
ARRAY_KINDS = {"an array of real numbers": "iuf", "a bool array": "b"}


def check_array(name: str, value: object, kind: str = "an array of real numbers") -> np.ndarray:
    """``value`` as a NumPy array of ``kind`` (a key of :data:`ARRAY_KINDS`), refusing ragged nested
    lists, strings, objects and complex numbers."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, RecursionError, OverflowError):
        raise InputTypeError(f"`{name}` must be {kind}, got {quote(value)}.") from None
    if arr.dtype.kind not in ARRAY_KINDS[kind]:
        shown = "" if isinstance(value, np.ndarray) else f": {quote(value)}"
        raise InputTypeError(f"`{name}` must be {kind}, got dtype {arr.dtype}{shown}.")
    return arr


def check_vector(name: str, value: Sequence[float], size: int | None = 3) -> np.ndarray:
    """Check that ``value`` is a finite vector of ``size`` numbers (None: one or more) and return it as float64."""
    count = "a list of numbers" if size is None else f"{size} numbers"
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, RecursionError, OverflowError):
        raise InputTypeError(f"`{name}` must be {count}, got {quote(value)}.") from None
    if arr.ndim != 1 or arr.shape[0] != (size or max(arr.shape[0], 1)):
        raise InputError(f"`{name}` must be {count}, got {quote(value)}.")
    check_finite(name, arr)
    return arr


def check_direction(name: str, value: Sequence[float]) -> np.ndarray:
    """Check a direction vector (3 finite numbers, not all zero) and return it normalised (float64).

    It is scaled by its largest component first, so tiny or huge vectors (``[0, 0, -1e-200]``) do
    not under- or overflow on the way to unit length.
    """
    v = unit_rows(check_vector(name, value))
    if not np.all(np.isfinite(v)):
        raise InputError(f"`{name}` must not be the zero vector.")
    return v


def unit_rows(v: np.ndarray) -> np.ndarray:
    """The vectors along the last axis of finite ``v`` at unit length, each scaled by its largest
    component first (no under- or overflow on the way); a zero vector gives NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = v / np.abs(v).max(axis=-1, keepdims=True)
        return scaled / np.linalg.norm(scaled, axis=-1, keepdims=True)


def closest(word: str, valid: Iterable[str]) -> str | None:
    """The valid word closest to a typo (difflib's ratio of at least 0.6), or None."""
    close = difflib.get_close_matches(word, list(valid), n=1)
    return close[0] if close else None


def check_choice(name: str, value: str, choices: Iterable[str]) -> str:
    """Check that ``value`` is one of ``choices``; the message lists them and suggests the closest."""
    valid = sorted(choices)
    if isinstance(value, str) and value in valid:
        return value
    close = closest(value, valid) if isinstance(value, str) else None
    hint = f" Did you mean {close!r}?" if close else ""
    error = InputError if isinstance(value, str) else InputTypeError
    raise error(f"`{name}` must be one of {shorten(', '.join(map(repr, valid)), 2000)}; got {quote(value)}.{hint}")


def negative_pixels(values: np.ndarray, sigma: float | np.ndarray | None = None,
                    used: np.ndarray | None = None) -> int:
    """How many pixels of a radiance image have a used value below zero, or, with the image's noise
    ``sigma`` (scalar, (h, w) or (h, w, c)) stated, below -:data:`NEGATIVE_SIGMAS` sigma."""
    values = np.asarray(values, dtype=float)
    floor = 0.0 if sigma is None else -NEGATIVE_SIGMAS * np.broadcast_to(
        np.asarray(sigma, float)[..., None] if np.ndim(sigma) == 2 else np.asarray(sigma, float), values.shape)
    below = values < floor
    return int(np.count_nonzero(np.any(below if used is None else below & used, axis=-1)))
