"""Light curves: what a ground telescope sees of an unresolved target, from sweeps of renders.

The irradiance at the camera's pinhole is the sum over the image of radiance times each pixel's
solid angle (:func:`pixel_solid_angles`), W m^-2, radiance being the mean
of the RGB channels (grey materials: the reflectance in the band is taken equal to it). It is
rendered at the scene's camera range and rescaled to the observer's range by the inverse square law,
E_obs = E (d_rendered / d_obs)^2, exact for an unresolved target (Mitsuba traces in float32, so a far
target is rendered near: ``scene.MAX_COORDINATE_M``).

The apparent magnitude in a band is m = m_sun - 2.5 log10(E_obs / E_sun), with E_sun the sun's
irradiance at the target (``sun.irradiance_w_m2``) and m_sun the sun's apparent magnitude in that
band at the same distance from the sun: the target and the observer are taken at the same
heliocentric distance (1 au for a target near the Earth or the Moon). The V band's m_sun is -26.74
(Cox 2000, Allen's Astrophysical Quantities, 4th ed., section 14.7; Willmer 2018, ApJS 236, 47
gives -26.76). ``AB532`` is lumos-sat's AB magnitude at 532 nm (Fankhauser, Askari & Tyson 2023, AJ
166:59; the band the Starlink observations are compared in): the irradiance read as a flux density
E lambda / c against 3631 Jy, lambda = 532 nm, c = 3e8 m s^-1, with the sun's irradiance 1360 W m^-2,
so m_sun = -2.5 log10(1360 lambda / (c 3631e-26)) = -27.056.

Directions towards the sun and the observer are given as world vectors (3 numbers, from the target
towards them) or as (elevation, azimuth) in degrees in the target's frame: elevation above its x-y
plane, azimuth from its +x towards +y, turned into the world by its attitude (thesis section 3.2).
The solar phase angle is the angle at the target between the directions towards the sun and towards
the observer.

Monte Carlo errors: with ``seeds`` (two or more), each point's irradiance is the mean of the seeds'
renders and carries its standard error, the seeds' standard deviation over sqrt(seeds)
(:func:`sensitivity.mean_and_error`). The magnitude's error follows by the delta
method, sigma_m = 2.5 / ln 10 * sigma_E / E (about 1.086 sigma_E / E); where sigma_E / E is large
that linearisation fails, so :meth:`LightCurve.magnitude_interval` gives the asymmetric interval
m(E + sigma_E), m(E - sigma_E) (the faint side infinite when sigma_E >= E), which the figure draws.
With one seed the error is unknown: NaN in the arrays, "unknown" in the table, no error bars. The
error of a mean falls as 1 / sqrt(seeds): :meth:`LightCurve.seeds_for` says how many seeds a
requested magnitude precision needs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.display import light_curve_html
from spacefit.errors import InputError, check_choice, check_count, check_direction, check_range, check_vector
from spacefit.executors import Cluster, cluster_of
from spacefit.scene.assembly import assemble, body_to_world
from spacefit.scene.parameters import scene_value
from spacefit.scene.conversions import sun_angles_deg, sun_direction
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.studies.axes import in_place_names
from spacefit.studies.lightcurve_sizing import DEFAULT_SEEDS, precise_sweep
from spacefit.studies.sensitivity import mean_and_error
from spacefit.studies.sweep import sweep

if TYPE_CHECKING:  # types only: matplotlib loads where a figure is drawn
    from spacefit.plotting import AxesArg, FigureArg

# The sun's apparent magnitude by band (module docstring gives the source).
SUN_MAGNITUDES = {"V": -26.74, "AB532": -2.5 * math.log10(1360.0 * 532e-9 / (3.0e8 * 3631e-26))}
# d m / d ln E: the magnitude's error per relative error of the irradiance.
MAGNITUDE_PER_LN = 2.5 / math.log(10.0)
SEED_AXIS = "render.seed"


def direction(scene: Scene, value: Sequence[float], name: str) -> np.ndarray:
    """A unit world vector from a world vector (3 numbers) or (elevation, azimuth) in degrees in the
    target's frame (2 numbers)."""
    value = check_vector(name, value, None)
    if len(value) == 2:
        el, az = check_vector(name, value, 2)
        check_range(f"{name} elevation", el, -90.0, 90.0, unit="deg")
        el, az = math.radians(el), math.radians(az)
        local = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        return body_to_world(scene)[:3, :3] @ local
    if len(value) != 3:
        raise InputError(f"`{name}` must be a world vector (3 numbers) or (elevation_deg, azimuth_deg) in the target's "
                         f"frame (2 numbers), got {value.tolist()}.")
    return check_direction(name, value)


