"""Fit a design, not a satellite: light curves of several satellites (or nights) of one design fitted
jointly, their materials shared and some nuisances each one's own, and predictive intervals for new
observations.

Each light curve is a member (:class:`DesignMember`) of the design: member k sees the shared free
values and its own values of the per-member parameters, named as every per-observation value is,
``target.attitude_x_deg@k`` (:class:`~spacefit.scene.names.Name`; k counts the light curves in
the order given). Besides the light curve's own parameters a member has the exposure scale
``image.scale`` (:data:`~spacefit.scene.parameters.IMAGE`, default 1): its model's irradiance times
it, a magnitude offset of -2.5 log10(scale), as a night's calibration or a satellite's unknown
brightening would be.

A prediction for new observations (:func:`predict_design`) has the member's own values, or, for a
member the fit has not seen (a new night, a new satellite), the members' mean with their spread
added to the parameters' covariance: the spread s^2 of the fitted members' values about their mean
plus the mean's own variance, so that a per-member nuisance widens the interval of an unseen member
as much as it varied between the seen ones. The interval is
:func:`predictive_intervals`'s, the observation's error with the parameters'
errors, in magnitudes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

from spacefit.errors import InputError, check_count, check_name_list, check_type
from spacefit.fitting.loop import fit
from spacefit.fitting.observations.base import Block, ValueObservation
from spacefit.fitting.params import Bijection, bijection
from spacefit.fitting.prediction import Prediction, covariance_of, predictive_intervals, residual_noise
from spacefit.fitting.result import FitResult
from spacefit.scene.names import Name
from spacefit.studies.lightcurve_observations import LN_PER_MAGNITUDE, LightCurveObservations
from spacefit.studies.plate_fit import PlateLightCurve

# A member's exposure scale: its model's irradiance times it (default 1).
SCALE = "image.scale"


@dataclass(frozen=True, eq=False)
class DesignMember(ValueObservation):
    """One light curve of a design fit: ``curve``'s parameters, shared, except ``own`` (registered
    names, ``target.attitude_x_deg``, :data:`SCALE`), which are member ``index``'s alone
    (``target.attitude_x_deg@<index>``); :data:`SCALE` scales its irradiance (the guide "BRDF tables and light curves as observations").

    Attributes:
        curve: the member's light curve (its plates, observations, sun, bounds, Earth).
        index: the member's number, k of its own names' ``@k``.
        own: the parameters that are the member's own.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> sf.DesignMember(plates, 1, ("target.attitude_x_deg",)).own
        ('target.attitude_x_deg',)
    """

    curve: PlateLightCurve
    index: int
    own: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        check_type("curve", self.curve, PlateLightCurve, "an sf.PlateLightCurve")
        check_count("index", self.index, lo=0, optional=False)
        own = check_name_list("own", self.own) if self.own else ()
        valid = (*self.curve.parameters(), SCALE)
        for name in own:
            if name not in valid:
                raise InputError(f"`own` names {name!r}, not a parameter of the light curve; valid: {', '.join(valid)}.")
        object.__setattr__(self, "own", tuple(own))

    def parameters(self) -> tuple[str, ...]:
        """The curve's parameters and :data:`SCALE`, each of :attr:`own` as this member's (``@index``)."""
        return tuple(Name(n, self.index) if n in self.own else n for n in (*self.curve.parameters(), SCALE))

    def start(self, name: str) -> float:
        """The curve's own value (1 for :data:`SCALE`)."""
        base = Name(name).parameter
        return 1.0 if base == SCALE else self.curve.start(base)

    def coordinate(self, name: str) -> Bijection:
        """The curve's range of the parameter (its bounds), or the registered one."""
        base = Name(name).parameter
        return self.curve.coordinate(base) if base in self.curve.parameters() else bijection(base)

    def block(self, free: tuple[str, ...]) -> Block:
        """The curve's block with this member's own values in place of the parameters, times :data:`SCALE`."""
        mine = set(self.parameters())
        inner = tuple(Name(n).parameter if n in mine else n for n in free)
        if len(set(inner)) != len(inner):
            raise InputError(f"`free` names a parameter both shared and member {self.index}'s own: {list(free)}.")
        block = self.curve.block(inner)
        at = {n: i for i, n in enumerate(inner)}
        scale = at.get(SCALE) if SCALE in at and free[at[SCALE]] in mine else None

        def model(x: jax.Array, j: int) -> jax.Array:
            y = block.model(x, j)
            return y if scale is None else y * x[scale]

        known = tuple(free[at[n]] for n in block.known) + (() if scale is None else (free[scale],))
        return Block(block.data, model, known, block.rendered)

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """The curve's: the solar phase angle."""
        return self.curve.abscissa(count)

    def shown(self, values: np.ndarray, unit: str) -> tuple[np.ndarray, str, str]:
        """The curve's: magnitudes."""
        return self.curve.shown(values, unit)


