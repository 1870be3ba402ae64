"""The bias a sensor's noise weight, taken at the fit's noisy render, leaves in the estimate (measured, flagged).

A fit of DN weights each difference by the noise the model predicts, r = (mu + e - y) / sigma(mu + e), with
``V = sigma^2 = floor + g max(mu - offset, 0)`` (:class:`~spacefit.fitting.losses.AffineVariance`) and e the render's
Monte Carlo noise. The weight moves with e, so r is not linear in it: to second order
``E[r] = (mu - y) / sigma - g Var(e) / (2 sigma^3)`` (the Taylor expansion of e / sigma(mu + e) about e = 0), and the
root of the estimating equation puts the model ``g Var(e) / (2 V)`` above the data: a relative brightening of about
half the render noise's relative variance where the shot noise dominates. The two-seed estimate
(:func:`spacefit.fitting.uncertainty.covariance`) removes the Jacobian's share of the render noise, not this one.

Where it matters: the render noise is largest, relative to the signal, in pixels a part covers only partly (a sample
hits it or not). A 6-frame pass of the panels case at 64 px (the legs, 1 to 2 px wide, all edge pixels) fitted at
16 spp: the legs' kd came out +0.0042 (0.84 of its standard errors, 11 fits, pass_coverage.py) and +0.0026 +- 0.0014
at the truth (24 draws of the render noise, noise-free references: pass_render_bias.py), where this expression puts
+0.0033; at 64 spp it is 4 times smaller (docs/measurements/validation.md).

:func:`weight_bias` evaluates it at the fit's linearisation (the render noise per residual from the two seeds'
difference, sigma at the data), and :func:`weight_bias_notes` warns where it is more than :data:`WEIGHT_BIAS_WARN`
of a value's standard error. It is not subtracted: measured on one case only.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from spacefit.fitting.losses import AffineVariance
from spacefit.fitting.residuals import Problem
from spacefit.precision import float64

WEIGHT_BIAS_WARN = 0.5
"""A value's weight bias (:func:`weight_bias`) above this many of its standard errors is warned of."""


@float64
def expected_residuals(problem: Problem, r: np.ndarray, r_alt: np.ndarray) -> np.ndarray | None:
    """Per residual, ``-g Var(e) / (2 sigma^3)`` in the residuals' unit (of the noise): ``Var(e) / sigma^2`` as the two
    seeds' difference squared, ``((r - r_alt) / sqrt 2)^2``, sigma and g at the data (the references), g 0 at or below
    the sensor's offset; 0 for value observations and images without a sensor. None where the residuals are not laid
    out as the images' pixels (a pyramid or statistics loss) or no image has a sensor."""
    terms = problem.noise_terms
    laid_out = problem.pixels + sum(b.data.value.size for b in problem.blocks) == r.size
    if not laid_out or not any(t is not None for t in terms):
        return None
    out, offset = np.zeros(r.size), 0
    for ref, t in zip(problem.references, terms):
        rows = slice(offset, offset + ref.size)
        offset = rows.stop
        if t is None:
            continue
        variance = AffineVariance(*t)
        y = np.ravel(ref).astype(float)
        sigma = np.asarray(variance.sigma(y), dtype=float)
        out[rows] = -np.where(y > variance.offset, variance.slope, 0.0) * 0.5 * (r[rows] - r_alt[rows]) ** 2 / (2.0 * sigma)
    return out


def weight_bias(problem: Problem, r: np.ndarray, r_alt: np.ndarray, step: Callable[[np.ndarray], np.ndarray]) -> np.ndarray | None:
    """The estimate's bias from the noise weight (physical units, per free value): ``step`` (the linearisation's
    Gauss-Newton step of a residual change, :meth:`~spacefit.fitting.uncertainty.Linearisation.step`) of
    :func:`expected_residuals`; None where those are None."""
    expected = expected_residuals(problem, r, r_alt)
    return None if expected is None else np.asarray(step(expected), dtype=float)


def weight_bias_notes(bias: Mapping[str, float], stderr: Mapping[str, float]) -> list[str]:
    """A warning for each value whose weight bias (``bias``, by name) is more than :data:`WEIGHT_BIAS_WARN` of its
    standard error ``stderr``."""
    return [f"{name}: the noise weights taken at the fit's noisy renders bias it by about {b:+.3g} ({b / stderr[name]:+.2g} "
            "of its standard error; not subtracted): the render noise is large where parts cover pixels partly; more "
            "samples per pixel (FitRender) shrink it as 1/spp."
            for name, b in bias.items() if name in stderr and np.isfinite(stderr[name]) and abs(b) > WEIGHT_BIAS_WARN * stderr[name]]
