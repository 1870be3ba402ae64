"""Fits of a flat-plate target's materials and attitude to observed magnitudes.

Observed magnitudes of a target of plates (:mod:`spacefit.studies.plates`) are an observation
(:class:`PlateLightCurve`) that :func:`fit` fits, alone or jointly with images of the same parts:
its parameters are the registered ones of the plates' materials (``parts.array.kd``,
``parts.chassis.alpha`` for both roughnesses, ``parts.array.scale`` a table's factor) and the
target's attitude angles; :func:`fit_plates` is the convenience that fits it alone, and
:func:`fitted_plates` the plates at its values.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import jax
import numpy as np

from spacefit.errors import InputError, check_choice, check_count, check_name_list, check_range, check_type, quote
from spacefit.fitting.loop import fit
from spacefit.fitting.observations.base import Block, MeasuredValues
from spacefit.fitting.params import Bijection, bijection
from spacefit.fitting.result import FitResult
from spacefit.materials import Material
from spacefit.materials.registry import with_material_values
from spacefit.studies.earthshine import Earth, EarthshineSources
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.lightcurve_kind import LightCurveKind
from spacefit.studies.lightcurve_observations import LN_PER_MAGNITUDE, LightCurveObservations, irradiance_of
from spacefit.studies.plates import (ATTITUDE, TARGET, Plate, check_earth, check_observations, check_plates, earthshine_of, plates_light,
                                     target_rotation)


def _grey(plate: Plate, name: str) -> float:
    value = getattr(plate.material, name)
    if isinstance(value, tuple):
        raise InputError(f"`{plate.name}.{name}` is an RGB value {value}; a light-curve fit varies grey values only.")
    return float(value)


def _fields(material: Material) -> tuple[str, ...]:
    """The names a plate's material may free: its model's fields and ties (a measured table's ``scale``)."""
    return (*(f.name for f in material.fields), *material.ties)


def _tied(material: Material, field: str) -> tuple[str, ...]:
    """The fields a free name sets: a tie's (``alpha``: both roughnesses), else itself."""
    ties = material.ties
    return ties[field][0] if field in ties else (field,)


def _split(name: str) -> tuple[str, str]:
    """The plate (or ``target``) and the field of a parameter name ``parts.<plate>.<field>`` (``target.<angle>``)."""
    if name.startswith(TARGET + "."):
        return TARGET, name.partition(".")[2]
    _, plate, field_name = name.split(".")
    return plate, field_name


def plate_parameters(plates: Sequence[Plate]) -> tuple[str, ...]:
    """The registered names of the plates' material values (``parts.<plate>.<field>``, ``alpha`` for
    both roughnesses) and of the target's attitude angles."""
    out: dict[str, None] = {}
    for plate in plates:
        out |= dict.fromkeys(f"parts.{plate.name}.{f}" for f in _fields(plate.material))
    return (*out, *(f"{TARGET}.{a}" for a in ATTITUDE))


@dataclass(frozen=True, eq=False)
class PlateLightCurve(LightCurveKind):
    """Observed magnitudes of a target of flat plates, the light-curve kind of observation :func:`fit` fits whose model is :func:`plates_irradiance`.

    Its parameters are the registered ones of each plate's material, ``parts.<plate>.<field>``
    (``alpha`` for both roughnesses; a :class:`TabulatedBRDF`'s
    ``scale``), and the target's attitude angles ``target.attitude_x_deg`` (``_y_``, ``_z_``: a
    rotation of all the plates from their given normals, at 0 unless free, as ``target.attitude_deg``). The residual is the magnitude's,
    (m_model - m_obs) / sigma_m, as ln(E_model / E_obs) / (0.4 ln 10 sigma_m); without stated
    errors the errors are scaled by the residuals. Observations in the Earth's shadow are left out.
    Given an ``earth``, the model adds Earthshine (the guide "BRDF tables and light curves as observations") and the report says its share.

    Attributes:
        plates: the target's plates (none named ``target``; those of one name share a material: one part's).
        observations: the measured magnitudes and their geometry.
        sun_irradiance_w_m2: the sun's irradiance at the target, W m^-2.
        bounds: narrower (low, high) ranges of some parameters (``{"parts.chassis.eta": (1.0, 100.0)}``:
            a dielectric's physical range) within their registered ones; the plates' values must lie inside.
        earth: the Earth lighting the target too (Earthshine; the observations must carry ``earth_m``), or None.

    Raises:
        InputError: a plate named ``target``, plates of one name with different materials, bounds
            outside the registered ranges or not holding the plates' values, an ``earth`` without the
            Earth's positions.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plates = sf.PlateLightCurve([sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))], curve)
        >>> plates.parameters()
        ('parts.panel.kd', 'target.attitude_x_deg', 'target.attitude_y_deg', 'target.attitude_z_deg')
        >>> sf.fit([plates], ["parts.panel.kd"]).status.value
        'converged'
    """

    plates: Sequence[Plate]
    observations: LightCurveObservations
    sun_irradiance_w_m2: float = 1360.0
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    earth: Earth | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "plates", tuple(check_plates(self.plates)))
        check_observations(self.observations)
        check_range("sun_irradiance_w_m2", self.sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
        if not (~self.observations.in_shadow).any():
            raise InputError(f"every observation of {self.observations.source} is in the Earth's shadow: there is nothing to fit.")
        check_earth(self.earth, self.observations)
        check_type("bounds", self.bounds, Mapping, "a dict of (low, high) ranges by parameter name")
        for name, given in self.bounds.items():
            check_choice("bounds", name, self.parameters())
            if not (isinstance(given, (tuple, list)) and len(given) == 2):
                raise InputError(f"`bounds[{name!r}]` must be a (low, high) pair, got {quote(given)}.")
            own = bijection(name)
            check_range(f"bounds[{name!r}][0]", given[0], own.lo, own.hi)
            check_range(f"bounds[{name!r}][1]", given[1], float(given[0]), own.hi, lo_open=True)
            if not given[0] < self.start(name) < given[1]:
                raise InputError(f"`{name}` starts at {self.start(name):g}, outside its bounds ({given[0]:g}, {given[1]:g}): "
                                 "give the plates a value inside.")

    def parameters(self) -> tuple[str, ...]:
        """Each plate's material values and the target's attitude angles (:func:`plate_parameters`)."""
        return plate_parameters(self.plates)

    def start(self, name: str) -> float:
        """The plate's own value (``alpha``: its ``alpha_x``), or 0 for an attitude angle."""
        plate, field_name = _split(name)
        if plate == TARGET:
            return 0.0
        of = next(p for p in self.plates if p.name == plate)
        return _grey(of, _tied(of.material, field_name)[0])

    def coordinate(self, name: str) -> Bijection:
        """The registered range of ``name``, or its narrower one in :attr:`bounds`."""
        return Bijection(*map(float, self.bounds[name])) if name in self.bounds else bijection(name)

    def block(self, free: tuple[str, ...]) -> Block:
        """ln E against the magnitudes' errors, outside the Earth's shadow (class docstring)."""
        obs = self.observations.subset(~self.observations.in_shadow)
        data = irradiance_of(obs.magnitude, obs.band, self.sun_irradiance_w_m2)
        sigma = None if obs.magnitude_sigma is None else LN_PER_MAGNITUDE * obs.magnitude_sigma
        measured = MeasuredValues(data, sigma, True, "W m^-2", f"light curve {obs.source}")
        known = tuple(n for n in free if n in self.parameters())
        sources = earthshine_of(self.earth, obs)

        @jax.jit
        def predict(x: jax.Array) -> jax.Array:
            direct, earthshine = self._light(obs, dict(zip(known, (x[free.index(n)] for n in known))), sources)
            return direct if sources is None else direct + earthshine

        return Block(measured, lambda x, j: predict(x), known)

    def _light(self, obs: LightCurveObservations, named: Mapping[str, jax.Array | float],
               sources: EarthshineSources | None) -> tuple[jax.Array, jax.Array]:
        """The sun's and Earthshine's irradiance of ``obs`` with the parameters ``named`` set (:func:`plates_light`)."""
        material = {p.name: p.material for p in self.plates}
        values: dict[str, dict[str, jax.Array | float]] = {}
        for name, value in named.items():
            plate, field_name = _split(name)
            for f in (field_name,) if plate == TARGET else _tied(material[plate], field_name):
                values.setdefault(plate, {})[f] = value
        return plates_light(self.plates, obs, self.sun_irradiance_w_m2, values, sources)

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """Its goodness of fit, and whether Earthshine was included, with its share of the fitted
        irradiances at the fitted values (median and largest)."""
        if self.earth is None:
            return [*super().report(result, entries), "    Earthshine: not included"]
        obs = self.observations.subset(~self.observations.in_shadow)
        named = {n: v for n, v in result.values.items() if n in self.parameters()}
        direct, earthshine = (np.asarray(e) for e in self._light(obs, named, earthshine_of(self.earth, obs)))
        share = 100.0 * earthshine / (direct + earthshine)
        return [*super().report(result, entries), f"    Earthshine: included ({self.earth.describe()}), share median "
                                                  f"{np.median(share):.3g} %, max {np.max(share):.3g} %"]

    def zero_point(self) -> tuple[float, float]:
        """The band's sun magnitude and :attr:`sun_irradiance_w_m2`."""
        return SUN_MAGNITUDES[self.observations.band], self.sun_irradiance_w_m2

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """The solar phase angle (between the sun and the observer) of each fitted magnitude, degrees."""
        obs = self.observations.subset(~self.observations.in_shadow)
        return np.degrees(np.arccos(np.clip(np.sum(obs.sun * obs.observer, axis=1), -1.0, 1.0))), "solar phase angle (deg)"


def fit_plates(plates: Sequence[Plate], observations: LightCurveObservations, free: Sequence[str], *,
               bounds: Mapping[str, tuple[float, float]] | None = None, sun_irradiance_w_m2: float = 1360.0,
               max_steps: int = 200, earth: Earth | None = None) -> FitResult:
    """Fit the plates' registered values ``free`` (``parts.<plate>.<field>``, ``target.attitude_z_deg``;
    :class:`PlateLightCurve`) to the observed magnitudes outside the Earth's shadow with
    :func:`fit`, from the plates' values. ``bounds`` narrows a free value's range within its
    registered one (:attr:`PlateLightCurve.bounds`); the start must lie inside. ``earth`` adds
    Earthshine to the model (:attr:`PlateLightCurve.earth`).

    Args:
        plates: the target's plates.
        observations: the observed magnitudes.
        free: parameter names (``parts.<plate>.<field>``, ``target.attitude_x_deg``, ...).
        bounds: narrower ranges by name.
        sun_irradiance_w_m2: the sun's irradiance at the target (W m^-2).
        max_steps: the solver's step limit.
        earth: the Earth for Earthshine, or None.

    Returns:
        The :class:`FitResult`.

    Raises:
        InputError: a name the plates cannot free, a start outside ``bounds``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plate = sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))
        >>> result = sf.fit_plates([plate], curve, ["parts.panel.kd"])
        >>> result.status.value, sf.fitted_plates([plate], result)[0].material.kd < 0.3  # fainter than predicted
        ('converged', True)
    """
    check_type("bounds", bounds, (Mapping, type(None)), "a dict of (low, high) ranges by free name, or None")
    names = list(check_name_list("free", free))
    for name in bounds or {}:
        check_choice("bounds", name, names)
    curve = PlateLightCurve(plates, observations, sun_irradiance_w_m2, dict(bounds or {}), earth)
    check_count("max_steps", max_steps, optional=False)
    return fit(curve, names, max_steps=max_steps)


def fitted_plates(plates: Sequence[Plate], fit: FitResult) -> list[Plate]:
    """The plates with a :func:`fit_plates` fit's values in their materials and, where it freed the
    attitude, their normals, tangents and tracking axes and normals turned by it.

    Args:
        plates: the plates the fit started from.
        fit: the :func:`fit_plates` result.

    Returns:
        New plates.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plate = sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))
        >>> fitted = sf.fitted_plates([plate], sf.fit_plates([plate], curve, ["parts.panel.kd"]))
        >>> type(fitted[0].material).__name__
        'Lambert'
    """
    plates = check_plates(plates)
    check_type("fit", fit, FitResult, "an sf.FitResult (of sf.fit_plates)")
    for name in fit.names:
        check_choice("fit.names", name, plate_parameters(plates))
    angles = {_split(name)[1]: float(v) for name, v in fit.values.items() if name.startswith(TARGET + ".")}
    if angles:
        turn = np.asarray(target_rotation([angles.get(a, 0.0) for a in ATTITUDE]))
        plates = [dataclasses.replace(p, normal=tuple(turn @ np.array(p.normal)), tangent=tuple(turn @ np.array(p.tangent)),
                                      **({} if p.tracking_axis is None else {"tracking_axis": tuple(turn @ np.array(p.tracking_axis)),
                                                                             "tracking_normal": tuple(turn @ np.array(p.tracking_normal))}))
                  for p in plates]
    out = []
    for plate in plates:
        values = {_split(name)[1]: float(v) for name, v in fit.values.items() if _split(name)[0] == plate.name}
        material = with_material_values(plate.material, values, where=plate.name) if values else plate.material
        out.append(dataclasses.replace(plate, material=material))
    return out
