"""The light curve of a target made of flat plates: its plates, their irradiance at an observer and its magnitudes.

Each plate (:class:`Plate`) has an area, a normal and a tangent in the target's frame, and a
spacefit material. The irradiance at an observer at distance d is

    E = E_sun / d^2 sum_k A_k f_k(wi, wo) |n_k . wi| |n_k . wo|,

f_k the plate's BRDF (:func:`spacefit.materials.brdf.brdf`, Mitsuba's evaluation, both sides
alike as the renderer's ``twosided``, 0 where sun and observer are on opposite sides; a measured
table's too, :class:`TabulatedBRDF`), wi and wo the
directions towards the sun and the observer: the renderer's integrated irradiance of the same
plates for a point target (no plate shadowing or lighting another, one bounce; the test renders
the two-plate satellite and compares). A target in the Earth's shadow is dark.

Given an :class:`Earth`, the irradiance is the sun's plus Earthshine's:
the same plates lit by the sunlit Earth (:func:`earthshine_sources`
once per set of observations, from their ``earth_m``, the sphere at the observing geometry's radius
:data:`~spacefit.studies.orbit.EARTH_RADIUS_M`; :func:`earthshine_irradiance`
with the plates' BRDF at the fitted values and attitude). Without one the model is the sun's alone.

Fits of the plates' materials to observed magnitudes are :mod:`spacefit.studies.plate_fit`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_direction, check_range, check_type, check_vector, quote
from spacefit.geometry.articulation import SunTracking
from spacefit.geometry.frames import attitude_matrix
from spacefit.geometry.rotations import tracking_rotation
from spacefit.materials import Material, MaterialModel
from spacefit.materials.brdf import brdf
from spacefit.precision import float64
from spacefit.studies.earthshine import EARTH_MEAN_RADIUS_M, Earth, EarthshineSources, earthshine_irradiance, earthshine_sources
from spacefit.studies.lightcurve_observations import LightCurveObservations, magnitude_of
from spacefit.studies.orbit import EARTH_RADIUS_M

# The target's attitude angles a fit may free ("target.attitude_x_deg").
TARGET = "target"
ATTITUDE = ("attitude_x_deg", "attitude_y_deg", "attitude_z_deg")


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


def _parts(plates: Sequence[Plate]) -> list[list[Plate]]:
    """The plates by part (one name, one material), in the order of each part's first plate."""
    parts: list[list[Plate]] = []
    for plate in plates:
        same = next((part for part in parts if part[0].name == plate.name and not part[0].material != plate.material), None)
        if same is None:
            parts.append([plate])
        else:
            same.append(plate)
    return parts


@float64
def plates_irradiance(plates: Sequence[Plate], sun: np.ndarray, observer: np.ndarray, range_m: np.ndarray,
                      sun_irradiance_w_m2: float, values: Mapping[str, Mapping[str, jax.Array]] | None = None, *,
                      tracking_sun: np.ndarray | None = None) -> jax.Array:
    """Irradiance at the observer (W m^-2) of the plates lit by the sun (module docstring); ``sun``,
    ``observer`` (n, 3) unit directions from the target in its frame, ``range_m`` (n,). ``values``:
    per plate name, material values replacing the plate's own (a fit's). ``tracking_sun`` (n, 3): the
    directions towards the sun that sun-tracking plates turn to (:meth:`Plate.frames`), where the light
    ``sun`` comes from elsewhere (Earthshine); ``sun`` itself by default.

    The plates of one part share one evaluation of its BRDF over all their directions: the program a fit
    compiles grows with the parts, not the plates (a box's six faces are one evaluation)."""
    sun, observer = jnp.asarray(sun), jnp.asarray(observer)
    toward = sun if tracking_sun is None else jnp.asarray(tracking_sun)
    total = jnp.zeros(len(range_m))
    for part in _parts(plates):
        frames = jnp.stack([plate.frames(toward) for plate in part])  # (k, n, 3, 3): each plate's frame at each time
        wi, wo = jnp.einsum("knij,nj->kni", frames, sun), jnp.einsum("knij,nj->kni", frames, observer)
        f = brdf(part[0].material, wi, wo, (values or {}).get(part[0].name, {}))
        two_sided = jnp.asarray([plate.two_sided for plate in part])[:, None]
        lit = jnp.where(two_sided, jnp.abs(wi[..., 2]), jnp.maximum(wi[..., 2], 0.0))  # f is 0 where wo is on the other side
        area = jnp.asarray([plate.area_m2 for plate in part])[:, None]
        total = total + jnp.sum(area * f * lit * jnp.abs(wo[..., 2]), axis=0)
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
    plates = check_plates(plates)
    check_observations(observations)
    check_range("sun_irradiance_w_m2", sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
    check_type("shares", shares, bool, "True or False")
    sources = earthshine_of(earth, observations)
    direct, earthshine = (np.asarray(e) for e in plates_light(plates, observations, sun_irradiance_w_m2, {}, sources))
    total = np.where(observations.in_shadow, 0.0, direct if sources is None else direct + earthshine)
    magnitudes = magnitude_of(total, observations.band, sun_irradiance_w_m2)
    if not shares:
        return magnitudes
    with np.errstate(divide="ignore", invalid="ignore"):
        return magnitudes, np.where(total > 0, np.where(observations.in_shadow, 0.0, earthshine) / total, np.nan)


def earthshine_of(earth: Earth | None, observations: LightCurveObservations) -> EarthshineSources | None:
    """The lit Earth seen from the observations' targets (None without an ``earth``), the sphere at
    the observing geometry's radius :data:`~spacefit.studies.orbit.EARTH_RADIUS_M`."""
    checked = check_earth(earth, observations)
    if checked is None or observations.earth_m is None:
        return None
    return earthshine_sources(observations.earth_m, observations.sun, dataclasses.replace(checked, radius_m=EARTH_RADIUS_M))


def check_earth(earth: object, observations: LightCurveObservations) -> Earth | None:
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


def plates_light(plates: Sequence[Plate], observations: LightCurveObservations, sun_irradiance_w_m2: float,
                 values: Mapping[str, Mapping[str, jax.Array]], sources: EarthshineSources | None) -> tuple[jax.Array, jax.Array]:
    """The sun's and Earthshine's irradiance at the observers (W m^-2; Earthshine 0 without ``sources``),
    the plates at ``values`` (per plate name; ``target``'s attitude angles turn them; JAX-traceable)."""
    sun, observer = jnp.asarray(observations.sun), jnp.asarray(observations.observer)
    turn = None
    if TARGET in values:
        turn = target_rotation([values[TARGET].get(a, 0.0) for a in ATTITUDE])
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


def check_plates(plates: object) -> list[Plate]:
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


def check_observations(observations: object) -> None:
    """Refuse anything but a :class:`LightCurveObservations`, naming ``observations``."""
    check_type("observations", observations, LightCurveObservations, "an sf.LightCurveObservations (sf.read_light_curve)")


def target_rotation(angles_deg: Sequence[jax.Array | float]) -> jax.Array:
    """The target's rotation (object to the observations' frame) of its three attitude angles (deg),
    :func:`spacefit.geometry.frames.attitude_matrix` as the scenes' ``target.attitude_deg``."""
    return attitude_matrix(jnp.radians(jnp.stack([jnp.asarray(a, dtype=float) for a in angles_deg])), xp=jnp)
