"""The light curve of a target made of flat plates, and fits of the plates' materials to observed magnitudes.

Each plate (:class:`Plate`) has an area, a normal and a tangent in the target's frame, and a
spacefit material. The irradiance at an observer at distance d is

    E = E_sun / d^2 sum_k A_k f_k(wi, wo) |n_k . wi| |n_k . wo|,

f_k the plate's BRDF (:func:`spacefit.materials.brdf.brdf`, Mitsuba's evaluation, both sides
alike as the renderer's ``twosided``, 0 where sun and observer are on opposite sides; a measured
table's too, :class:`TabulatedBRDF`), wi and wo the
directions towards the sun and the observer: the renderer's integrated irradiance of the same
plates for a point target (no plate shadowing or lighting another, one bounce; the test renders
the two-plate satellite and compares). A target in the Earth's shadow is dark.

Observed magnitudes of such a target are an observation (:class:`PlateLightCurve`) that
:func:`fit` fits, alone or jointly with images of the same parts: its parameters are the
registered ones of the plates' materials (``parts.array.kd``, ``parts.chassis.alpha`` for both
roughnesses, ``parts.array.scale`` a table's factor) and the target's attitude angles;
:func:`fit_plates` is the convenience that fits it alone.

Given an :class:`Earth`, the irradiance is the sun's plus Earthshine's:
the same plates lit by the sunlit Earth (:func:`earthshine_sources`
once per set of observations, from their ``earth_m``, the sphere at the observing geometry's radius
:data:`~spacefit.studies.orbit.EARTH_RADIUS_M`; :func:`earthshine_irradiance`
with the plates' BRDF at the fitted values and attitude). Without one the model is the sun's alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import (InputError, check_choice, check_count, check_direction, check_name_list, check_range, check_type, check_vector,
                             quote)
from spacefit.geometry.attitude import SunTracking, tracking_rotation
from spacefit.fitting.loop import fit
from spacefit.fitting.result import FitResult
from spacefit.fitting.observations.base import Block, MeasuredValues
from spacefit.fitting.params import Bijection, bijection
from spacefit.geometry.frames import attitude_matrix
from spacefit.materials import Material, MaterialModel
from spacefit.materials.brdf import brdf
from spacefit.materials.registry import with_material_values
from spacefit.precision import float64
from spacefit.studies.earthshine import EARTH_MEAN_RADIUS_M, Earth, EarthshineSources, earthshine_irradiance, earthshine_sources
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.lightcurve_kind import LightCurveKind
from spacefit.studies.observing import LN_PER_MAGNITUDE, LightCurveObservations, irradiance_of, magnitude_of
from spacefit.studies.orbit import EARTH_RADIUS_M


@dataclass(frozen=True)
class Plate:
    """A flat plate: ``area_m2``, unit ``normal`` and ``tangent`` (the direction of a conductor's
    ``alpha_x``; made normal to ``normal``) in the target's frame, and its material. ``two_sided``:
    lit and seen from both sides (a thin sheet), or, False, from the side its normal points to only
    (a face of a closed part, whose back is inside it). Plates of one name are one part's: they share
    its material and its parameters (``parts.<name>.<field>``). A plate with a ``tracking_axis``
    (target frame) is (a face of) a sun-tracking part: for each observation its normal and tangent are
    turned about that axis by the turn that makes the part's ``tracking_normal`` (default: the plate's
    own normal) face the sun as closely as the turn allows
    (as :class:`SunTracking` turns a part; unturned with the sun along the axis).

    Raises:
        InputError: a non-positive area, a zero normal or tangent, a material without a finite BRDF.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> plate = sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))
        >>> plate.area_m2, plate.normal
        (10.0, (0.0, 0.0, 1.0))
    """

    name: str
    area_m2: float
    normal: tuple[float, float, float]
    material: Material
    tangent: tuple[float, float, float] = (1.0, 0.0, 0.0)
    two_sided: bool = True
    tracking_axis: tuple[float, float, float] | None = None
    tracking_normal: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        check_type("name", self.name, str, "a string")
        check_type(f"{self.name}.two_sided", self.two_sided, bool, "True or False")
        what = ("an sf.Lambert, sf.Conductor, sf.DiffuseConductor, sf.OrenNayar (a material model with a BRDF) or sf.TabulatedBRDF "
                "(a Mirror's BRDF is a delta function: never lit towards an observer by a point sun)")
        check_type(f"{self.name}.material", self.material, MaterialModel, what)
        if isinstance(self.material, MaterialModel) and self.material.delta:
            raise InputError(f"`{self.name}.material` must be {what}, got {self.material!r}.")
        check_range(f"{self.name}.area_m2", self.area_m2, 0.0, lo_open=True, unit="m^2")
        n = check_vector(f"{self.name}.normal", self.normal)
        if np.linalg.norm(n) == 0:
            raise InputError(f"`{self.name}.normal` must not be (0, 0, 0).")
        n = n / np.linalg.norm(n)
        t = check_vector(f"{self.name}.tangent", self.tangent)
        t = t - np.dot(t, n) * n
        if np.linalg.norm(t) < 1e-6:
            raise InputError(f"`{self.name}.tangent` must not be parallel to its normal {tuple(n)}.")
        object.__setattr__(self, "normal", tuple(n.tolist()))
        object.__setattr__(self, "tangent", tuple((t / np.linalg.norm(t)).tolist()))
        if self.tracking_normal is not None and self.tracking_axis is None:
            raise InputError(f"`{self.name}.tracking_normal` is given without a `tracking_axis` to turn about.")
        if self.tracking_axis is not None:
            tracking = SunTracking(check_direction(f"{self.name}.tracking_axis", self.tracking_axis))
            own = self.tracking_normal is None
            tracked = n if own else check_direction(f"{self.name}.tracking_normal", self.tracking_normal)
            tracking.check_normal(tracked, f"`{self.name}.{'normal' if own else 'tracking_normal'}`", f"{self.name}.tracking_axis")
            object.__setattr__(self, "tracking_axis", tracking.axis)
            object.__setattr__(self, "tracking_normal", tuple(tracked.tolist()))

    def frame(self) -> np.ndarray:
        """(3, 3) rows: tangent, bitangent, normal (the plate's local frame in the target's), unturned."""
        n, t = np.array(self.normal), np.array(self.tangent)
        return np.stack([t, np.cross(n, t), n])

    def frames(self, sun: jax.Array) -> jax.Array:
        """(n, 3, 3) the plate's frame (:meth:`frame`) for each of the (n, 3) unit directions ``sun``
        towards the sun (target frame): turned to track it with a ``tracking_axis``, else repeated.
        Differentiable in ``sun`` (JAX)."""
        frame = jnp.asarray(self.frame())
        if self.tracking_axis is None:
            return jnp.broadcast_to(frame, (len(sun), 3, 3))
        turn = tracking_rotation(jnp.asarray(self.tracking_axis), jnp.asarray(self.tracking_normal), jnp.asarray(sun), xp=jnp)
        return jnp.einsum("kj,nij->nki", frame, turn)  # each row r of the frame turned: R r


def _grey(plate: Plate, name: str) -> float:
    value = getattr(plate.material, name)
    if isinstance(value, tuple):
        raise InputError(f"`{plate.name}.{name}` is an RGB value {value}; a light-curve fit varies grey values only.")
    return float(value)


def _fields(material: Material) -> tuple[str, ...]:
    """The names a plate's material may free: its model's fields and ties (a measured table's ``scale``)."""
    return (*(f.name for f in material.fields), *material.ties)


# The target's attitude angles a fit may free ("target.attitude_x_deg").
TARGET = "target"
ATTITUDE = ("attitude_x_deg", "attitude_y_deg", "attitude_z_deg")


def _plate_brdf(plate: Plate, wi: jax.Array, wo: jax.Array, values: Mapping[str, jax.Array]) -> jax.Array:
    """The plate's BRDF with some of its material's values replaced (by field name; JAX-traceable)."""
    return brdf(plate.material, wi, wo, values)


@float64
def plates_irradiance(plates: Sequence[Plate], sun: np.ndarray, observer: np.ndarray, range_m: np.ndarray,
                      sun_irradiance_w_m2: float, values: Mapping[str, Mapping[str, jax.Array]] | None = None, *,
                      tracking_sun: np.ndarray | None = None) -> jax.Array:
    """Irradiance at the observer (W m^-2) of the plates lit by the sun (module docstring); ``sun``,
    ``observer`` (n, 3) unit directions from the target in its frame, ``range_m`` (n,). ``values``:
    per plate name, material values replacing the plate's own (a fit's). ``tracking_sun`` (n, 3): the
    directions towards the sun that sun-tracking plates turn to (:meth:`Plate.frames`), where the light
    ``sun`` comes from elsewhere (Earthshine); ``sun`` itself by default."""
    total = jnp.zeros(len(range_m))
    for plate in plates:
        if plate.tracking_axis is None:
            frame = jnp.asarray(plate.frame())
            wi, wo = jnp.asarray(sun) @ frame.T, jnp.asarray(observer) @ frame.T
        else:
            frames = plate.frames(jnp.asarray(sun if tracking_sun is None else tracking_sun))
            wi, wo = jnp.einsum("nij,nj->ni", frames, jnp.asarray(sun)), jnp.einsum("nij,nj->ni", frames, jnp.asarray(observer))
        f = _plate_brdf(plate, wi, wo, (values or {}).get(plate.name, {}))
        lit = jnp.abs(wi[:, 2]) if plate.two_sided else jnp.maximum(wi[:, 2], 0.0)  # f is 0 where wo is on the other side
        total = total + plate.area_m2 * f * lit * jnp.abs(wo[:, 2])
    return sun_irradiance_w_m2 * total / jnp.asarray(range_m) ** 2


@float64
def predict_magnitudes(plates: Sequence[Plate], observations: LightCurveObservations, sun_irradiance_w_m2: float = 1360.0, *,
                       earth: Earth | None = None, shares: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The plates' magnitudes in the observations' band at their geometry (inf in the Earth's shadow or
    unlit), lit by the sun and, given an ``earth``, by Earthshine (the guide "BRDF tables and light curves as observations"). With ``shares``
    also each magnitude's Earthshine share of the irradiance, E_earthshine / (E_sun + E_earthshine)
    (nan where dark).

    Raises:
        InputError: an ``earth`` for observations without the Earth's position (``earth_m`` None).

    Args:
        plates: the target's plates.
        observations: the geometry (and band) to predict at.
        sun_irradiance_w_m2: the sun's irradiance at the target (W m^-2).
        earth: the Earth for Earthshine, or None.
        shares: also return the Earthshine shares.

    Returns:
        (n,) magnitudes, and with ``shares`` the (n,) shares.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=None, source="example")
        >>> plate = sf.Plate("panel", area_m2=10.0, normal=(0, 0, 1), material=sf.Lambert(kd=0.3))
        >>> np.round(sf.predict_magnitudes([plate], curve), 2)
        array([3.38, 3.6 , 4.06])
    """
    plates = _check_plates(plates)
    _check_observations(observations)
    check_range("sun_irradiance_w_m2", sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
    check_type("shares", shares, bool, "True or False")
    sources = _sources(earth, observations)
    direct, earthshine = (np.asarray(e) for e in _light(plates, observations, sun_irradiance_w_m2, {}, sources))
    total = np.where(observations.in_shadow, 0.0, direct if sources is None else direct + earthshine)
    magnitudes = magnitude_of(total, observations.band, sun_irradiance_w_m2)
    if not shares:
        return magnitudes
    with np.errstate(divide="ignore", invalid="ignore"):
        return magnitudes, np.where(total > 0, np.where(observations.in_shadow, 0.0, earthshine) / total, np.nan)


def _sources(earth: Earth | None, observations: LightCurveObservations) -> EarthshineSources | None:
    """The lit Earth seen from the observations' targets (None without an ``earth``), the sphere at
    the observing geometry's radius :data:`~spacefit.studies.orbit.EARTH_RADIUS_M`."""
    checked = _check_earth(earth, observations)
    if checked is None or observations.earth_m is None:
        return None
    return earthshine_sources(observations.earth_m, observations.sun, dataclasses.replace(checked, radius_m=EARTH_RADIUS_M))


def _check_earth(earth: object, observations: LightCurveObservations) -> Earth | None:
    """``earth``: None, or an :class:`Earth` of the default radius for observations that carry ``earth_m``."""
    check_type("earth", earth, (Earth, type(None)), "an sf.Earth or None")
    if earth is None:
        return None
    if earth.radius_m not in (EARTH_MEAN_RADIUS_M, EARTH_RADIUS_M):
        raise InputError(f"`earth.radius_m` is {earth.radius_m:g} m, but the observations' geometry puts the Earth's surface at "
                         f"{EARTH_RADIUS_M:g} m: leave it at its default (Earthshine takes the geometry's radius).")
    if observations.earth_m is None:
        raise InputError(f"light curve {observations.source} has no Earth position (`earth_m` is None), which Earthshine needs: "
                         "read it from a site's altitude, azimuth and height, a SCORE file or an `orbit`, give the columns "
                         "earth_x, earth_y, earth_z, or pass earth=None.")
    return earth


def _light(plates: Sequence[Plate], observations: LightCurveObservations, sun_irradiance_w_m2: float,
           values: Mapping[str, Mapping[str, jax.Array]], sources: EarthshineSources | None) -> tuple[jax.Array, jax.Array]:
    """The sun's and Earthshine's irradiance at the observers (W m^-2; Earthshine 0 without ``sources``),
    the plates at ``values`` (per plate name; ``target``'s attitude angles turn them; JAX-traceable)."""
    sun, observer = jnp.asarray(observations.sun), jnp.asarray(observations.observer)
    turn = None
    if TARGET in values:
        turn = _rotation([values[TARGET].get(a, 0.0) for a in ATTITUDE])
        sun, observer = sun @ turn, observer @ turn
    direct = plates_irradiance(plates, sun, observer, observations.range_m, sun_irradiance_w_m2, values)
    if sources is None:
        return direct, jnp.zeros_like(direct)

    # The observation of each Earthshine direction reflect() is given: earthshine_irradiance passes the
    # sources' nodes that carry light in np.nonzero's order.
    rows = np.nonzero(sources.weights > 0)[0]

    def reflect(wi: jax.Array, wo: jax.Array) -> jax.Array:
        if turn is not None:
            wi, wo = wi @ turn, wo @ turn
        return plates_irradiance(plates, wi, wo, jnp.ones(len(wi)), 1.0, values, tracking_sun=sun[rows])

    return direct, earthshine_irradiance(reflect, sources, observations.observer, observations.range_m, sun_irradiance_w_m2)


def _check_plates(plates: object) -> list[Plate]:
    """``plates`` as a list: one or more :class:`Plate`, those of one name (one part's) of one material."""
    if isinstance(plates, (str, bytes)) or not isinstance(plates, Sequence) or not plates:
        raise InputError(f"`plates` must be a list of one or more sf.Plate, got {quote(plates)}.")
    for i, p in enumerate(plates):
        check_type(f"plates[{i}]", p, Plate, "an sf.Plate")
    names = [p.name for p in plates]
    if TARGET in names:
        raise InputError(f"`plates` must not have a plate named {TARGET!r}: the name is the target's attitude's in `free`.")
    material = {}
    for p in plates:
        if material.setdefault(p.name, p.material) != p.material:
            raise InputError(f"`plates` named {p.name!r} must share one material (they are one part's), got "
                             f"{material[p.name]!r} and {p.material!r}; give plates of different materials distinct names.")
    return list(plates)


def _check_observations(observations: object) -> None:
    check_type("observations", observations, LightCurveObservations, "an sf.LightCurveObservations (sf.read_light_curve)")


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


def _rotation(angles_deg: Sequence[jax.Array | float]) -> jax.Array:
    """The target's rotation (object to the observations' frame) of its three attitude angles (deg),
    :func:`spacefit.geometry.frames.attitude_matrix` as the scenes' ``target.attitude_deg``."""
    return attitude_matrix(jnp.radians(jnp.stack([jnp.asarray(a, dtype=float) for a in angles_deg])), xp=jnp)


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
        object.__setattr__(self, "plates", tuple(_check_plates(self.plates)))
        _check_observations(self.observations)
        check_range("sun_irradiance_w_m2", self.sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
        if not (~self.observations.in_shadow).any():
            raise InputError(f"every observation of {self.observations.source} is in the Earth's shadow: there is nothing to fit.")
        _check_earth(self.earth, self.observations)
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
        sources = _sources(self.earth, obs)

        @jax.jit
        def predict(x: jax.Array) -> jax.Array:
            direct, earthshine = self._light(obs, dict(zip(known, (x[free.index(n)] for n in known))), sources)
            return direct if sources is None else direct + earthshine

        return Block(measured, lambda x, j: predict(x), known)

    def _light(self, obs: LightCurveObservations, named: Mapping[str, jax.Array | float],
               sources: EarthshineSources | None) -> tuple[jax.Array, jax.Array]:
        """The sun's and Earthshine's irradiance of ``obs`` with the parameters ``named`` set (:func:`_light`)."""
        material = {p.name: p.material for p in self.plates}
        values: dict[str, dict[str, jax.Array | float]] = {}
        for name, value in named.items():
            plate, field_name = _split(name)
            for f in (field_name,) if plate == TARGET else _tied(material[plate], field_name):
                values.setdefault(plate, {})[f] = value
        return _light(self.plates, obs, self.sun_irradiance_w_m2, values, sources)

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """Its goodness of fit, and whether Earthshine was included, with its share of the fitted
        irradiances at the fitted values (median and largest)."""
        if self.earth is None:
            return [*super().report(result, entries), "    Earthshine: not included"]
        obs = self.observations.subset(~self.observations.in_shadow)
        named = {n: v for n, v in result.values.items() if n in self.parameters()}
        direct, earthshine = (np.asarray(e) for e in self._light(obs, named, _sources(self.earth, obs)))
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
    plates = _check_plates(plates)
    check_type("fit", fit, FitResult, "an sf.FitResult (of sf.fit_plates)")
    for name in fit.names:
        check_choice("fit.names", name, plate_parameters(plates))
    angles = {_split(name)[1]: float(v) for name, v in fit.values.items() if name.startswith(TARGET + ".")}
    if angles:
        turn = np.asarray(_rotation([angles.get(a, 0.0) for a in ATTITUDE]))
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