def observer_view(scene: Scene, towards: np.ndarray) -> dict[str, Any]:
    """Scene values putting the camera along ``towards`` from the target at the scene's range, looking at it."""
    target = np.array(scene.target.position_m)
    rendered_range = float(np.linalg.norm(np.array(scene.camera.position_m) - target))
    up = np.array(scene.camera.up) if abs(np.dot(scene.camera.up, towards)) < 0.99 * np.linalg.norm(scene.camera.up) else np.eye(3)[0]
    return {"camera.position_m": (target + rendered_range * towards).tolist(), "camera.look_at_m": target.tolist(),
            "camera.up": up.tolist()}


def phase_plane_sun(scene: Scene, phase_deg: np.ndarray) -> dict[str, list[float]]:
    """Sun elevation and azimuth (deg, world, as the registry has them) for each phase angle: the sun
    turns away from the observer's direction towards the camera's image right."""
    camera = assemble(scene).camera
    v = camera.position - np.array(scene.target.position_m)
    v /= np.linalg.norm(v)
    w = camera.right - np.dot(camera.right, v) * v
    w /= np.linalg.norm(w)
    angles = [sun_angles_deg(-(math.cos(a) * v + math.sin(a) * w)) for a in np.radians(phase_deg)]
    return {"sun.elevation_deg": [a[0] for a in angles], "sun.azimuth_deg": [a[1] for a in angles]}


def phase_angles_deg(scene: Scene, dataset: Any) -> np.ndarray:
    """The solar phase angle (deg) at each point of a light curve's sweep (the camera is fixed)."""
    v = np.array(scene.camera.position_m) - np.array(scene.target.position_m)
    v /= np.linalg.norm(v)
    el = dataset["sun.elevation_deg"].values if "sun.elevation_deg" in dataset.coords else scene_value(scene, "sun.elevation_deg")
    az = dataset["sun.azimuth_deg"].values if "sun.azimuth_deg" in dataset.coords else scene_value(scene, "sun.azimuth_deg")
    towards = -np.asarray(sun_direction(el, az), dtype=float)
    return np.degrees(np.arccos(np.clip(np.tensordot(v, towards, axes=1), -1.0, 1.0)))