def design_names(free: Sequence[str], own: Sequence[str], members: int) -> list[str]:
    """A design fit's free names: the shared ``free`` and each of the ``own`` names once per member
    (``target.attitude_x_deg@0``, ``@1``, ...)."""
    return [*free, *(Name(n, k) for k in range(members) for n in own)]


def fit_design(curves: Sequence[PlateLightCurve], free: Sequence[str], own: Sequence[str] = (), **options: Any) -> FitResult:
    """Fit light curves of one design jointly with :func:`fit`: the ``free`` values shared
    by every curve and the ``own`` ones each curve's (``<name>@k``, k the curve's place in
    ``curves``; :class:`DesignMember`). ``options``: :func:`fit`'s keywords.

    Raises:
        InputError: no curve; a name both shared and own; an unknown name (listing the valid ones).

    Args:
        curves: the members' light curves (:class:`PlateLightCurve`), one design.
        free: the shared parameters.
        own: the parameters each member has its own value of.
        options: :func:`fit`'s keywords (``max_steps``, ``solver``, ...).

    Returns:
        The :class:`FitResult`; a member's own values are named ``<name>@k``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> result = sf.fit_design([plates, plates], ["parts.panel.kd"])
        >>> result.names, result.status.value
        (('parts.panel.kd',), 'converged')
    """
    members = design_members(curves, own)
    shared = check_name_list("free", free) if free else ()
    both = set(shared) & set(members[0].own)
    if both:
        raise InputError(f"`free` and `own` both name {sorted(both)}: a parameter is shared or each member's own, not both.")
    return fit(members, design_names(shared, members[0].own, len(members)), **options)


def design_members(curves: Sequence[PlateLightCurve], own: Sequence[str] = ()) -> list[DesignMember]:
    """The curves as the members of a design fit (:class:`DesignMember`), member k ``curves[k]``."""
    if isinstance(curves, (str, bytes, PlateLightCurve)) or not isinstance(curves, Sequence) or not curves:
        raise InputError(f"`curves` must be a list of one or more sf.PlateLightCurve, got {type(curves).__name__}.")
    return [DesignMember(c, k, tuple(own)) for k, c in enumerate(curves)]


@dataclass(frozen=True)
class MagnitudePrediction:
    """Predicted magnitudes of observations outside the Earth's shadow with their predictive errors.

    Attributes:
        rows: (n,) the observations' rows predicted (those outside the Earth's shadow).
        magnitude: (n,) the predicted magnitudes.
        sigma: (n,) their predictive standard errors (mag).
        sigma_parameters, sigma_noise: (n,) the parameters' and the observations' shares (mag).
        noise: where the observations' error came from: ``"stated"`` or ``"training residuals"``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> prediction = sf.predict_design(sf.fit_design([plates, plates], ["parts.panel.kd"]), plates, curve, members=2)
        >>> bool((prediction.sigma >= prediction.sigma_noise).all())  # the parameters' share adds
        True
    """

    rows: np.ndarray
    magnitude: np.ndarray
    sigma: np.ndarray
    sigma_parameters: np.ndarray
    sigma_noise: np.ndarray
    noise: str

    def coverage(self, observed: np.ndarray, k: float = 1.0) -> float:
        """The fraction of the ``observed`` magnitudes of these rows within ``k`` predictive errors."""
        observed = np.asarray(observed, dtype=float)
        if observed.shape != self.magnitude.shape:
            raise InputError(f"`observed` must have the prediction's shape {self.magnitude.shape}, got {observed.shape}.")
        return float(np.mean(np.abs(observed - self.magnitude) <= k * self.sigma))


def _unseen(result: FitResult, own: Sequence[str], members: int, index: int) -> tuple[list[str], dict[str, float], np.ndarray]:
    """The fit's names, values and covariance with a new member ``index``'s own values added: the seen
    members' mean, their spread about it plus the mean's variance (module docstring)."""
    names, values, cov = list(result.names), dict(result.values), covariance_of(result)
    for name in own:
        seen = [names.index(Name(name, k)) for k in range(members)]
        v = np.array([values[names[i]] for i in seen])
        weights = np.full(len(seen), 1.0 / len(seen))
        spread = float(np.var(v, ddof=1)) if len(seen) > 1 else 0.0
        row = cov[seen].T @ weights
        new = Name(name, index)
        names.append(new)
        values[new] = float(v.mean())
        cov = np.block([[cov, row[:, None]], [row[None, :], np.array([[weights @ cov[np.ix_(seen, seen)] @ weights + spread]])]])
    return names, values, cov


