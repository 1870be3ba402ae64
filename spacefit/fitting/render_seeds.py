"""Whether a fit's values depend on its own renders' seeds more than their standard errors carry: the render-seed check.

A fit's estimate is the root of its two renders' estimating equation (:func:`~spacefit.fitting.uncertainty.covariance`),
so each render's Monte Carlo noise moves it, by the Gauss-Newton step that render's residuals take with the fit's
Jacobian. Where no noise is given (no sensor, no ``sigma``), the error carries that through the sandwich of the residuals, a model of the
render noise whose own estimate is poor where the noise is long-tailed (a path that finds a glint holds a pixel many
times its neighbours' noise, a firefly): on two views of the panels case one value of 80 was 5.1 of its standard
errors off, from the fit's own 64 spp renders (the same references fitted with other seeds: 1.3;
docs/measurements/validation.md). The check measures what the model misses: at the fit's point, primal renders with
the fresh seeds :data:`FRESH` (no Jacobian) and the step ``d`` from the fit's two renders' mean residuals to theirs
(:func:`seed_shift`). ``d`` is one draw of the fit's renders' own error less the fresh renders' mean error, of
variance ``(1 + 2 / len(FRESH))`` times the estimate's render-noise variance: ``d_i^2 / (1 + 2 / len(FRESH))`` is that
variance measured once, at this fit's own renders, firefly and all. Where it is more than the error carries for it
(the sandwich's half of the render noise's meat), the excess is added to the value's variance (:func:`seed_excess`),
and a value whose error that widens more than :data:`SEED_WIDENED_WARN` times is named in a warning
(:func:`seed_notes`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax
import numpy as np

from spacefit.fitting.residuals import Problem

# The seed indices of the check's fresh renders (Problem.models_seeded's j: the fit's seeds plus j times
# spacefit.fitting.residuals.INDEPENDENT_SEED_OFFSET; 0 and 1 are the fit's own).
FRESH = (2, 3, 4, 5)
# A value whose standard error the check widened by more than this factor is named in a warning: where the error is
# right and all render noise, one value in 370 (P(chi^2_1 > 9)); one of 120 in docs/measurements/validation.md's study.
SEED_WIDENED_WARN = 3.0


def seed_shift(problem: Problem, x: jax.Array, own: tuple[np.ndarray, np.ndarray],
               step: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(n,): how far the estimate moves when the fit's own two renders at ``x`` (``own``: its residuals with its seeds,
    then with the independent ones) are replaced by the mean of primal renders with the fresh seeds :data:`FRESH`, the
    Jacobian kept (solver coordinates, physical units); ``step``: the Gauss-Newton step of a change of the residuals
    (:meth:`~spacefit.fitting.uncertainty.Linearisation.step`, 0 for a change that is not finite)."""
    fresh = [np.asarray(problem.residual_of(problem.models_seeded(x, j)), dtype=float) for j in FRESH]
    return step(sum(fresh) / len(fresh) - 0.5 * (own[0] + own[1]))


def seed_excess(shift: np.ndarray, modelled: np.ndarray) -> np.ndarray:
    """(n,): per value, the variance its error lacks: one draw of its estimate's render-noise variance,
    ``shift^2 / (1 + 2 / len(FRESH))`` (:func:`seed_shift`'s variance is the fit's two renders' plus the fresh ones'),
    less ``modelled``, the variance the error already carries for it; 0 where that is more."""
    return np.maximum(0.0, shift**2 / (1.0 + 2.0 / len(FRESH)) - modelled)


def seed_notes(shifts: Mapping[str, float], widened: Mapping[str, float], stderr: Mapping[str, float]) -> list[str]:
    """A warning for each value whose standard error ``stderr`` the check widened (``widened``: the factor, by name)
    by more than :data:`SEED_WIDENED_WARN`, with its :func:`seed_shift` (``shifts``, user units)."""
    return [f"{name} depends on the fit's render seed: primal renders with fresh seeds in place of its own two move it by "
            f"{shifts[name]:+.3g} (long-tailed render noise, a firefly, that its error did not carry); its standard error is "
            f"widened {factor:.2g} times to carry it, to {stderr[name]:.3g}; more samples per pixel (FitRender) would shrink it."
            for name, factor in widened.items() if factor > SEED_WIDENED_WARN and name in shifts and name in stderr]
