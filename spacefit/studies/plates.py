"""The light curve of a target made of flat plates, and fits of the plates' materials to observed magnitudes.

Each plate (:class:`Plate`) has an area, a normal and a tangent in the target's frame, and a
spacefit material. The irradiance at an observer at distance d is

    E = E_sun / d^2 sum_k A_k f_k(wi, wo) |n_k . wi| |n_k . wo|,

f_k the plate's BRDF (:func:`spacefit.materials.brdf.brdf`, Mitsuba's evaluation, both sides
alike as the renderer's ``twosided``, 0 where sun and observer are on opposite sides; or a measured
table's, :class:`~spacefit.fitting.brdf_table.TabulatedBRDF`), wi and wo the
directions towards the sun and the observer: the renderer's integrated irradiance of the same
plates for a point target (no plate shadowing or lighting another, one bounce; the test renders
the two-plate satellite and compares). A target in the Earth's shadow is dark.

:func:`fit_plates` fits named values of the plates' materials (``"array.kd"``, ``"chassis.alpha"``
for both roughnesses, ``"array.scale"`` a table's factor) and, where freed, the target's attitude
angles to observed magnitudes with :func:`spacefit.fitting.tabular.fit_table`: the
residual is the magnitude's, (m_model - m_obs) / sigma_m, as ln(E_model / E_obs) / (0.4 ln 10
sigma_m); without stated errors the errors are scaled by the residuals. Observations in the
Earth's shadow are left out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_choice, check_count, check_name_list, check_range, check_type, check_vector, quote
from spacefit.fitting.brdf_table import PARAMETER_BOUNDS, TabulatedBRDF
from spacefit.fitting.params import Bijection
from spacefit.fitting.tabular import TableFit, fit_table
from spacefit.geometry.frames import attitude_matrix
from spacefit.materials import Material, MaterialModel
from spacefit.materials.brdf import brdf
from spacefit.materials.registry import with_material_values
from spacefit.precision import float64
from spacefit.studies.observing import LN_PER_MAGNITUDE, LightCurveObservations, irradiance_of, magnitude_of


@dataclass(frozen=True)
class Plate:
    """A flat plate: ``area_m2``, unit ``normal`` and ``tangent`` (the direction of a conductor's
    ``alpha_x``; made normal to ``normal``) in the target's frame, and its material."""

    name: str
    area_m2: float
    normal: tuple[float, float, float]
    material: Material | TabulatedBRDF
    tangent: tuple[float, float, float] = (1.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        check_type("name", self.name, str, "a string")
        what = ("an sf.Lambert, sf.Conductor, sf.DiffuseConductor, sf.OrenNayar (a material model with a BRDF) or sf.TabulatedBRDF "
                "(a Mirror's BRDF is a delta function: never lit towards an observer by a point sun)")
        check_type(f"{self.name}.material", self.material, (MaterialModel, TabulatedBRDF), what)
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

    def frame(self) -> np.ndarray:
        """(3, 3) rows: tangent, bitangent, normal (the plate's local frame in the target's)."""
        n, t = np.array(self.normal), np.array(self.tangent)
        return np.stack([t, np.cross(n, t), n])


def _grey(plate: Plate, name: str) -> float:
    value = getattr(plate.material, name)
    if isinstance(value, tuple):
        raise InputError(f"`{plate.name}.{name}` is an RGB value {value}; a light-curve fit varies grey values only.")
    return float(value)


def _fields(material: Material | TabulatedBRDF) -> tuple[str, ...]:
    """The names a plate's material may free: its model's fields and ties, or a measured table's ``scale``."""
    if isinstance(material, TabulatedBRDF):
        return ("scale",)
    return (*(f.name for f in material.fields), *material.ties)


# A measured table's factor's range; a material's fields' are its model's (PARAMETER_BOUNDS).
SCALE_BOUNDS = Bijection(0.0, 1e3)
# The target's attitude angles a fit may free ("target.attitude_x_deg"), and their range (deg).
TARGET = "target"
ATTITUDE = ("attitude_x_deg", "attitude_y_deg", "attitude_z_deg")
ATTITUDE_BOUNDS = Bijection(-180.0, 180.0)


def _plate_brdf(plate: Plate, wi: jax.Array, wo: jax.Array, values: Mapping[str, jax.Array]) -> jax.Array:
    """The plate's BRDF with some of its material's values replaced (by field name; JAX-traceable)."""
    if isinstance(plate.material, TabulatedBRDF):
        return plate.material.evaluate(wi, wo, values.get("scale"))
    return brdf(plate.material, wi, wo, values)


@float64
def plates_irradiance(plates: Sequence[Plate], sun: np.ndarray, observer: np.ndarray, range_m: np.ndarray,
                      sun_irradiance_w_m2: float, values: Mapping[str, Mapping[str, jax.Array]] | None = None) -> jax.Array:
    """Irradiance at the observer (W m^-2) of the plates lit by the sun (module docstring); ``sun``,
    ``observer`` (n, 3) unit directions from the target in its frame, ``range_m`` (n,). ``values``:
    per plate name, material values replacing the plate's own (a fit's)."""
    total = jnp.zeros(len(range_m))
    for plate in plates:
        frame = jnp.asarray(plate.frame())
        wi, wo = jnp.asarray(sun) @ frame.T, jnp.asarray(observer) @ frame.T
        f = _plate_brdf(plate, wi, wo, (values or {}).get(plate.name, {}))
        total = total + plate.area_m2 * f * jnp.abs(wi[:, 2]) * jnp.abs(wo[:, 2])
    return sun_irradiance_w_m2 * total / jnp.asarray(range_m) ** 2


@float64
def predict_magnitudes(plates: Sequence[Plate], observations: LightCurveObservations, sun_irradiance_w_m2: float = 1360.0) -> np.ndarray:
    """The plates' magnitudes in the observations' band at their geometry (inf in the Earth's shadow or unlit)."""
    plates = _check_plates(plates)
    _check_observations(observations)
    check_range("sun_irradiance_w_m2", sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
    e = np.asarray(plates_irradiance(plates, observations.sun, observations.observer, observations.range_m, sun_irradiance_w_m2))
    return magnitude_of(np.where(observations.in_shadow, 0.0, e), observations.band, sun_irradiance_w_m2)


def _check_plates(plates: object) -> list[Plate]:
    """``plates`` as a list: one or more :class:`Plate` of distinct names."""
    if isinstance(plates, (str, bytes)) or not isinstance(plates, Sequence) or not plates:
        raise InputError(f"`plates` must be a list of one or more sf.Plate, got {quote(plates)}.")
    for i, p in enumerate(plates):
        check_type(f"plates[{i}]", p, Plate, "an sf.Plate")
    names = [p.name for p in plates]
    if TARGET in names:
        raise InputError(f"`plates` must not have a plate named {TARGET!r}: the name is the target's attitude's in `free`.")
    if len(set(names)) != len(names):
        raise InputError(f"`plates` must have distinct names, got {names}.")
    return list(plates)


def _check_observations(observations: object) -> None:
    check_type("observations", observations, LightCurveObservations, "an sf.LightCurveObservations (sf.read_light_curve)")


def _tied(material: Material | TabulatedBRDF, field: str) -> tuple[str, ...]:
    """The fields a free name sets: a tie's (``alpha``: both roughnesses), else itself."""
    ties = getattr(material, "ties", {})
    return ties[field][0] if field in ties else (field,)


def _split(name: str, plates: Sequence[Plate]) -> tuple[str, str]:
    plate, _, field = name.partition(".")
    check_choice("free", plate, [TARGET, *(p.name for p in plates)])
    if plate == TARGET:
        check_choice(f"free ({TARGET})", field, ATTITUDE)
        return plate, field
    material = next(p for p in plates if p.name == plate).material
    check_choice(f"free ({plate})", field, _fields(material))
    return plate, field


def _rotation(angles_deg: Sequence[jax.Array | float]) -> jax.Array:
    """The target's rotation (object to the observations' frame) of its three attitude angles (deg),
    :func:`spacefit.geometry.frames.attitude_matrix` as the scenes' ``target.attitude_deg``."""
    return attitude_matrix(jnp.radians(jnp.stack([jnp.asarray(a, dtype=float) for a in angles_deg])), xp=jnp)


def fit_plates(plates: Sequence[Plate], observations: LightCurveObservations, free: Sequence[str], *,
               bounds: Mapping[str, tuple[float, float]] | None = None, sun_irradiance_w_m2: float = 1360.0,
               max_steps: int = 200) -> TableFit:
    """Fit the plates' material values ``free`` (``"plate.field"``; ``alpha`` sets both roughnesses;
    a :class:`~spacefit.fitting.brdf_table.TabulatedBRDF`'s ``scale``) and, where freed, the target's
    attitude angles (``"target.attitude_x_deg"``, ``_y_``, ``_z_``: a rotation of all the plates from
    their given normals, started at 0, :func:`spacefit.geometry.frames.attitude_matrix`) to the
    observed magnitudes outside the Earth's shadow (module docstring), from the plates' values.
    ``bounds`` narrows a free value's range (``{"chassis.eta": (1.0, 100.0)}``: a dielectric's
    physical range) within its own (its model's field's, a table's scale :data:`SCALE_BOUNDS`, attitudes
    +-180 deg); the start must lie inside."""
    plates = _check_plates(plates)
    _check_observations(observations)
    check_range("sun_irradiance_w_m2", sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
    check_count("max_steps", max_steps, optional=False)
    names = list(check_name_list("free", free))
    split = [_split(n, plates) for n in names]
    check_type("bounds", bounds, (Mapping, type(None)), "a dict of (low, high) ranges by free name, or None")
    ranges = [ATTITUDE_BOUNDS if p == TARGET else SCALE_BOUNDS if f == "scale" else PARAMETER_BOUNDS[f] for p, f in split]
    for name, given in (bounds or {}).items():
        check_choice("bounds", name, names)
        i = names.index(name)
        if not (isinstance(given, (tuple, list)) and len(given) == 2):
            raise InputError(f"`bounds[{name!r}]` must be a (low, high) pair, got {quote(given)}.")
        check_range(f"bounds[{name!r}][0]", given[0], ranges[i].lo, ranges[i].hi)
        check_range(f"bounds[{name!r}][1]", given[1], float(given[0]), ranges[i].hi, lo_open=True)
        ranges[i] = Bijection(float(given[0]), float(given[1]))
    lit = ~observations.in_shadow
    if not lit.any():
        raise InputError(f"every observation of {observations.source} is in the Earth's shadow: there is nothing to fit.")
    obs = observations.subset(lit)
    plate_of = {p.name: p for p in plates}
    start = [0.0 if p == TARGET else _grey(plate_of[p], _tied(plate_of[p].material, f)[0]) for p, f in split]
    for name, value, r in zip(names, start, ranges):
        if not r.lo < value < r.hi:
            raise InputError(f"`{name}` starts at {value:g}, outside its bounds ({r.lo:g}, {r.hi:g}): give the plates a value inside.")
    data = irradiance_of(obs.magnitude, obs.band, sun_irradiance_w_m2)
    sigma = None if obs.magnitude_sigma is None else LN_PER_MAGNITUDE * obs.magnitude_sigma

    def predict(x: jax.Array) -> jax.Array:
        values: dict[str, dict[str, jax.Array]] = {}
        for (plate, field), v in zip(split, x):
            for f in _tied(plate_of[plate].material, field):
                values.setdefault(plate, {})[f] = v
        sun, observer = jnp.asarray(obs.sun), jnp.asarray(obs.observer)
        if TARGET in values:
            turn = _rotation([values[TARGET].get(a, 0.0) for a in ATTITUDE])
            sun, observer = sun @ turn, observer @ turn
        return plates_irradiance(plates, sun, observer, obs.range_m, sun_irradiance_w_m2, values)

    return fit_table(predict, data, sigma, names, ranges, start, log=True, max_steps=max_steps)


def fitted_plates(plates: Sequence[Plate], fit: TableFit) -> list[Plate]:
    """The plates with a :func:`fit_plates` fit's values in their materials and, where it freed the
    attitude, their normals and tangents turned by it."""
    plates = _check_plates(plates)
    check_type("fit", fit, TableFit, "an sf.TableFit (of sf.fit_plates)")
    for name in fit.names:
        _split(name, plates)
    angles = {name.partition(".")[2]: float(v) for name, v in zip(fit.names, fit.values) if name.startswith(TARGET + ".")}
    if angles:
        turn = np.asarray(_rotation([angles.get(a, 0.0) for a in ATTITUDE]))
        plates = [dataclasses.replace(p, normal=tuple(turn @ np.array(p.normal)), tangent=tuple(turn @ np.array(p.tangent))) for p in plates]
    out = []
    for plate in plates:
        values = {}
        for name, v in zip(fit.names, fit.values):
            p, _, field = name.partition(".")
            if p == plate.name:
                values[field] = float(v)
        if isinstance(plate.material, TabulatedBRDF) and values:
            material = dataclasses.replace(plate.material, **values)
        else:
            material = with_material_values(plate.material, values, where=plate.name) if values else plate.material
        out.append(dataclasses.replace(plate, material=material))
    return out
