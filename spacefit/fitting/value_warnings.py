"""What a fit's values and standard errors warn of: a value at a bound of its range or within a few standard errors
of one, a value poorly determined or not determined, two values strongly correlated (:func:`warnings_for`, on the
errors of :mod:`spacefit.fitting.uncertainty`)."""

from __future__ import annotations

import numpy as np

from spacefit.fitting.params import FreeParameters
from spacefit.scene.entries import Bounds
from spacefit.scene.parameters import parameter

# |correlation| above which two parameters are reported as not separately determined.
CORRELATION_WARN = 0.95
# Standard error, relative to the larger of the value and the parameter's own scale
# (:attr:`~spacefit.scene.entries.Parameter.scale`), above which it is reported as poorly determined.
REL_STDERR_WARN = 0.2
# |correlation| at or above which a parameter near a bound of its range is named beside it (:func:`near_bound`).
NEAR_BOUND_CORRELATION = 0.3
# A value within this many standard errors of a finite bound of its range is near it (:func:`near_bound`).
NEAR_BOUND_STDERRS = 2.0


def near_bound(bounds: Bounds, value: float, stderr: float) -> str | None:
    """"lower" or "upper" where ``value`` lies within :data:`NEAR_BOUND_STDERRS` standard errors ``stderr`` of that
    finite bound of ``bounds``: there its 95 % interval reaches out of the range, and the delta method's normal error
    does not describe an estimate that cannot cross the bound (a blur whose truth is 0, at its bound: 0.030 +- 0.046 px
    on average over 24 fits of a pass, every one above it; docs/measurements/validation.md)."""
    if value - bounds.lo < NEAR_BOUND_STDERRS * stderr:
        return "lower"
    return "upper" if bounds.hi - value < NEAR_BOUND_STDERRS * stderr else None


def warnings_for(params: FreeParameters, values: np.ndarray, stderr: np.ndarray, corr: np.ndarray) -> list[str]:
    out = []
    names = params.names
    for name, b, value in zip(names, params.bijections, values):
        if side := b.at_bound(float(value)):
            out.append(f"{name} = {value:.4g} is at the {side} bound of its range {b.describe()}: the solver pushed "
                       "it there, so neither it nor its standard error is an estimate; the model may not be able "
                       "to match the images (another start, or another free parameter?).")
    for i, (name, b) in enumerate(zip(names, params.bijections)):
        if np.isnan(stderr[i]):
            continue  # no error estimate at all: reported by the caller
        if not np.isfinite(stderr[i]):
            out.append(f"{name} is not determined by these observations (singular J^T J).")
        elif stderr[i] > REL_STDERR_WARN * (scale := max(abs(values[i]), parameter(name).scale, 1e-12)):
            out.append(f"{name} is poorly determined: standard error {stderr[i]:.3g} on {values[i]:.4g} "
                       f"(more than {REL_STDERR_WARN:g} x {scale:.3g}, the larger of its value and its scale).")
        if np.isfinite(stderr[i]) and not b.at_bound(float(values[i])) and (side := near_bound(b, float(values[i]), float(stderr[i]))):
            bound = b.lo if side == "lower" else b.hi
            linked = [f"{names[j]} ({corr[i, j]:+.2f})" for j in range(len(names)) if j != i and abs(corr[i, j]) >= NEAR_BOUND_CORRELATION]
            out.append(f"{name} = {values[i]:.4g} +- {stderr[i]:.2g} lies within {NEAR_BOUND_STDERRS:g} standard errors of the {side} bound "
                       f"{bound:g} of its range: its interval is cut there, so it is not a normal error (the estimate "
                       "cannot fall beyond the bound, so it is biased away from it)"
                       + (f"; the errors of the parameters correlated with it, {', '.join(linked)}, take it as normal and "
                          "may be understated." if linked else "."))
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if abs(corr[i, j]) > CORRELATION_WARN:
                out.append(
                    f"{names[i]} and {names[j]} are correlated ({corr[i, j]:+.3f}): the images determine a "
                    "combination of them better than each; add views, resolution or samples."
                )
    return out
