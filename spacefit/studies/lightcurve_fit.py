"""The rendered light-curve kind of observation: observed magnitudes at given geometries, predicted by
the path tracer (:mod:`spacefit.studies.lightcurve`), and the convenience that fits it alone.

Each point's irradiance is its image's sum of radiance x pixel solid angle, rescaled from its
camera's range to the observer's; the residuals compare ln E with the magnitudes' errors
(0.4 ln 10 sigma_m). A point is a scene: the target's scene with the point's geometry (its camera,
sun and target pose, given as any scene values of them). The points are the frames of one batch
(:func:`spacefit.fitting.render_batches.batched_renders`): one loaded scene on which each point sets its
own view, rendered one after another, their Jacobian columns the bridge's. The model is rendered:
its render noise, measured from renders with independent seeds, enters the fit's goodness and its
errors as an image's does (:func:`spacefit.fitting.uncertainty.covariance`).

A point's irradiance is a flux: any film over the same field of view estimates it without bias (a
film's pixels sum to the integral of radiance over solid angle, :mod:`spacefit.rendering.flux`), and
its render noise falls with the samples traced, not with the pixels. So a fit renders the points on
the coarsest film its magnitudes' errors allow (:func:`film_for_fit`), at the scene's samples per pixel.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_array, check_choice, check_count, check_name_list, check_range, check_type, check_vector, quote
from spacefit.fitting.frames import POSE, POSE_KEYS, VIEW, VIEW_KEYS, FrameSpec, InProcess, share_views
from spacefit.fitting.render_batches import batched_renders
from spacefit.fitting.loop import fit
from spacefit.fitting.resume import Resume
from spacefit.fitting.result import FitResult
from spacefit.fitting.observations.base import Block, MeasuredValues
from spacefit.fitting.residuals import INDEPENDENT_SEED_OFFSET
from spacefit.geometry.frames import pixel_solid_angles
from spacefit.precision import float64
from spacefit.progress import Progress, ProgressCallback
from spacefit.rendering.bridge import seeds_array
from spacefit.rendering.derivatives import check_seed
from spacefit.rendering.memory import check_fit_memory, describe_fit
from spacefit.scene.assembly import assemble
from spacefit.scene.parameters import IMAGE, available, fd_step, scene_value
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.studies.lightcurve import MAGNITUDE_PER_LN, SUN_MAGNITUDES
from spacefit.studies.lightcurve_kind import LightCurveKind

# The fit's film (film_for_fit): the coarsest of the scene's width halved k times, none under MIN_FILM_PX, whose
# render noise at the start (two seeds) is at most RENDER_NOISE_SHARE of the magnitudes' errors (rms over the points):
# the model's noise adds a quarter of the data's variance, which the fit's errors and goodness count (its verdict renders
# at 2 x the samples: spacefit.fitting.goodness.verdict_factor).
MIN_FILM_PX = 16
RENDER_NOISE_SHARE = 0.5

# What a point may set: its camera, sun and target pose, as registered parameters or scene-file values
# (the values a frame sets on a loaded scene it shares, spacefit.fitting.frames).
POINT_KEYS = tuple(sorted({*VIEW, *POSE, *(f"{section}.{key}" for section, keys in (*VIEW_KEYS.items(), *POSE_KEYS.items()) for key in keys)}))


@dataclass(frozen=True, eq=False)
class RenderedLightCurve(LightCurveKind):
    """Observed magnitudes of a rendered target at given geometries.

    Attributes:
        scene: the target; its values are the parameters' own (a fit's default start).
        points: per magnitude, the scene values of its geometry, any of :data:`POINT_KEYS`
            (``{"target.attitude_z_deg": 30.0}``, ``{"sun.elevation_deg": ..., "sun.azimuth_deg": ...}``,
            ``{"camera.position_m": [x, y, z], "sun.direction": [x, y, z]}``), every point setting the same ones.
        magnitude: the observed magnitudes.
        magnitude_sigma: their errors (mag; one for all, or one each), or None: unknown.
        band: the band (``V`` or ``AB532``).
        sun_magnitude: the sun's magnitude in it (None: the band's).
        observer_range_m: the observer's range (None: each point's camera's).
        seed: the renders' seed, in [0, 2^31 - 1] (independent ones: ``seed + 1000 j``).
        film_px: the width (px) of the film the points are rendered on, over the scene's field of
            view (its height and pixel pitch scaled with it), or None: the scene's own film.

    Raises:
        InputError: points that set unknown keys, magnitudes and points of different counts, a bad
            error or band.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> curve = sf.RenderedLightCurve(scene, points=[{"sun.elevation_deg": 80}, {"sun.elevation_deg": 50}],
        ...                               magnitude=[5.0, 5.3], magnitude_sigma=0.05)
        >>> "parts.legs.kd" in curve.parameters()  # what sf.fit([curve], free) may free
        True
    """

    scene: Scene
    points: Sequence[Mapping[str, Any]]
    magnitude: Sequence[float]
    magnitude_sigma: Sequence[float] | float | None
    band: str = "V"
    sun_magnitude: float | None = None
    observer_range_m: float | None = None
    seed: int = 1
    film_px: int | None = None
    scenes: tuple[Scene, ...] = field(init=False, repr=False)  # each point's scene: the target's with its geometry, on the film

    def __post_init__(self) -> None:
        check_scene(self.scene)
        check_choice("band", self.band, SUN_MAGNITUDES)
        if self.sun_magnitude is not None:
            check_range("sun_magnitude", self.sun_magnitude)
        check_seed("seed", self.seed)
        check_count("film_px", self.film_px, 1)
        film = on_film(self.scene, self.film_px)
        magnitude = check_vector("magnitude", self.magnitude, None)
        points = self.points
        if isinstance(points, (str, bytes, Mapping)) or not isinstance(points, Sequence):
            raise InputError(f"`points` must be a list of dicts of scene values, got {quote(points)}.")
        if len(points) != len(magnitude):
            raise InputError(f"`points` and `magnitude` must be as long: {len(points)} points, {len(magnitude)} magnitudes.")
        scenes = []
        for i, p in enumerate(points):
            check_type(f"points[{i}]", p, Mapping, "a dict of scene values")
            for key in p:
                check_type(f"points[{i}] key", key, str, "a scene key (a string)")
                if key not in POINT_KEYS:
                    raise InputError(f"`points[{i}]` sets {key!r}, which is not a point's geometry; a point sets any of {list(POINT_KEYS)}.")
            try:
                scenes.append(film.with_values(dict(p)))
                assemble(scenes[-1])  # the point's view checked: its camera sees the target
            except InputError as err:
                raise type(err)(f"`points[{i}]`: {err}") from None
        if any(set(p) != set(self.geometry) for p in points):
            raise InputError(f"every point must set the same values, {list(self.geometry)}; got {[sorted(p) for p in points]}.")
        object.__setattr__(self, "scenes", tuple(scenes))
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
        """Every parameter of the scene (:func:`available_parameters`) but those the points
        set (named, or moved by a vector they set) and the image nuisances (an irradiance has no pixels)."""
        names = [n for n in available(self.scene) if n not in self.geometry and n not in IMAGE]
        return tuple(n for n in names if len({scene_value(s, n) for s in self.scenes}) == 1)

    def start(self, name: str) -> float:
        """The scene's value of ``name``."""
        return scene_value(self.scene, name)

    def block(self, free: tuple[str, ...]) -> Block:
        """ln E of each point's render against the magnitudes' errors (the guide "BRDF tables and light curves as observations")."""
        known = tuple(n for n in free if n in self.parameters())
        index = np.asarray([free.index(n) for n in known], dtype=int)
        steps = tuple(fd_step(self.scene, n) for n in known)
        specs = share_views([FrameSpec(scene, known, steps, None, None, "prb") for scene in self.scenes])
        if len({repr(scene.to_dict()["target"]) for scene in self.scenes}) > 1:  # the points turn or move the target
            specs = [dataclasses.replace(spec, view_pose=True) for spec in specs]
        intrinsics = assemble(self.scenes[0]).intrinsics
        shape = (intrinsics.height, intrinsics.width, 3)
        # each point's rescaling from its camera's range to the observer's
        ranges = np.array([np.linalg.norm(np.subtract(s.camera.position_m, s.target.position_m)) for s in self.scenes])
        scale = jnp.asarray((ranges / (self.observer_range_m or ranges)) ** 2)
        omega = jnp.asarray(pixel_solid_angles(intrinsics))
        sun_magnitude = SUN_MAGNITUDES[self.band] if self.sun_magnitude is None else self.sun_magnitude
        data = self.scene.sun.irradiance_w_m2 * 10.0 ** (-0.4 * (np.asarray(self.magnitude) - sun_magnitude))
        sigma = None if self.magnitude_sigma is None else np.asarray(self.magnitude_sigma, float) / MAGNITUDE_PER_LN
        images = batched_renders(InProcess(), specs, [index] * len(specs), [shape] * len(specs))

        def model(x: jax.Array, j: int) -> jax.Array:
            seed = self.seed + j * INDEPENDENT_SEED_OFFSET
            runs = images(x, seeds_array(seed, seed + 1))  # the points' images stacked (one run: one shape)
            return scale * jnp.concatenate([jnp.sum(jnp.mean(run.astype(x.dtype), axis=-1) * omega, axis=(1, 2)) for run in runs])

        spp = self.scene.render.spp

        def resampled(factor: int) -> Block:
            return dataclasses.replace(self, scene=self.scene.with_values({"render.spp": factor * spp})).block(free)

        return Block(MeasuredValues(data, sigma, True, "W m^-2", "light curve"), model, known, rendered=True, spp=spp, resampled=resampled)

    def size(self, free: Sequence[str], *, allow_large: bool = False) -> tuple[str, int] | None:
        """The fit's size in words and its estimated peak memory (bytes): its points are the frames of one
        batch (the memory check of an image fit, which refuses a fit this machine cannot hold unless
        ``allow_large``), each seeing the free parameters it depends on."""
        intrinsics, own = assemble(self.scenes[0]).intrinsics, self.parameters()
        columns = sum(name in own for name in free)
        estimate = check_fit_memory(len(self.scenes), intrinsics.width, intrinsics.height, columns, self.scene.render.spp,
                                    allow_large=allow_large)
        words = describe_fit(len(self.scenes), intrinsics.width, intrinsics.height, estimate)
        width, height = self.scene.render.resolution
        if (intrinsics.width, intrinsics.height) != (width, height):
            words += f" (the points rendered over the field of view of the scene's {width} x {height} px film: a flux needs no finer one)"
        return words, estimate

    def zero_point(self) -> tuple[float, float]:
        """The sun's magnitude in the band (:attr:`sun_magnitude` or the band's) and the scene sun's irradiance."""
        return SUN_MAGNITUDES[self.band] if self.sun_magnitude is None else self.sun_magnitude, self.scene.sun.irradiance_w_m2

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """Each point's first geometry value (:attr:`geometry`) that is a number, else its index."""
        for key in self.geometry:
            if all(np.ndim(p[key]) == 0 for p in self.points):
                return np.array([float(p[key]) for p in self.points]), key
        return np.arange(count, dtype=float), "point"