@dataclass(frozen=True)
class LightCurve:
    """A light curve against one swept quantity.

    Attributes:
        against: what was swept (``phase_angle_deg``, an attitude key, or ``time_s``); ``x`` its values.
        irradiance_w_m2: at the observer, W m^-2 (rescaled from the rendered range), mean over the seeds.
        irradiance_se_w_m2: its Monte Carlo standard error (NaN with one seed: unknown).
        magnitude: apparent magnitude in ``band`` with the sun's ``sun_magnitude``.
        magnitude_se: its standard error by the delta method, 2.5 / ln 10 * se / E (NaN with one seed).
        seeds: the number of independent seeds averaged at each point.
        phase_angle_deg: the solar phase angle of each point.
        rendered_range_m, observer_range_m: camera range rendered and observer range (m).
        sun_irradiance_w_m2: the sun's irradiance at the target.
        dataset: the sweep's Dataset, with ``irradiance_observer``, ``magnitude`` and their ``_se`` added.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> curve = sf.light_curve(scene, phase_deg=[10, 40], quiet=True)
        >>> [round(float(a), 6) for a in curve.phase_angle_deg]
        [10.0, 40.0]
    """

    against: str
    x: np.ndarray
    irradiance_w_m2: np.ndarray
    magnitude: np.ndarray
    phase_angle_deg: np.ndarray
    band: str
    sun_magnitude: float
    rendered_range_m: float
    observer_range_m: float
    sun_irradiance_w_m2: float
    dataset: Any
    irradiance_se_w_m2: np.ndarray
    magnitude_se: np.ndarray
    seeds: int

    def magnitude_interval(self) -> tuple[np.ndarray, np.ndarray]:
        """(bright, faint): the magnitudes at E + se and E - se, an asymmetric one-sigma interval exact
        where the delta method's ``magnitude_se`` is not (faint is inf when se >= E; NaN with one seed)."""
        e, se = self.irradiance_w_m2, self.irradiance_se_w_m2
        with np.errstate(divide="ignore", invalid="ignore"):
            bright = self.sun_magnitude - 2.5 * np.log10((e + se) / self.sun_irradiance_w_m2)
            faint = np.where(se >= e, np.inf, self.sun_magnitude - 2.5 * np.log10((e - se) / self.sun_irradiance_w_m2))
        return bright, faint

    def seeds_for(self, precision_mag: float) -> int:
        """The number of seeds at which every point's magnitude standard error is at most
        ``precision_mag`` (mag), from the errors measured here (which need two or more seeds):
        se falls as 1 / sqrt(seeds), so seeds x (se / precision)^2 at the worst point."""
        check_range("precision_mag", precision_mag, 0.0, lo_open=True, unit="mag")
        if self.seeds < 2:
            raise InputError("the light curve was rendered with one seed, so its error is unknown: run it with `seeds` "
                             "(two or more, e.g. seeds=[1, 2, 3, 4]) to measure the error that `seeds_for` scales.")
        worst = float(np.nanmax(self.magnitude_se)) if np.isfinite(self.magnitude_se).any() else math.inf
        if not math.isfinite(worst):
            raise InputError("no point has a finite magnitude error (the target is dark at every point); "
                             "no number of seeds reaches a precision there.")
        return max(2, math.ceil(self.seeds * (worst / precision_mag) ** 2))

    def table(self) -> str:
        """The light curve as text: each point's phase angle, irradiance and magnitude with their
        standard errors ("unknown" with one seed; an asymmetric interval where it is over 10 % wide)."""
        lines = [f"{self.against:>18s} {'phase (deg)':>11s} {'irradiance (W m^-2)':>28s} {'magnitude ' + self.band:>28s}",
                 f"(mean of {self.seeds} seed{'s' * (self.seeds > 1)}; Monte Carlo standard errors)" if self.seeds > 1
                 else "(one seed: the Monte Carlo error is unknown; run with `seeds` to measure it)"]
        bright, faint = self.magnitude_interval()
        for i in range(len(self.x)):
            e, m = self.irradiance_w_m2[i], self.magnitude[i]
            if self.seeds < 2:
                e_text, m_text = f"{e:.5g} +- unknown", f"{m:.4f} +- unknown"
            else:
                e_text = f"{e:.5g} +- {self.irradiance_se_w_m2[i]:.2g}"
                asymmetric = self.irradiance_se_w_m2[i] > 0.1 * e
                m_text = (f"{m:.4f} -{m - bright[i]:.3f} +{faint[i] - m:.3f}" if asymmetric
                          else f"{m:.4f} +- {self.magnitude_se[i]:.3f}")
            lines.append(f"{self.x[i]:18.6g} {self.phase_angle_deg[i]:11.3f} {e_text:>28s} {m_text:>28s}")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        return light_curve_html(self)

    def figure(self, *, ax: AxesArg = None, fig: FigureArg = None) -> np.ndarray:
        """Irradiance and magnitude (brighter up) against the swept quantity, with one-sigma Monte
        Carlo error bars when more than one seed was run (asymmetric in magnitude): into ``ax``, two
        Axes (irradiance, magnitude) or one (the magnitude, with the irradiance it stands for on a
        second y axis), or ``fig`` (a matplotlib Figure or SubFigure; default: a new one with both
        panels). Returns the array of the axes drawn."""
        from spacefit.plotting import axis_label, log_scale, panels, with_unit  # here: only a figure needs matplotlib (optional; slow to import)

        axes = panels(ax, fig, (1, 2), (9.0, 3.6), lambda f: f.subplots(1, 2))
        irradiance_label = with_unit("irradiance at the observer", "W m^-2")
        known = self.seeds > 1
        bright, faint = self.magnitude_interval()
        faint = np.where(np.isfinite(faint), faint, np.nanmax(np.where(np.isfinite(faint), faint, self.magnitude)) + 1.0)
        magnitude = axes[-1]
        if len(axes) == 2:
            irradiance = axes[0]
            irradiance.errorbar(self.x, self.irradiance_w_m2, yerr=self.irradiance_se_w_m2 if known else None, fmt="o-", capsize=2)
            log_scale(irradiance)
            irradiance.set_ylabel(irradiance_label)
        magnitude.errorbar(self.x, self.magnitude, yerr=np.stack([self.magnitude - bright, faint - self.magnitude]) if known else None,
                           fmt="o-", capsize=2)
        magnitude.invert_yaxis()  # brighter up
        magnitude.set_ylabel(f"apparent {self.band} magnitude (mag; m$_{{sun}}$ = {self.sun_magnitude:.4g})")
        if len(axes) == 1:  # the irradiance each magnitude stands for, on the right
            sun_m, sun_e = self.sun_magnitude, self.sun_irradiance_w_m2

            def irradiance_of(m: np.ndarray) -> np.ndarray:  # the magnitude's definition, inverted
                return sun_e * 10.0 ** (-0.4 * (np.asarray(m) - sun_m))

            def magnitude_of(e: np.ndarray) -> np.ndarray:  # E <= 0, which matplotlib may probe, has no magnitude: clipped
                return sun_m - 2.5 * np.log10(np.maximum(np.asarray(e), np.finfo(float).tiny) / sun_e)

            second = magnitude.secondary_yaxis("right", functions=(irradiance_of, magnitude_of))
            second.set_ylabel(irradiance_label)
        for panel in axes:
            panel.set_xlabel(axis_label(self.against))
        errors = f"1-sigma Monte Carlo errors of {self.seeds} seeds" if known else "one seed: Monte Carlo error unknown"
        if ax is None:
            axes[0].figure.suptitle(f"observer at {self.observer_range_m:.4g} m (rendered at {self.rendered_range_m:.4g} m, "
                                    f"inverse square); {errors}", fontsize=9)
        return axes


