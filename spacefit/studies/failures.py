"""Classify a fit against known true values: did it succeed, and if not, how did it fail?

For studies on synthetic references, where the truth is known: the solver-stability study
(``experiments/stability.py``) classifies every run with it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from spacefit.errors import InputError
from spacefit.fitting.status import Status

if TYPE_CHECKING:
    from spacefit.fitting.result import FitResult

FAILURE_CLASSES = ("success", "nan", "stalled", "wrong_minimum", "unidentifiable")
# Relative tolerance of every parameter unless told otherwise.
DEFAULT_TOLERANCE = 0.05
# Parameters whose tolerance (and error) is absolute, with their default tolerance: D lives in
# (2, 3), where a relative error means little.
ABSOLUTE_TOLERANCE = {"wrinkles.D": 0.02}
# An estimate within this many standard errors of the truth is one the fit cannot tell from it.
COVERAGE = 2.0


def tolerances(names: Sequence[str], tolerance: Mapping[str, float] | float) -> dict[str, float]:
    """Tolerance of each parameter: relative, except absolute for :data:`ABSOLUTE_TOLERANCE`'s names.

    A float applies to every relative parameter; the absolute ones keep their defaults (D: 0.02).
    A mapping gives per-parameter tolerances in the same units; names it leaves out take the
    defaults (:data:`DEFAULT_TOLERANCE` relative, :data:`ABSOLUTE_TOLERANCE` absolute).
    """
    given = dict(tolerance) if isinstance(tolerance, Mapping) else {}
    default = DEFAULT_TOLERANCE if isinstance(tolerance, Mapping) else float(tolerance)
    out = {n: float(given.get(n, ABSOLUTE_TOLERANCE.get(n, default))) for n in names}
    for name, value in out.items():
        if not (math.isfinite(value) and value >= 0):
            raise InputError(f"tolerance of {name} must be a finite number >= 0, got {value!r}.")
    return out


def errors(values: Mapping[str, float], truth: Mapping[str, float]) -> dict[str, float]:
    """Signed error of each estimate, in its tolerance's units: ``value / truth - 1`` (relative),
    or ``value - truth`` for the absolute parameters (``wrinkles.D``)."""
    return {n: values[n] - t if n in ABSOLUTE_TOLERANCE else values[n] / t - 1.0 for n, t in truth.items()}


def classify(
    result: FitResult, truth: Mapping[str, float], tolerance: Mapping[str, float] | float = DEFAULT_TOLERANCE
) -> str:
    """The outcome of a fit as one of :data:`FAILURE_CLASSES`.

    ``truth`` holds the true value of every free parameter of ``result`` (physical units).
    ``tolerance``: a float is a relative tolerance, ``|value - truth| <= tolerance * |truth|``, for
    every parameter except ``wrinkles.D``, whose tolerance is absolute, 0.02 unless given in a
    mapping; a mapping gives per-parameter tolerances (relative, absolute for ``wrinkles.D``), and
    parameters it leaves out take the defaults (0.05 relative, 0.02 absolute for D).

    The first rule that holds decides:

    1. ``"nan"``: a fitted value or the final loss is not finite, or the status is
       :attr:`~spacefit.Status.NONFINITE`.
    2. ``"unidentifiable"``: a standard error is infinite or NaN (the images do not determine that
       parameter, even if its value happens to be close), or the estimate is outside tolerance but
       every parameter outside tolerance is within 2 standard errors of its truth (the fit's own
       errors cannot tell the truth apart).
    3. ``"success"``: every parameter is within tolerance of its truth (converged or not).
    4. ``"stalled"``: the solver did not report convergence (``result.success`` False, and the status
       is no verdict on a converged solve: a misfit or a parameter at a bound).
    5. ``"wrong_minimum"``: it converged to a point outside tolerance that its standard errors
       exclude (some parameter more than 2 standard errors from its truth).

    Raises:
        InputError: if ``truth`` misses a free parameter of ``result``, holds a non-finite value,
            or a zero truth where the tolerance is relative.
    """
    missing = [n for n in result.names if n not in truth]
    if missing:
        raise InputError(f"`truth` has no value for {', '.join(missing)}; give one for every free parameter.")
    truth = {n: float(truth[n]) for n in result.names}
    for name, value in truth.items():
        if not math.isfinite(value) or (value == 0 and name not in ABSOLUTE_TOLERANCE):
            raise InputError(f"truth of {name} must be finite (and non-zero for a relative tolerance), got {value!r}.")
    tol = tolerances(result.names, tolerance)

    values = {n: float(result.values[n]) for n in result.names}
    finite = all(math.isfinite(v) for v in values.values()) and math.isfinite(result.loss)
    if not finite or result.status is Status.NONFINITE:
        return "nan"
    stderr = {n: float(result.stderr[n]) for n in result.names}
    if not all(math.isfinite(s) for s in stderr.values()):
        return "unidentifiable"
    outside = [n for n, e in errors(values, truth).items() if abs(e) > tol[n]]
    if outside and all(abs(values[n] - truth[n]) <= COVERAGE * stderr[n] for n in outside):
        return "unidentifiable"
    if not outside:
        return "success"
    converged = result.success or result.status in (Status.MISFIT, Status.AT_BOUND)
    return "wrong_minimum" if converged else "stalled"
