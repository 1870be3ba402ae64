"""The 3-D Weierstrass-Mandelbrot (W-M) height field of the wrinkled insulation (thesis eq. 2-1).

Yan & Komvopoulos (1998, J. Appl. Phys. 84(7):3617), as written in the thesis::

    z(x, y) = L (G/L)^(D-2) (ln(gamma)/M)^(1/2) sum_{m=1..M} sum_{n=0..nmax} gamma^((D-3) n)
              { cos(phi_mn) - cos[2 pi gamma^n r / L cos(theta - pi m / M) + phi_mn] }

with (r, theta) the polar coordinates of (x, y) and nmax = int(log(L/Ls) / log(gamma)). Lengths
are in metres. Heights are JAX functions of the fractal dimension D and the height scale G, so
their derivatives can flow into the renderer; every other parameter is a static Python value.
"""

from __future__ import annotations

import math
import operator
import sys
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from spacefit.errors import InputError, check_range
from spacefit.precision import float64

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s), which a render does not need
    from jaxtyping import Array, ArrayLike, Float

# log(L/Ls)/log(gamma) is an integer in exact arithmetic when Ls = L / gamma^k; without this slack
# rounding can land just below k and drop the finest scale.
_N_MAX_SLACK = 1e-9
# Caps on the W-M sum's terms (M ridges x n_max + 1 scales, evaluated at every vertex): the thesis
# uses 5 x 8; 1e8 ridges or gamma = 1 + 1e-7 exhausted the memory.
MAX_RIDGES = 64
MAX_SCALES = 64


def _xp(*values: object) -> ModuleType:
    """``jax.numpy`` when a value is a JAX array or tracer, else NumPy: the level of detail's slope
    of plain numbers then needs no JAX, whose import alone takes 0.6 s of a render."""
    jax = sys.modules.get("jax")
    if jax is not None and any(isinstance(v, jax.Array) for v in values):
        return jax.numpy
    return np


def wm_n_max(L: float, Ls: float, gamma: float) -> int:
    """Index of the finest W-M scale, ``int(log(L/Ls) / log(gamma))`` (7 for 0.1 m, 5 mm, 1.5)."""
    return int(math.floor(math.log(L / Ls) / math.log(gamma) + _N_MAX_SLACK))


def wm_phases(M: int, n_max: int, seed: int) -> Float[np.ndarray, "M K"]:
    """Random phases phi_mn, uniform in [0, 2 pi), shape (M, n_max + 1), from ``default_rng(seed)``."""
    return np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, size=(M, n_max + 1))


def check_wm_params(D: float, G: float, gamma: float, M: int, L: float, Ls: float) -> None:
    """Check the W-M parameters (thesis eq. 2-1); lengths G, L, Ls in metres.

    Raises:
        InputError: naming ``wrinkles.<name>``, unless D in (2, 3), G > 0, gamma > 1, M an integer
            >= 1, L > 0 and Ls in (0, L).
    """
    check_range("wrinkles.D", D, 2.0, 3.0, lo_open=True, hi_open=True)
    check_range("wrinkles.G", G, 0.0, lo_open=True, unit="m")
    check_range("wrinkles.gamma", gamma, 1.0, lo_open=True)
    try:
        m = operator.index(M)
    except TypeError:
        raise InputError(f"`wrinkles.M` must be an integer, got {M!r}.") from None
    if isinstance(M, bool) or m < 1:
        raise InputError(f"`wrinkles.M` must be an integer >= 1, got {M!r}.")
    if m > MAX_RIDGES:
        raise InputError(f"`wrinkles.M` must be at most {MAX_RIDGES} (each ridge direction costs a term per scale "
                         f"at every vertex), got {m}.")
    length = check_range("wrinkles.L", L, 0.0, lo_open=True, unit="m")
    check_range("wrinkles.Ls", Ls, 0.0, length, lo_open=True, hi_open=True, unit="m")
    scales = math.log(L / Ls) / math.log(gamma)
    if scales > MAX_SCALES:
        raise InputError(f"`wrinkles.gamma` = {gamma:.10g} with `wrinkles.L` / `wrinkles.Ls` = {L / Ls:.3g} gives "
                         f"{scales:.3g} W-M scales (log(L / Ls) / log(gamma)); at most {MAX_SCALES}: raise gamma or Ls.")


@float64
def wm_height(
    uv: Float[ArrayLike, "n 2"],
    D: float | Array,
    G: float | Array,
    *,
    gamma: float,
    M: int,
    L: float,
    Ls: float,
    phases: Float[np.ndarray, "M K"],
) -> Float[Array, " n"]:
    """W-M heights z(u, v) of thesis eq. 2-1 (Yan & Komvopoulos 1998) at points ``uv``.

    Args:
        uv: (n, 2) plane coordinates, metres.
        D: fractal dimension in (2, 3); may be a JAX tracer.
        G: height scale, metres; may be a JAX tracer.
        gamma, M, L, Ls: frequency ratio, number of ridges, sample and cut-off lengths (metres).
        phases: (M, nmax + 1) phases phi_mn in radians (see :func:`wm_phases`).

    Returns:
        (n,) heights, metres.
    """
    import jax.numpy as jnp  # here: a render of cached vertices never needs JAX

    n = np.arange(wm_n_max(L, Ls, gamma) + 1)
    phases = np.asarray(phases, dtype=float)
    if phases.shape != (M, len(n)):
        raise InputError(f"W-M phases must have shape ({M}, {len(n)}) for these M, L, Ls, gamma; got {phases.shape}.")
    uv = jnp.asarray(uv, dtype=float)
    angles = np.pi * np.arange(1, M + 1) / M
    # r cos(theta - a) = u cos(a) + v sin(a): no polar angle, so no singularity at the origin.
    along = uv @ jnp.asarray(np.stack([np.cos(angles), np.sin(angles)]))  # (n, M)
    wavenumbers = 2.0 * np.pi * gamma**n / L
    weights = jnp.power(gamma, (D - 3.0) * n)
    # One ridge at a time keeps the intermediate at (n, nmax + 1) rather than (n, M, nmax + 1).
    waves = sum(jnp.cos(along[:, m, None] * wavenumbers + phases[m]) @ weights for m in range(M))
    scale = L * (G / L) ** (D - 2.0) * math.sqrt(math.log(gamma) / M)
    return scale * (jnp.sum(jnp.asarray(np.cos(phases)) @ weights) - waves)


