"""Whether a rendered light curve has converged: the same curve at twice the pixels and at four
times the samples, compared point by point (:func:`light_curve_convergence`).

An unresolved target needs few pixels, and each point's irradiance is a sum over them: more pixels
or more samples change it only by what the scene's settings had not resolved. The change is
relative, over the points lit at the scene's settings (a dark point's change has no scale).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.errors import check_range
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.studies.lightcurve import LightCurve, light_curve


@dataclass(frozen=True)
class Convergence:
    """Whether a light curve's integrated irradiance has converged in pixels and in samples.

    Attributes:
        pixels_change: the largest relative change of a point's irradiance from the scene's
            resolution to twice it (each axis), at the scene's spp.
        samples_change: the same from the scene's spp to four times it, at the scene's resolution.
        tolerance: the relative change allowed.
        irradiance_w_m2: the light curve at the scene's settings.
    """

    pixels_change: float
    samples_change: float
    tolerance: float
    irradiance_w_m2: np.ndarray

    @property
    def converged(self) -> bool:
        """Both changes within the tolerance: more pixels or samples would not change the light curve."""
        return self.pixels_change <= self.tolerance and self.samples_change <= self.tolerance

    def line(self) -> str:
        """One line of words."""
        verdict = "converged" if self.converged else "NOT converged: raise render.resolution or render.spp"
        return (f"light curve {verdict}: x2 pixels changes it by {self.pixels_change:.2%}, x4 samples by "
                f"{self.samples_change:.2%} (tolerance {self.tolerance:.2%})")


def light_curve_convergence(scene: Scene, *, tolerance: float = 0.01, **kwargs: Any) -> Convergence:
    """Render the light curve (:func:`light_curve`, its keyword arguments) at the scene's resolution and
    spp, at twice the resolution and at four times the spp, and compare: a point target needs few
    pixels, and this says whether the scene's are enough (the irradiance of the points that are lit
    at the scene's settings; a dark point's change is not relative).

    Args:
        scene: the scene.
        tolerance: the relative change of irradiance allowed.
        kwargs: :func:`light_curve`'s keywords (``phase_deg=[...]``, ...).

    Returns:
        The changes in pixels and in samples, and ``converged``.

    Raises:
        InputError: a ``tolerance`` not > 0, or what :func:`light_curve` refuses.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> check = sf.light_curve_convergence(scene, phase_deg=[10, 40], quiet=True)
        >>> check.tolerance
        0.01
    """
    check_scene(scene)
    check_range("tolerance", tolerance, 0.0, lo_open=True)
    base = light_curve(scene, **kwargs)
    width, height = scene.render.resolution
    finer = scene.with_values({"render.resolution": [2 * width, 2 * height]})
    more = scene.with_values({"render.spp": 4 * scene.render.spp})
    lit = base.irradiance_w_m2 > 0

    def change(other: LightCurve) -> float:
        if not lit.any():
            return 0.0
        return float(np.max(np.abs(other.irradiance_w_m2[lit] / base.irradiance_w_m2[lit] - 1.0)))

    return Convergence(change(light_curve(finer, **kwargs)), change(light_curve(more, **kwargs)), tolerance, base.irradiance_w_m2)
