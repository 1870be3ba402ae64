"""The one place where two coordinates of a scene value are converted: the wrinkles' rms height and
their height scale G at a dimension D (eq. 2-1, :func:`spacefit.geometry.wm.wm_rms`), and the sun's
direction of travel and the elevation and azimuth (deg) of the direction towards it.

In an image D and G trade off along a valley of nearly constant rms height; (D, rms) are the better
determined coordinates. The sun's angles give the direction towards it, (cos el cos az, cos el sin az,
sin el); the light travels the opposite way (the scene's ``sun.direction``).
"""

from __future__ import annotations

import math
from types import ModuleType
from typing import Any

import numpy as np

from spacefit.geometry.wm import wm_G_from_rms, wm_rms
from spacefit.scene.sections import WrinkleSettings


def rms_of(w: WrinkleSettings, D: Any, G: Any) -> Any:
    """Expected rms height (m) of the wrinkles ``w`` at (D, G) (floats, NumPy or JAX arrays)."""
    return wm_rms(D, G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)


def G_of(w: WrinkleSettings, D: Any, rms: Any) -> Any:
    """The height scale G (m) that gives the wrinkles ``w`` an rms height ``rms`` (m) at D."""
    return wm_G_from_rms(D, rms, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)


# A sun at the zenith or the nadir (the default sun is at the zenith) has no azimuth of its own: it
# reads STATED_AZIMUTH_DEG (world +x), and setting its elevation alone turns it towards +x.
STATED_AZIMUTH_DEG = 0.0
VERTICAL_SUN = 1e-9


def sun_angles_deg(direction: tuple[float, float, float] | np.ndarray) -> tuple[float, float]:
    """Elevation and azimuth (deg) of the direction towards the sun, from its direction of travel."""
    towards = -np.asarray(direction, float) / np.linalg.norm(direction)
    vertical = np.hypot(towards[0], towards[1]) < VERTICAL_SUN
    azimuth = STATED_AZIMUTH_DEG if vertical else math.degrees(math.atan2(towards[1], towards[0]))
    return math.degrees(math.asin(float(np.clip(towards[2], -1.0, 1.0)))), azimuth


def sun_direction(elevation_deg: Any, azimuth_deg: Any, xp: ModuleType = np) -> Any:
    """The sun's direction of travel from the elevation and azimuth (deg) of the direction towards
    it, in the array module ``xp`` (NumPy, or ``jax.numpy`` to differentiate it)."""
    el, az = xp.deg2rad(elevation_deg), xp.deg2rad(azimuth_deg)
    return -xp.stack([xp.cos(el) * xp.cos(az), xp.cos(el) * xp.sin(az), xp.sin(el)])