def on_film(scene: Scene, width: int | None) -> Scene:
    """``scene`` on a film ``width`` px wide over the same field of view (None: ``scene``): the height, the
    pixel pitch (or, with ``camera.fov_deg`` given, nothing else) and the principal point's offset scaled."""
    if width is None or width == scene.render.resolution[0]:
        return scene
    w, h = scene.render.resolution
    ratio = width / w
    values: dict[str, Any] = {"render.resolution": [width, max(1, round(h * ratio))],
                              "camera.principal_offset_px": [o * ratio for o in scene.camera.principal_offset_px]}
    if scene.camera.fov_deg == 0.0:
        values["camera.pixel_pitch_mm"] = scene.camera.pixel_pitch_mm / ratio
    return scene.with_values(values)


@float64
def film_for_fit(curve: RenderedLightCurve, free: Sequence[str], start: Mapping[str, float] | None = None) -> RenderedLightCurve:
    """``curve`` on the coarsest film of :data:`MIN_FILM_PX` px or more, the scene's width halved k times,
    whose render noise is at most :data:`RENDER_NOISE_SHARE` of the magnitudes' errors: each candidate's
    points rendered at the start values (the scene's, or ``start``'s) with two independent seeds, the
    noise of one render taken as their difference over sqrt 2, relative, rms over the points against
    each point's error in ln E. ``curve`` itself where none is, where its errors are unknown or where it
    already sets ``film_px``. Renders only the candidates tried, cheapest first (primal renders)."""
    width = curve.scene.render.resolution[0]
    if curve.magnitude_sigma is None or curve.film_px is not None:
        return curve
    known = tuple(n for n in free if n in curve.parameters())
    x = jnp.asarray([(start or {}).get(n, curve.start(n)) for n in known], dtype=jnp.float64)
    widths = sorted({math.ceil(width / 2**k) for k in range(1, 16) if math.ceil(width / 2**k) >= MIN_FILM_PX})
    for candidate in widths:
        coarse = dataclasses.replace(curve, film_px=candidate)
        block = coarse.block(known)
        first, second = (np.asarray(block.model(x, j)) for j in (0, 1))
        noise = np.abs(first - second) / np.sqrt(2.0) / (0.5 * (first + second))
        if np.sqrt(np.mean((noise / block.data.sigma) ** 2)) <= RENDER_NOISE_SHARE:  # sigma: ln E's
            return coarse
    return curve


