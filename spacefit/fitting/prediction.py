"""Predictive intervals of a value observation (a light curve, a table) at a fit's values: the
observation's own error and the parameters' errors together.

For the model y(theta) of an observation's values (in its residuals' space: ln y for values fitted
by their logarithm, :class:`~spacefit.fitting.observations.base.MeasuredValues`), the fitted values
theta with covariance C, and the observation's noise sigma_obs, the predictive variance of a new
value is, to first order in theta (the delta method; e.g. Seber & Wild 1989, *Nonlinear
Regression*, sec. 5.1),

    sigma^2 = sigma_obs^2 + diag(J C J^T),    J = d y / d theta,

J the model's Jacobian at the fitted values (JAX forward mode). The noise sigma_obs is the stated
error of each value where the observation states it, else a given one, such as
:func:`residual_noise`: the root mean square of a fit's own residuals over its degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_choice, check_range, check_type
from spacefit.fitting.observations.base import ValueObservation
from spacefit.fitting.result import FitResult
from spacefit.precision import float64


@dataclass(frozen=True)
class Prediction:
    """Predicted values with their predictive errors, in an observation's residual space (ln of the
    values for a logarithmic one).

    Attributes:
        value: (n,) the model's values at the fitted parameters.
        sigma_parameters: (n,) the parameters' share, sqrt(diag(J C J^T)).
        sigma_noise: (n,) the observation's own error.
        noise: where ``sigma_noise`` came from: ``"stated"`` (the observation's errors) or ``"given"``.
        log: the values are logarithms (natural) of the observation's.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> result = sf.fit([plates], ["parts.panel.kd"])
        >>> s = np.array([result.stderr[n] for n in result.names])
        >>> prediction = sf.predictive_intervals(plates, result.names, result.values, result.correlation * np.outer(s, s))
        >>> prediction.noise
        'stated'
    """

    value: np.ndarray
    sigma_parameters: np.ndarray
    sigma_noise: np.ndarray
    noise: str
    log: bool

    @property
    def sigma(self) -> np.ndarray:
        """(n,) the predictive standard error, sqrt(sigma_noise^2 + sigma_parameters^2)."""
        return np.hypot(self.sigma_noise, self.sigma_parameters)


def covariance_of(result: FitResult) -> np.ndarray:
    """A fit's (n, n) covariance of its free values, in ``result.names`` order (physical units),
    from its standard errors and correlation."""
    check_type("result", result, FitResult, "an sf.FitResult")
    stderr = np.array([result.stderr[n] for n in result.names], dtype=float)
    return np.asarray(result.correlation, dtype=float) * np.outer(stderr, stderr)


@float64
def predictive_intervals(observation: ValueObservation, names: Sequence[str], values: Mapping[str, float], covariance: np.ndarray, *,
               noise: float | None = None) -> Prediction:
    """The predictive values and errors of ``observation`` (the guide "BRDF tables and light curves as observations") at the parameter
    ``values`` (by name; those of ``names`` it depends on move it) with ``covariance`` ((n, n),
    ``names`` order). ``noise``: the observation's error in its residual space (relative for a
    logarithmic one), used where it states none.

    Raises:
        InputError: ``noise`` missing for an observation without stated errors, or not positive; a
            covariance of the wrong shape or not finite; a name without a value.

    Args:
        observation: a value observation (:class:`PlateLightCurve`, :class:`BRDFTableObservation`, ...).
        names: the fit's parameter names, ``covariance``'s order.
        values: the parameter values by name.
        covariance: (n, n) the parameters' covariance.
        noise: the observation's error where it states none.

    Returns:
        A :class:`Prediction`.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> result = sf.fit([plates], ["parts.panel.kd"])
        >>> s = np.array([result.stderr[n] for n in result.names])
        >>> prediction = sf.predictive_intervals(plates, result.names, result.values, result.correlation * np.outer(s, s))
        >>> prediction.log, prediction.value.shape  # ln of the irradiance
        (True, (3,))
    """
    check_type("observation", observation, ValueObservation, "a value observation (sf.PlateLightCurve, ...)")
    names = tuple(str(n) for n in names)
    cov = np.asarray(covariance, dtype=float)
    if cov.shape != (len(names), len(names)) or not np.all(np.isfinite(cov)):
        raise InputError(f"`covariance` must be a finite ({len(names)}, {len(names)}) matrix for {len(names)} names, got shape {cov.shape}.")
    missing = [n for n in names if n not in values]
    if missing:
        raise InputError(f"`values` has no value of {missing}; it must hold every one of `names`.")
    block = observation.block(names)
    x = jnp.asarray([float(values[n]) for n in names])

    def model(x: jax.Array) -> jax.Array:
        y = block.model(x, 0)
        return jnp.log(y) if block.data.log else y

    y = np.asarray(model(x))
    jac = np.asarray(jax.jacfwd(model)(x))
    sigma_parameters = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0))
    if block.data.sigma is not None:
        return Prediction(y, sigma_parameters, np.asarray(block.data.sigma, dtype=float), "stated", block.data.log)
    if noise is None:
        raise InputError(f"{block.data.source} states no errors: give `noise`, its error (e.g. sf.residual_noise of the fit).")
    check_range("noise", noise, 0.0, lo_open=True)
    return Prediction(y, sigma_parameters, np.full(len(y), float(noise)), "given", block.data.log)


# How an observation's error is estimated from a fit's residuals (:func:`residual_noise`).
NOISE_ESTIMATORS = ("rms", "central68")
# The fraction of a normal distribution within 1 sigma of its mean.
ONE_SIGMA = 0.6826894921370859


@float64
def residual_noise(observations: Sequence[ValueObservation], result: FitResult, estimator: str = "rms") -> float:
    """The observations' error estimated from a fit's own residuals r (model - data in their
    residual space, unscaled) at its values, n values, p free parameters: ``"rms"``,
    sqrt(sum r^2 / (n - p)); ``"central68"``, the half-width of the central 68.27 % of ``abs(r)`` (the
    ``ONE_SIGMA`` quantile of ``abs(r)``, times sqrt(n / (n - p))), which equals the rms for normal
    residuals and, for heavy-tailed ones, gives 1-sigma intervals that hold 68 % of them where
    the rms's hold more.

    Raises:
        InputError: an unknown ``estimator``; no more values than free parameters.

    Args:
        observations: the fit's value observations, in its order.
        result: the fit's result.
        estimator: ``"rms"`` or ``"central68"``.

    Returns:
        The error in the observations' residual space (relative, for magnitudes' ln irradiance).

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> result = sf.fit([plates], ["parts.panel.kd"])
        >>> round(sf.residual_noise([plates], result), 3)
        0.093
    """
    check_type("result", result, FitResult, "an sf.FitResult")
    check_choice("estimator", estimator, NOISE_ESTIMATORS)
    x = jnp.asarray([result.values[n] for n in result.names])
    residuals = []
    for obs in observations:
        check_type("observations[]", obs, ValueObservation, "a value observation (sf.PlateLightCurve, ...)")
        block = obs.block(tuple(result.names))
        y = np.asarray(block.model(x, 0))
        residuals.append(np.log(y / block.data.value) if block.data.log else y - block.data.value)
    r = np.concatenate(residuals) if residuals else np.zeros(0)
    n, p = len(r), len(result.names)
    if n <= p:
        raise InputError(f"the fit has {n} values for {p} free parameters: no degrees of freedom to estimate the noise.")
    if estimator == "rms":
        return float(np.sqrt(np.sum(r**2) / (n - p)))
    return float(np.quantile(np.abs(r), ONE_SIGMA) * np.sqrt(n / (n - p)))