def profile_ra(x: Float[ArrayLike, " n"], z: Float[ArrayLike, " n"]) -> float:
    """Arithmetic mean roughness Ra = mean |z - line| about the least-squares mean line (thesis 2.2).

    ``x`` and ``z`` are the (n,) abscissae and heights of a profile; Ra has the unit of ``z``.
    """
    x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
    residual = z - np.polyval(np.polyfit(x, z, 1), x)
    return float(np.mean(np.abs(residual)))


def wm_section_ra(
    D: float,
    G: float,
    *,
    gamma: float = 1.5,
    M: int = 5,
    L: float = 0.1,
    Ls: float = 5e-3,
    length: float | None = None,
    n_samples: int = 4096,
    y: float = 0.0,
) -> float:
    """Ra (metres) of a section along x of the W-M surface with all phases 0, as in thesis section 2.2.

    The profile is z(x, y) for ``n_samples`` points with x uniform in [0, ``length``] (default L), y fixed.
    """
    check_wm_params(D, G, gamma, M, L, Ls)
    x = np.linspace(0.0, L if length is None else length, n_samples)
    uv = np.stack([x, np.full_like(x, y)], axis=1)
    phases = np.zeros((M, wm_n_max(L, Ls, gamma) + 1))
    return profile_ra(x, np.asarray(wm_height(uv, D, G, gamma=gamma, M=M, L=L, Ls=Ls, phases=phases)))


def _rms_factor(D: float | Array, gamma: float, M: int, L: float, Ls: float) -> Array:
    """rms height / (L (G/L)^(D-2)): sqrt(ln(gamma)/2 * sum_n gamma^(2 (D-3) n))."""
    n = np.arange(wm_n_max(L, Ls, gamma) + 1)
    xp = _xp(D)
    return xp.sqrt(0.5 * math.log(gamma) * xp.sum(xp.power(gamma, 2.0 * (D - 3.0) * n)))


def wm_rms(D: float | Array, G: float | Array, *, gamma: float, M: int, L: float, Ls: float) -> Array:
    """Expected rms height (m) of eq. 2-1 over positions and random phases.

    Each of the M (nmax + 1) cosines has variance 1/2 over the plane, so the rms height is
    ``L (G/L)^(D-2) sqrt(ln(gamma)/2 * sum_n gamma^(2 (D-3) n))``, independent of M.

    Args:
        D: fractal dimension, in (2, 3).
        G: height scale (m).
        gamma: the frequencies' ratio, > 1.
        M: the number of ridge directions.
        L, Ls: the longest and the cut-off wavelength (m).

    Returns:
        The rms height (m), a JAX scalar (or D's and G's broadcast shape); differentiable in D and G.

    Example:
        >>> import spacefit as sf
        >>> w = sf.default_scene().wrinkles
        >>> f"{float(sf.wm_rms(w.D, w.G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)) * 1e3:.2f} mm"
        '4.29 mm'
    """
    return L * (G / L) ** (D - 2.0) * _rms_factor(D, gamma, M, L, Ls)


def wm_G_from_rms(D: float | Array, rms: float | Array, *, gamma: float, M: int, L: float, Ls: float) -> Array:
    """The height scale G (m) that gives rms height ``rms`` (m) at fractal dimension D (inverse of :func:`wm_rms`)."""
    return L * (rms / (L * _rms_factor(D, gamma, M, L, Ls))) ** (1.0 / (D - 2.0))


def wm_rms_slope(D: float | Array, G: float | Array, *, gamma: float, M: int, L: float, Ls: float) -> Array:
    """Expected rms slope of eq. 2-1 along one axis (dimensionless).

    With wave numbers k_n = 2 pi gamma^n / L and ridges at angles pi m / M (sum of cos^2 over them
    M / 2 for M >= 2), each axis's slope variance is
    ``L^2 (G/L)^(2(D-2)) ln(gamma)/4 * sum_n gamma^(2(D-3)n) k_n^2``.

    Args:
        D: fractal dimension, in (2, 3).
        G: height scale (m).
        gamma: the frequencies' ratio, > 1.
        M: the number of ridge directions.
        L, Ls: the longest and the cut-off wavelength (m).

    Returns:
        The rms slope, a JAX scalar (or D's and G's broadcast shape); compare :data:`MLI_SLOPE_RANGE`.

    Example:
        >>> import spacefit as sf
        >>> w = sf.default_scene().wrinkles
        >>> round(float(sf.wm_rms_slope(w.D, w.G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)), 2)
        0.59
    """
    n = np.arange(wm_n_max(L, Ls, gamma) + 1)
    k2 = (2.0 * np.pi * gamma**n / L) ** 2
    xp = _xp(D, G)
    spectrum = xp.sum(xp.power(gamma, 2.0 * (D - 3.0) * n) * k2)
    return L * (G / L) ** (D - 2.0) * xp.sqrt(0.25 * math.log(gamma) * spectrum)