def fit_light_curve(
    scene: Scene,
    free: Sequence[str],
    points: Sequence[Mapping[str, Any]],
    magnitude: Sequence[float],
    magnitude_sigma: Sequence[float] | float | None,
    *,
    band: str = "V",
    sun_magnitude: float | None = None,
    observer_range_m: float | None = None,
    seed: int = 1,
    film_px: int | None = None,
    max_steps: int = 50,
    start: Mapping[str, float] | None = None,
    allow_large: bool = False,
    progress: ProgressCallback | None = None,
    resume: Resume = Resume(),
    quiet: bool = False,
) -> FitResult:
    """Fit the registered parameters ``free`` of a rendered target (materials, attitude angles, ...)
    to an observed light curve (:class:`RenderedLightCurve` of these arguments) with
    :func:`fit`, from the scene's values or ``start``'s. Its size (points, pixels, estimated
    memory: :meth:`RenderedLightCurve.size`) is said as an image fit's is, and a fit above the memory
    available is refused unless ``allow_large``. The points are rendered on the coarsest film over the
    scene's field of view whose render noise at the start is at most half the magnitudes' errors (a
    flux needs no finer one: docs/reference/light-curves.md; its size said with the fit's), or on ``film_px``'s. ``progress``: called with (step, max_steps) after
    each step (default: a progress display on stderr, none with ``quiet``); ``resume``: the fit's
    checkpoint plumbing (:class:`Resume`), as :func:`fit` takes it.

    Args:
        scene: the scene of the target, at the start values.
        free: registered parameter names.
        points: per observation, the scene values of its geometry (``sun.elevation_deg``, ...).
        magnitude: the observed magnitudes.
        magnitude_sigma: their errors (mag): one for all, one each, or None (unknown).
        band: the magnitudes' band, ``V`` or ``AB532``.
        sun_magnitude: the sun's magnitude in ``band`` (None: the band's).
        observer_range_m: the observer's distance (m; None: the camera's).
        seed: the renders' seed, in [0, 2^31 - 1].
        film_px: the width (px) of the points' film over the scene's field of view (None: the coarsest
            the magnitudes' errors allow; the scene's width: the scene's own film).
        max_steps: the solver's step limit.
        start: start values by name (physical units); None: the scene's.
        allow_large: run a fit above the memory available.

    Returns:
        The :class:`FitResult`.

    Raises:
        InputError: what :class:`RenderedLightCurve` and :func:`fit` refuse.

    Example:
        Not run by the tests (a rendered light curve's fit takes minutes)::

            scene = sf.load_scene("lander.toml")
            points = [{"sun.elevation_deg": e} for e in (80, 60, 40)]
            result = sf.fit_light_curve(scene, ["parts.panels.alpha"], points, [5.0, 5.3, 5.9], 0.05)
    """
    check_count("max_steps", max_steps, optional=False)
    free = check_name_list("free", free)
    curve = RenderedLightCurve(scene, points, magnitude, magnitude_sigma, band, sun_magnitude, observer_range_m, seed, film_px)
    curve = film_for_fit(curve, free, start)
    if progress is None and not quiet:
        progress = Progress(f"light-curve fit {', '.join(free)}")
    return fit(curve, free, max_steps=max_steps, start=start, allow_large=allow_large, progress=progress, resume=resume)