def predict_design(result: FitResult, curve: PlateLightCurve, observations: LightCurveObservations, *, member: int | None = None,
                   own: Sequence[str] = (), members: int | None = None, noise_mag: float | None = None) -> MagnitudePrediction:
    """Predicted magnitudes of ``observations`` (outside the Earth's shadow) by a design fit's result
    (:func:`fit_design` of ``members`` curves with per-member ``own`` names) for the design of
    ``curve`` (its plates, sun, Earth; its observations replaced), with their predictive errors
    (the guide "BRDF tables and light curves as observations"): as ``member``'s, or (None) as a member the fit has not seen. ``noise_mag``:
    the observations' error (mag) where they state none, e.g. :func:`design_noise_mag` of the fit.

    Raises:
        InputError: ``member`` out of range; ``own`` names not the fit's; no ``noise_mag`` for
            observations without stated errors.

    Args:
        result: the :func:`fit_design` result.
        curve: a light curve of the design (its plates, sun and Earth).
        observations: the geometry to predict at.
        member: the member predicted as, or None for an unseen one.
        own: the fit's own names.
        members: the number of members the fit had.
        noise_mag: the observations' error (mag) where they state none.

    Returns:
        A :class:`MagnitudePrediction`.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> result = sf.fit_design([plates, plates], ["parts.panel.kd"])
        >>> prediction = sf.predict_design(result, plates, curve, members=2)
        >>> prediction.noise, prediction.magnitude.shape
        ('stated', (3,))
    """
    check_type("result", result, FitResult, "an sf.FitResult (of sf.fit_design)")
    check_type("curve", curve, PlateLightCurve, "an sf.PlateLightCurve")
    own = tuple(own)
    check_count("members", members)
    if members is None and own:
        raise InputError("`members` must be the design fit's number of curves when it has `own` names.")
    count = members or 1
    for k in range(count):
        for name in own:
            if Name(name, k) not in result.names:
                raise InputError(f"`own` names {name!r}, but the fit has no {Name(name, k)!r}; its names: {', '.join(result.names)}.")
    if member is not None:
        check_count("member", member, lo=0)
        if member >= count:
            raise InputError(f"`member` must be from 0 to {count - 1} (the fit's members), or None for an unseen one; got {member}.")
    index = count if member is None else member
    names, values, cov = (_unseen(result, own, count, index) if member is None and own
                          else (list(result.names), dict(result.values), covariance_of(result)))
    new = DesignMember(dataclasses.replace(curve, observations=observations), index, own)
    noise = None if noise_mag is None else LN_PER_MAGNITUDE * noise_mag
    p: Prediction = predictive_intervals(new, names, values, cov, noise=noise)
    sun_magnitude, sun_irradiance = curve.zero_point()
    magnitude = sun_magnitude - (p.value - np.log(sun_irradiance)) / LN_PER_MAGNITUDE
    return MagnitudePrediction(np.flatnonzero(~observations.in_shadow), magnitude, p.sigma / LN_PER_MAGNITUDE,
                               p.sigma_parameters / LN_PER_MAGNITUDE, p.sigma_noise / LN_PER_MAGNITUDE,
                               "stated" if p.noise == "stated" else "training residuals")


def design_noise_mag(result: FitResult, curves: Sequence[PlateLightCurve], own: Sequence[str] = (), estimator: str = "rms") -> float:
    """The observations' error (mag) estimated from a design fit's residuals over its degrees of
    freedom (:func:`residual_noise`: ``"rms"`` or ``"central68"``).

    Args:
        result: the :func:`fit_design` result.
        curves: its light curves, in the fit's order.
        own: the fit's own names.
        estimator: ``"rms"`` or ``"central68"``.

    Returns:
        The error (mag).

    Raises:
        InputError: an unknown ``estimator``, no more values than free parameters.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> result = sf.fit_design([plates, plates], ["parts.panel.kd"])
        >>> round(sf.design_noise_mag(result, [plates, plates]), 3)
        0.09
    """
    return residual_noise(design_members(curves, own), result, estimator) / LN_PER_MAGNITUDE
