"""Brown-Conrady lens distortion: radial (k1, k2, k3) and tangential (decentring, p1, p2) terms.

Normalised image coordinates are ``x = (u - u0) / f_px``, ``y = (v - v0) / f_px`` (pixel
coordinates of :mod:`spacefit.geometry.frames`, v down), as in OpenCV, so OpenCV's calibrated
coefficients apply as they are. An ideal (pinhole) point (x, y) is seen at

    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y,     r^2 = x^2 + y^2.

The renderer is a pinhole camera; distortion is applied *after* the render by resampling its
radiance image (:func:`spacefit.formation.distort_image`, in JAX; this module, the lens's
description, is NumPy only). Radiance is unchanged along a ray, so resampling it is right; the
pixels' solid angles (:func:`~spacefit.geometry.frames.pixel_solid_angles`) stay the pinhole's,
which is off by the distortion's local area change (about 1 + 4 k1 r^2 for the radial term).

References: Conrady, A. E. (1919), "Decentred lens-systems", MNRAS 79, 384-390; Brown, D. C. (1966),
"Decentering distortion of lenses", Photogrammetric Engineering 32(3), 444-462.
"""

from __future__ import annotations

from dataclasses import dataclass

from typing import TYPE_CHECKING

import numpy as np

from spacefit.errors import check_finite

if TYPE_CHECKING:
    from jaxtyping import Float

UNDISTORT_TOLERANCE = 1e-12
"""Newton's iteration stops when the distorted point is reproduced within this (normalised units)."""
UNDISTORT_MAX_STEPS = 50


@dataclass(frozen=True)
class Distortion:
    """Brown-Conrady coefficients: radial k1, k2, k3 and tangential p1, p2 (dimensionless, OpenCV's order and signs).

    Lens distortion of a camera, applied to a pinhole render by :func:`distort_image`: a point at
    normalised image coordinates (x, y), r^2 = x^2 + y^2, moves to
    x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2), and likewise in y.

    Args:
        k1, k2, k3: radial coefficients.
        p1, p2: tangential coefficients.

    Raises:
        InputError: a coefficient that is not finite.

    Example:
        >>> import spacefit as sf
        >>> sf.Distortion(k1=-0.1)
        Distortion(k1=-0.1, k2=0.0, k3=0.0, p1=0.0, p2=0.0)
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self) -> None:
        for name in ("k1", "k2", "k3", "p1", "p2"):
            check_finite(f"Distortion.{name}", getattr(self, name))


def _distort_with_jacobian(x: np.ndarray, y: np.ndarray, c: Distortion) -> tuple[np.ndarray, ...]:
    r2 = x * x + y * y
    radial = 1.0 + r2 * (c.k1 + r2 * (c.k2 + r2 * c.k3))
    dradial = 2.0 * c.k1 + r2 * (4.0 * c.k2 + 6.0 * c.k3 * r2)  # d(radial)/dx = dradial * x
    xd = x * radial + 2.0 * c.p1 * x * y + c.p2 * (r2 + 2.0 * x * x)
    yd = y * radial + c.p1 * (r2 + 2.0 * y * y) + 2.0 * c.p2 * x * y
    dxx = radial + dradial * x * x + 2.0 * c.p1 * y + 6.0 * c.p2 * x
    dyy = radial + dradial * y * y + 6.0 * c.p1 * y + 2.0 * c.p2 * x
    dxy = dradial * x * y + 2.0 * c.p1 * x + 2.0 * c.p2 * y
    return xd, yd, dxx, dxy, dyy


def distort(points: Float[np.ndarray, "... 2"], coefficients: Distortion) -> Float[np.ndarray, "... 2"]:
    """Ideal normalised coordinates (x, y) to where the lens puts them, by the equations of the module."""
    p = np.asarray(points, dtype=float)
    xd, yd, *_ = _distort_with_jacobian(p[..., 0], p[..., 1], coefficients)
    return np.stack([xd, yd], axis=-1)


def undistort(points: Float[np.ndarray, "... 2"], coefficients: Distortion) -> Float[np.ndarray, "... 2"]:
    """Distorted normalised coordinates back to the ideal ones: Newton's method on :func:`distort`.

    Returns:
        the same shape; NaN where the iteration does not reach ``UNDISTORT_TOLERANCE`` (beyond the
        radius where the distortion folds over and has no inverse).
    """
    target = np.asarray(points, dtype=float)
    x, y = target[..., 0].copy(), target[..., 1].copy()
    with np.errstate(all="ignore"):  # points without an inverse may run off to inf / NaN; they are marked below
        x, y = _newton(x, y, target, coefficients)
        xd, yd, *_ = _distort_with_jacobian(x, y, coefficients)
        failed = ~(np.hypot(xd - target[..., 0], yd - target[..., 1]) < UNDISTORT_TOLERANCE)
    return np.where(failed[..., None], np.nan, np.stack([x, y], axis=-1))


def _newton(x: np.ndarray, y: np.ndarray, target: np.ndarray, coefficients: Distortion) -> tuple[np.ndarray, np.ndarray]:
    for _ in range(UNDISTORT_MAX_STEPS):
        xd, yd, dxx, dxy, dyy = _distort_with_jacobian(x, y, coefficients)
        ex, ey = xd - target[..., 0], yd - target[..., 1]
        if np.all(np.hypot(ex, ey) < UNDISTORT_TOLERANCE):
            break
        det = dxx * dyy - dxy * dxy
        x = x - (dyy * ex - dxy * ey) / det
        y = y - (dxx * ey - dxy * ex) / det
    return x, y
