"""Earthshine: the Earth as a second light source of a target's light curve.

The Earth is a sphere (:class:`Earth`, radius 6371 km, the mean radius) lit by the sun, its surface's
BRDF of the Phong type that lumos-sat's ``PHONG`` states (Fankhauser, Tyson & Askari 2023, AJ 166, 59;
lumos-sat ``lumos/brdf/library.py``),

    f_E(s, w) = kd / pi + ks (n + 2) / (2 pi) max(r . w, 0)^n,    r = 2 (s . N) N - s,

N the surface's normal, s the direction towards the sun, w towards the target: ``ks = 0`` is a
Lambert surface of albedo ``kd`` (default 0.3, the albedo lumos-sat's Earthshine studies take), and
:data:`VEGETATION` the paper's vegetation Earth (kd 0.53, ks 0.28, n 7.31, fitted to CAR airborne
BRDF measurements in its repository Forrest-Fankhauser/satellite-optical-brightness).

Seen from a target at distance r from the Earth's centre, the visible cap (angle gamma from the
sub-target point up to gamma_max = arccos(R / r)) is lit where N . s > 0. Each point of it at
distance D sends the target the irradiance, on a surface facing it,

    dE = E_sun f_E(s, w) (N . s) (N . w) dA / D^2,

and a target of plates reflects towards an observer at distance d

    E_earthshine = E_sun / d^2 sum_j W_j sum_k A_k f_k(w_j, wo) |n_k . w_j| |n_k . wo|,

W_j = f_E (N . s) (N . w) dA / D^2 the Earth's weights per unit solar irradiance
(:func:`earthshine_sources`), w_j the directions towards the Earth's points from the target: the sum
the sun's term of :func:`spacefit.studies.plates.plates_irradiance` makes with w_j in place of the
sun (lumos-sat's ``get_intensity_satellite_frame`` sums the same product over a mesh of panels).

The quadrature is Gauss-Legendre over the lit part of the cap exactly: in polar coordinates
(gamma, phi) about the sub-target point, phi split where the terminator leaves the horizon (the
interval of gamma changes form there), gamma over [gamma_lo(phi), gamma_hi(phi)] between the
terminator and the horizon. A plate's own horizon is the one kink left inside: ``points`` nodes
per dimension and piece (default 32: three pieces, 3,072 nodes per observation) give the
irradiance of any plate within 1e-3 of the target's Earthshine irradiance (that on a plate facing
the Earth's centre, which they give within 1e-6), and the product with lumos-sat's calculator
within 0.3 % (tests/test_earthshine.py: against the converged sum, a Lambert sphere's phase law, an
overhead sun's closed form, the view factor of a uniformly bright sphere and lumos-sat). The atmosphere is not modelled (no scattering, no refraction), nor the Earth's
oblateness.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_array, check_count, check_range, check_type, quote, unit_rows
from spacefit.precision import float64

# The Earth's mean radius (m, IUGG): the sphere Earthshine comes from.
EARTH_MEAN_RADIUS_M = 6371.0e3
# Gauss-Legendre nodes per dimension and piece of the lit cap (module docstring).
DEFAULT_POINTS = 32


@dataclass(frozen=True)
class Earth:
    """The Earth for Earthshine, a sunlit sphere with a Phong-type surface; ``ks = 0`` (the default) is Lambert.

    A sphere of ``radius_m`` whose surface reflects the sun with the BRDF
    ``kd / pi + ks (n + 2) / (2 pi) max(r·w, 0)^n`` (the guide "BRDF tables and light curves as observations"); ``ks = 0`` is a Lambert surface of albedo ``kd``.

    Args:
        kd: the diffuse albedo, in [0, 1].
        ks: the specular share, >= 0 (kd + ks <= 1).
        n: the Phong exponent, >= 0.
        radius_m: the sphere's radius (m).

    Raises:
        InputError: a value out of range.

    Example:
        >>> import spacefit as sf
        >>> sf.Earth()
        Earth(kd=0.3, ks=0.0, n=1.0, radius_m=6371000.0)
    """

    kd: float = 0.3
    ks: float = 0.0
    n: float = 1.0
    radius_m: float = EARTH_MEAN_RADIUS_M

    def __post_init__(self) -> None:
        check_range("earth.kd", self.kd, 0.0, 1.0)
        check_range("earth.ks", self.ks, 0.0, 1.0)
        if self.kd + self.ks > 1.0:
            raise InputError(f"`earth.kd + earth.ks` must be at most 1 (energy conservation), got {self.kd + self.ks:g}.")
        check_range("earth.n", self.n, 0.0, 1e4, lo_open=True)
        check_range("earth.radius_m", self.radius_m, 0.0, lo_open=True, unit="m")

    def describe(self) -> str:
        """Its surface in words, for reports: ``Lambert Earth, albedo 0.3`` or the Phong-type values."""
        if self.ks == 0:
            return f"Lambert Earth, albedo {self.kd:g}"
        return f"Phong-type Earth, kd {self.kd:g}, ks {self.ks:g}, n {self.n:g}"

    def brdf(self, normal: np.ndarray, sun: np.ndarray, towards: np.ndarray) -> np.ndarray:
        """f_E (sr^-1) at unit ``normal`` (..., 3) for the unit directions towards the sun and the viewer."""
        mirrored = 2.0 * np.sum(sun * normal, axis=-1, keepdims=True) * normal - sun
        lobe = np.clip(np.sum(mirrored * towards, axis=-1), 0.0, 1.0) ** self.n
        return self.kd / math.pi + self.ks * (self.n + 2.0) / (2.0 * math.pi) * lobe


# The paper's vegetation Earth (module docstring).
VEGETATION = Earth(kd=0.53, ks=0.28, n=7.31)


@dataclass(frozen=True)
class EarthshineSources:
    """The lit Earth seen from targets as quadrature nodes.

    Attributes:
        directions: (n, m, 3) unit directions from each target towards the Earth's nodes, in the
            frame of the ``earth_m`` and ``sun`` they were made from.
        weights: (n, m) each node's irradiance at the target on a surface facing it, per unit solar
            irradiance (f_E (N . s) (N . w) dA / D^2; 0 at unused nodes).
        solid_angles: (n, m) each node's solid angle seen from the target (sr; 0 at unused nodes).

    Example:
        >>> import numpy as np, spacefit as sf
        >>> sources = sf.earthshine_sources(np.array([[0.0, 0.0, -(6371e3 + 550e3)]]), sun=np.array([[1.0, 0.0, 0.0]]))
        >>> float(sources.irradiance(np.array([0.0, 0.0, -1.0]))[0]) > 0  # per unit solar irradiance, facing the Earth
        True
    """

    directions: np.ndarray
    weights: np.ndarray
    solid_angles: np.ndarray

    def irradiance(self, normal: np.ndarray) -> np.ndarray:
        """(n,) the Earth's irradiance per unit solar irradiance on a surface of unit ``normal`` ((3,) or
        (n, 3), in the targets' frame) lit from its front only."""
        facing = np.clip(np.einsum("nmi,ni->nm", self.directions, np.broadcast_to(normal, (len(self.weights), 3))), 0.0, None)
        return np.sum(self.weights * facing, axis=-1)