def light_curve(
    scene: Scene,
    *,
    phase_deg: Sequence[float] | None = None,
    attitude_deg: Sequence[float] | None = None,
    times_s: Sequence[float] | None = None,
    spin_rate_deg_s: float | None = None,
    axis: str = "z",
    sun: Sequence[float] | None = None,
    observer: Sequence[float] | None = None,
    observer_range_m: float | None = None,
    band: str = "V",
    sun_magnitude: float | None = None,
    store: str | Path | None = None,
    seeds: Sequence[int] | None = None,
    precision: float | None = None,
    quiet: bool = False,
    cluster: Cluster | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
) -> LightCurve:
    """The light curve of ``scene``'s target against one of: the solar phase angle ``phase_deg`` (the sun
    turns about the target from the observer's direction), the attitude angle about ``axis``
    (``attitude_deg``), or time ``times_s`` under a spin of ``spin_rate_deg_s`` about ``axis`` from the
    scene's attitude. ``sun`` / ``observer``: directions towards them (the Studies guide), else the
    scene's; ``observer_range_m``: the observer's distance (default: the rendered one). ``band`` and
    ``sun_magnitude`` (default: :data:`SUN_MAGNITUDES`) give the magnitudes. ``seeds`` averages
    renders of these seeds, two or more giving each point's Monte Carlo standard error (the Studies guide).
    ``precision``: the relative standard error each point's irradiance must reach (0.005: 0.5 %, about
    5.4 mmag), for ``phase_deg`` rendered in this process: each point gets the samples its own error asks
    for, pixel by pixel, measured by pilots (the Studies guide; ``seeds`` default to
    four there), in place of the scene's ``render.spp``; the dataset holds ``irradiance`` by seed and the
    ``samples`` its seeds and ``pilot_samples`` its pilots traced by point. ``cluster`` where its renders run
    (as :func:`sweep` takes it; ``workers`` / ``scheduler``: its deprecated spellings). The rest is
    :func:`sweep`'s.

    Returns:
        A :class:`LightCurve`.

    Raises:
        InputError: none or more than one of ``phase_deg``, ``attitude_deg``, ``times_s``; an unknown
            band or axis; a value the scene refuses; a ``precision`` not in (0, 1), or with fewer than two
            seeds, or with ``attitude_deg``, ``times_s``, a ``store``, a ``cluster`` or a sun that parts follow.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> curve = sf.light_curve(scene, phase_deg=[10, 40], quiet=True)
        >>> curve.magnitude.shape
        (2,)
    """
    check_scene(scene)
    cluster = cluster_of(cluster, workers, scheduler)
    given = [n for n, v in (("phase_deg", phase_deg), ("attitude_deg", attitude_deg), ("times_s", times_s)) if v is not None]
    if len(given) != 1:
        raise InputError(f"give exactly one of `phase_deg`, `attitude_deg`, `times_s` (with `spin_rate_deg_s`); got {given or 'none'}.")
    check_choice("axis", axis, ("x", "y", "z"))
    if sun_magnitude is None:
        sun_magnitude = SUN_MAGNITUDES[check_choice("band", band, SUN_MAGNITUDES)]
    check_range("sun_magnitude", sun_magnitude)
    values: dict[str, Any] = {}
    if sun is not None:
        values["sun.direction"] = (-direction(scene, sun, "sun")).tolist()
    if observer is not None:
        values.update(observer_view(scene, direction(scene, observer, "observer")))
    scene = scene.with_values(values) if values else scene
    rendered_range = float(np.linalg.norm(np.array(scene.camera.position_m) - np.array(scene.target.position_m)))
    observer_range = rendered_range if observer_range_m is None else check_range("observer_range_m", observer_range_m, 0.0,
                                                                                 lo_open=True, unit="m")
    key = f"target.attitude_{axis}_deg"
    if phase_deg is None and scene.target.attitude != "fixed":
        raise InputError(f"a light curve over the target's attitude needs `target.attitude` = \"fixed\"; the scene's "
                         f"{scene.target.attitude!r} law sets the attitude (give phase_deg, or make the law fixed).")
    if phase_deg is not None:
        x = check_vector("phase_deg", phase_deg, None)
        for a in x:
            check_range("phase_deg", a, 0.0, 180.0, hi_open=True, unit="deg")
        against, axes = "phase_angle_deg", {"phase_angle_deg": phase_plane_sun(scene, x)}
    elif attitude_deg is not None:
        x = check_vector("attitude_deg", attitude_deg, None)
        against, axes = key, {key: {key: x.tolist()}}
    else:
        check_range("spin_rate_deg_s", spin_rate_deg_s if spin_rate_deg_s is not None else math.nan, unit="deg s^-1")
        x = check_vector("times_s", times_s, None)
        start = scene.target.attitude_deg["xyz".index(axis)]
        against, axes = "time_s", {"time_s": {key: (start + spin_rate_deg_s * x).tolist()}}
    if precision is not None:
        check_range("precision", precision, 0.0, 1.0, lo_open=True, hi_open=True)
        seeds = DEFAULT_SEEDS if seeds is None else seeds
    if seeds is not None:
        check_vector("seeds", seeds, None)
        for s in seeds:
            check_count("seeds", s, 0, optional=False)
        if precision is not None and len(seeds) < 2:
            raise InputError(f"`precision` needs two or more `seeds` to measure each point's error, got {list(seeds)}.")
        axes[SEED_AXIS] = list(seeds)
    if precision is None:
        ds = sweep(scene, axes, store=store, quiet=quiet, cluster=cluster)
    else:
        points = axes[against]
        if phase_deg is None or store is not None or cluster is not None or not set(points) <= in_place_names(scene):
            raise InputError("`precision` sizes a light curve over `phase_deg`, rendered in this process, of a scene whose "
                             "sun turns alone (no part or body follows it): give phase_deg, no store or cluster, or "
                             "size the samples yourself with `seeds` and `render.spp`.")
        ds = precise_sweep(scene, against, points, list(seeds), float(precision))
    if against in ds.dims:
        ds = ds.assign_coords({against: (against, x, {"units": against.rsplit("_", 1)[1]})})
    irradiance = ds.irradiance.sel(region="target")
    if seeds is None:
        irradiance = irradiance.expand_dims(SEED_AXIS)
    samples = np.moveaxis(irradiance.values, irradiance.dims.index(SEED_AXIS), 0)
    scale = (rendered_range / observer_range) ** 2
    mean, se = mean_and_error(samples) if len(samples) > 1 else (samples[0], np.full(samples.shape[1:], np.nan))
    e_obs, e_se = mean * scale, se * scale
    e_sun = scene.sun.irradiance_w_m2
    with np.errstate(divide="ignore", invalid="ignore"):
        magnitude = sun_magnitude - 2.5 * np.log10(e_obs / e_sun)
        magnitude_se = MAGNITUDE_PER_LN * e_se / e_obs
    dims = [d for d in irradiance.dims if d != SEED_AXIS]
    ds = ds.assign({
        "irradiance_observer": (dims, e_obs, {"units": "W m^-2", "description": f"at the observer, {observer_range:.6g} m, "
                                                                                  "mean over the seeds"}),
        "irradiance_observer_se": (dims, e_se, {"units": "W m^-2", "description": "its Monte Carlo standard error (NaN: one seed)"}),
        "magnitude": (dims, magnitude, {"units": "mag", "description": f"apparent {band} magnitude"}),
        "magnitude_se": (dims, magnitude_se, {"units": "mag", "description": "2.5 / ln 10 * se / E (NaN: one seed)"}),
    })
    phase = np.broadcast_to(phase_angles_deg(scene, ds), x.shape).copy()
    return LightCurve(against, x, e_obs, magnitude, phase, band, float(sun_magnitude), rendered_range, observer_range,
                      e_sun, ds, e_se, magnitude_se, len(samples))
