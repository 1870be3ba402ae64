"""The rendered light-curve kind of observation: observed magnitudes at given geometries, predicted by
the path tracer (:mod:`spacefit.studies.lightcurve`), and the convenience that fits it alone.

Each point's irradiance is its image's sum of radiance x pixel solid angle
(:func:`spacefit.rendering.derivatives.render_function`, differentiable), rescaled to the observer's
range; the residuals compare ln E with the magnitudes' errors (0.4 ln 10 sigma_m). The model is
rendered: its render noise, measured from renders with independent seeds, enters the fit's goodness
and its errors as an image's does (:func:`spacefit.fitting.uncertainty.covariance`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_array, check_choice, check_count, check_range, check_type, check_vector, quote
from spacefit.fitting.loop import fit
from spacefit.fitting.result import FitResult
from spacefit.fitting.observations.base import Block, MeasuredValues
from spacefit.fitting.problem import INDEPENDENT_SEED_OFFSET
from spacefit.geometry.frames import pixel_solid_angles
from spacefit.rendering.derivatives import render_function
from spacefit.scene.assembly import assemble
from spacefit.scene.parameters import IMAGE, available, scene_value
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.studies.lightcurve import MAGNITUDE_PER_LN, SUN_MAGNITUDES
from spacefit.studies.lightcurve_kind import LightCurveKind


@dataclass(frozen=True, eq=False)
class RenderedLightCurve(LightCurveKind):
    """Observed magnitudes of a rendered target at given geometries.

    Attributes:
        scene: the target; its values are the parameters' own (a fit's default start).
        points: per magnitude, the scene values of its geometry (``{"target.attitude_z_deg": 30.0}``,
            ``{"sun.elevation_deg": ..., "sun.azimuth_deg": ...}``), every point setting the same ones.
        magnitude: the observed magnitudes.
        magnitude_sigma: their errors (mag; one for all, or one each), or None: unknown.
        band: the band (:data:`~spacefit.studies.lightcurve.SUN_MAGNITUDES`).
        sun_magnitude: the sun's magnitude in it (None: the band's).
        observer_range_m: the observer's range (None: the scene camera's).
        seed: the renders' seed (independent ones: ``seed + 1000 j``).
    """

    scene: Scene
    points: Sequence[Mapping[str, float]]
    magnitude: Sequence[float]
    magnitude_sigma: Sequence[float] | float | None
    band: str = "V"
    sun_magnitude: float | None = None
    observer_range_m: float | None = None
    seed: int = 1

    def __post_init__(self) -> None:
        check_scene(self.scene)
        check_choice("band", self.band, SUN_MAGNITUDES)
        if self.sun_magnitude is not None:
            check_range("sun_magnitude", self.sun_magnitude)
        check_count("seed", self.seed, 0, optional=False)
        magnitude = check_vector("magnitude", self.magnitude, None)
        points = self.points
        if isinstance(points, (str, bytes, Mapping)) or not isinstance(points, Sequence):
            raise InputError(f"`points` must be a list of dicts of scene values, got {quote(points)}.")
        if len(points) != len(magnitude):
            raise InputError(f"`points` and `magnitude` must be as long: {len(points)} points, {len(magnitude)} magnitudes.")
        for i, p in enumerate(points):
            check_type(f"points[{i}]", p, Mapping, "a dict of scene values")
            for key, value in p.items():
                check_type(f"points[{i}] key", key, str, "a scene key (a string)")
                check_range(f"points[{i}].{key}", value)
        if any(set(p) != set(self.geometry) for p in points):
            raise InputError(f"every point must set the same values, {list(self.geometry)}; got {[sorted(p) for p in points]}.")
        sigma = self.magnitude_sigma
        if sigma is not None:
            given = check_array("magnitude_sigma", sigma)
            sigma = check_vector("magnitude_sigma", np.broadcast_to(given, magnitude.shape) if given.ndim == 0 else given, len(magnitude))
        if self.observer_range_m is not None:
            check_range("observer_range_m", self.observer_range_m, 0.0, lo_open=True, unit="m")
        object.__setattr__(self, "magnitude", magnitude)
        object.__setattr__(self, "magnitude_sigma", sigma)

    @property
    def geometry(self) -> tuple[str, ...]:
        """The scene values each point sets, sorted."""
        return tuple(sorted({key for p in self.points for key in p}))

    def parameters(self) -> tuple[str, ...]:
        """Every parameter of the scene (:func:`~spacefit.scene.parameters.available`) but the points'
        geometry and the image nuisances (an irradiance has no pixels)."""
        return tuple(n for n in available(self.scene) if n not in self.geometry and n not in IMAGE)

    def start(self, name: str) -> float:
        """The scene's value of ``name``."""
        return scene_value(self.scene, name)

    def block(self, free: tuple[str, ...]) -> Block:
        """ln E of each point's render against the magnitudes' errors (module docstring)."""
        scene, geometry = self.scene, list(self.geometry)
        known = tuple(n for n in free if n in self.parameters())
        index = jnp.asarray([free.index(n) for n in known], dtype=int)
        at = jnp.asarray([[float(p[key]) for key in geometry] for p in self.points])
        rendered_range = float(np.linalg.norm(np.array(scene.camera.position_m) - np.array(scene.target.position_m)))
        scale = (rendered_range / (self.observer_range_m or rendered_range)) ** 2
        omega = jnp.asarray(pixel_solid_angles(assemble(scene).intrinsics))
        sun_magnitude = SUN_MAGNITUDES[self.band] if self.sun_magnitude is None else self.sun_magnitude
        data = scene.sun.irradiance_w_m2 * 10.0 ** (-0.4 * (np.asarray(self.magnitude) - sun_magnitude))
        sigma = None if self.magnitude_sigma is None else np.asarray(self.magnitude_sigma, float) / MAGNITUDE_PER_LN

        def loaded(j: int) -> Any:
            """The render function at seed index j: one loaded scene, each point's geometry as fixed parameter values."""
            seed = self.seed + j * INDEPENDENT_SEED_OFFSET
            return render_function(scene, [*known, *geometry], seed=seed, seed_grad=seed + 1)

        # the fit's and the independent seeds' are made here, outside the solver's traces; a verdict's further ones when asked
        renders = {0: loaded(0), 1: loaded(1)}

        def model(x: jax.Array, j: int) -> jax.Array:
            if j not in renders:
                renders[j] = loaded(j)
            image, y = renders[j], x[index].astype(float)
            return scale * jnp.stack([jnp.sum(jnp.mean(image(jnp.concatenate([y, g.astype(y.dtype)])), axis=-1) * omega) for g in at])

        return Block(MeasuredValues(data, sigma, True, "W m^-2", "light curve"), model, known, rendered=True)

    def zero_point(self) -> tuple[float, float]:
        """The sun's magnitude in the band (:attr:`sun_magnitude` or the band's) and the scene sun's irradiance."""
        return SUN_MAGNITUDES[self.band] if self.sun_magnitude is None else self.sun_magnitude, self.scene.sun.irradiance_w_m2

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """Each point's first geometry value (:attr:`geometry`)."""
        key = self.geometry[0]
        return np.array([float(p[key]) for p in self.points]), key


def fit_light_curve(
    scene: Scene,
    free: Sequence[str],
    points: Sequence[dict[str, Any]],
    magnitude: Sequence[float],
    magnitude_sigma: Sequence[float] | float | None,
    *,
    band: str = "V",
    sun_magnitude: float | None = None,
    observer_range_m: float | None = None,
    seed: int = 1,
    max_steps: int = 50,
) -> FitResult:
    """Fit the registered parameters ``free`` of a rendered target (materials, attitude angles, ...)
    to an observed light curve (:class:`RenderedLightCurve` of these arguments) with
    :func:`spacefit.fit`, from the scene's values."""
    check_count("max_steps", max_steps, optional=False)
    curve = RenderedLightCurve(scene, points, magnitude, magnitude_sigma, band, sun_magnitude, observer_range_m, seed)
    return fit(curve, free, max_steps=max_steps)