def _rows(name: str, value: object) -> np.ndarray:
    """``value`` as (n, 3) finite floats."""
    arr = check_array(name, value).astype(float)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 3 or not len(arr) or not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` must be (n, 3) finite vectors, got {quote(value)}.")
    return arr


def _perpendicular(c: np.ndarray) -> np.ndarray:
    """(n, 3) unit vectors normal to the unit rows ``c``."""
    helper = np.where(np.abs(c[:, :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    return unit_rows(np.cross(c, helper))


def earthshine_sources(earth_m: np.ndarray, sun: np.ndarray, earth: Earth = Earth(), points: int = DEFAULT_POINTS) -> EarthshineSources:
    """The lit, visible Earth seen from targets (the guide "BRDF tables and light curves as observations"): ``earth_m`` (n, 3) the Earth's centre
    from each target (m), ``sun`` (n, 3) directions towards the sun, both in the targets' frame (for :class:`NadirSun`, the frame of a light curve's ``sun`` and
    ``observer``, the Earth's centre is (0, 0, -(R + height))); ``points`` Gauss-Legendre nodes per
    dimension and piece of the lit cap.

    Raises:
        InputError: a target on or inside the Earth, shapes that disagree, a zero sun direction.

    Returns:
        The :class:`EarthshineSources`.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> below = np.array([[0.0, 0.0, -(6371e3 + 550e3)]])  # the Earth's centre, 550 km under the target
        >>> sources = sf.earthshine_sources(below, sun=np.array([[1.0, 0.0, 0.0]]))
        >>> sources.directions.shape
        (1, 3072, 3)
    """
    check_type("earth", earth, Earth, "an sf.Earth")
    check_count("points", points, 2, 1000, optional=False)
    to_earth = _rows("earth_m", earth_m)
    s = unit_rows(_rows("sun", sun))
    if s.shape != to_earth.shape or not np.all(np.isfinite(s)):
        raise InputError(f"`sun` must be {len(to_earth)} non-zero directions like `earth_m`, got {quote(sun)}.")
    R = earth.radius_m
    r = np.linalg.norm(to_earth, axis=-1)
    if np.any(r <= R):
        raise InputError(f"every target must lie above the Earth (|earth_m| > {R:g} m), got distances {quote(r)} m.")
    c = -to_earth / r[:, None]  # from the Earth's centre towards the target
    s_c = np.sum(s * c, axis=-1)
    perp = s - s_c[:, None] * c
    s_p = np.linalg.norm(perp, axis=-1)
    e1 = np.where(s_p[:, None] > 1e-12, perp / np.maximum(s_p, 1e-300)[:, None], _perpendicular(c))
    e2 = np.cross(c, e1)
    g_max = np.arccos(R / r)
    # phi where the terminator meets the horizon: cos(phi_k) = -s_c cot(gamma_max) / s_p
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(s_p > 0, -s_c / np.tan(g_max) / s_p, -np.sign(s_c) * np.inf)
    phi_k = np.arccos(np.clip(np.nan_to_num(kappa, nan=-1.0), -1.0, 1.0))
    x, w = np.polynomial.legendre.leggauss(points)
    t, wt = (x + 1) / 2, w / 2  # nodes and weights on [0, 1]
    edges = np.stack([-np.full_like(phi_k, math.pi), -phi_k, phi_k, np.full_like(phi_k, math.pi)], axis=-1)
    lo, hi = edges[:, :-1, None], edges[:, 1:, None]  # (n, 3, 1): the three pieces in phi
    phi = lo + (hi - lo) * t  # (n, 3, p)
    d_phi = (hi - lo) * wt
    cos_phi = np.cos(phi)
    sc, sp, gm = s_c[:, None, None], s_p[:, None, None], g_max[:, None, None]
    g_lo = np.where(sc >= 0, 0.0, np.arctan2(-sc, sp * cos_phi))
    g_hi = np.where(sc >= 0, np.minimum(gm, np.arctan2(sc, -sp * cos_phi)), gm)
    span = np.clip(g_hi - g_lo, 0.0, None)
    gamma = g_lo[..., None] + span[..., None] * t  # (n, 3, p, p)
    d_gamma = span[..., None] * wt
    n = len(r)
    gamma, d_area = gamma.reshape(n, -1), (R**2 * np.sin(gamma) * d_gamma * d_phi[..., None]).reshape(n, -1)
    phi = np.broadcast_to(phi[..., None], (n, 3, points, points)).reshape(n, -1)
    normal = (np.cos(gamma)[..., None] * c[:, None] + np.sin(gamma)[..., None]
              * (np.cos(phi)[..., None] * e1[:, None] + np.sin(phi)[..., None] * e2[:, None]))
    v = R * normal - r[:, None, None] * c[:, None]  # from the target to the node
    distance = np.linalg.norm(v, axis=-1)
    towards_node = v / distance[..., None]
    cos_view = np.clip(-np.sum(normal * towards_node, axis=-1), 0.0, None)
    cos_sun = np.clip(np.sum(normal * s[:, None], axis=-1), 0.0, None)
    solid = cos_view * d_area / distance**2
    f = earth.brdf(normal, s[:, None], -towards_node)
    return EarthshineSources(towards_node, f * cos_sun * solid, solid)


# A target's reflection: wi, wo (k, 3) unit directions towards the light and the observer in the
# target's frame -> (k,) sum_k A_k f_k(wi, wo) |n_k . wi| |n_k . wo| (m^2 sr^-1; JAX-traceable).
Reflection = Callable[[jax.Array, jax.Array], jax.Array]


@float64
def earthshine_irradiance(reflect: Reflection, sources: EarthshineSources, observer: np.ndarray, range_m: np.ndarray,
                          sun_irradiance_w_m2: float = 1360.0) -> jax.Array:
    """The irradiance at the observers (W m^-2) of the Earthshine a target reflects: the sunlit Earth's
    quadrature nodes (``sources``) each light the target, whose reflection sends part of it to the
    observer (the guide "BRDF tables and light curves as observations"). Differentiable in what
    ``reflect`` closes over.

    Args:
        reflect: the target's reflection, ``(wi, wo) -> (k,)``: for (k, 3) unit directions towards the
            light and the observer in the target's frame, sum over its surfaces of area x BRDF x
            ``|n . wi| |n . wo|`` (m^2 sr^-1; JAX-traceable).
        sources: the Earth seen from the target (:func:`earthshine_sources`, same frame).
        observer: (n, 3) directions towards the observer.
        range_m: (n,) the observer's distance (m).
        sun_irradiance_w_m2: the sun's irradiance at the target (W m^-2).

    Returns:
        (n,) irradiance (W m^-2).

    Raises:
        InputError: shapes that disagree with ``sources``, a zero direction, a non-positive range.

    Example:
        A 10 m^2 white plate facing the Earth, seen from 550 km below:

        >>> import jax.numpy as jnp, numpy as np, spacefit as sf
        >>> sources = sf.earthshine_sources(np.array([[0.0, 0.0, -(6371e3 + 550e3)]]), sun=np.array([[1.0, 0.0, 0.0]]))
        >>> def plate(wi, wo):  # Lambert, albedo 0.3, normal -z, lit and seen from below only
        ...     return 10.0 * 0.3 / np.pi * jnp.abs(wi[:, 2] * wo[:, 2]) * (wi[:, 2] < 0) * (wo[:, 2] < 0)
        >>> E = sf.earthshine_irradiance(plate, sources, observer=np.array([[0.0, 0.0, -1.0]]), range_m=np.array([550e3]))
        >>> f"{float(E[0]):.2g} W m^-2"
        '3.2e-11 W m^-2'
    """
    check_type("sources", sources, EarthshineSources, "an sf.EarthshineSources (sf.earthshine_sources)")
    check_range("sun_irradiance_w_m2", sun_irradiance_w_m2, 0.0, lo_open=True, unit="W m^-2")
    n, m = sources.weights.shape
    wo = unit_rows(_rows("observer", observer))
    d = check_array("range_m", range_m).astype(float).reshape(-1)
    if wo.shape != (n, 3) or not np.all(np.isfinite(wo)) or d.shape != (n,) or not np.all(d > 0):
        raise InputError(f"`observer` must be ({n}, 3) non-zero directions and `range_m` {n} positive distances, "
                         f"as many as the sources' targets; got shapes {np.shape(observer)} and {np.shape(range_m)}.")
    used = sources.weights > 0  # the reflection at the nodes that carry light only
    rows, cols = np.nonzero(used)
    reflected = reflect(jnp.asarray(sources.directions[rows, cols]), jnp.asarray(wo[rows]))
    per_target = jax.ops.segment_sum(jnp.asarray(sources.weights[rows, cols]) * reflected, jnp.asarray(rows), num_segments=n)
    return sun_irradiance_w_m2 * per_target / jnp.asarray(d) ** 2
