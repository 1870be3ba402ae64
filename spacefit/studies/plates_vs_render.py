"""The flat plates of a target (:func:`~spacefit.studies.target_plates.target_plates`) against the path
tracer's light curve of the same target, and the choice between the two light-curve models.

:func:`compare_plates_to_render` renders the target at a set of geometries (a sweep: the image's
radiance x pixel solid angle summed) and sets the plates' irradiance beside it (:class:`PlatesVsRender`);
:func:`choose_light_curve_model` measures that difference at a sample of the observations' geometries
and fits a light curve with the plates only where it is below the observations' noise, else with the
path tracer (:class:`ChosenLightCurve`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from spacefit.errors import InputError, check_count, check_range, check_type, check_vector
from spacefit.executors import Cluster, cluster_of
from spacefit.fitting.observations.base import Block
from spacefit.fitting.params import Bijection
from spacefit.fitting.result import FitResult
from spacefit.geometry.frames import attitude_matrix
from spacefit.scene.checks import MAX_COORDINATE_M, deg2rad
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.studies.lightcurve import phase_plane_sun
from spacefit.studies.lightcurve_fit import RenderedLightCurve
from spacefit.studies.lightcurve_kind import LightCurveKind
from spacefit.studies.lightcurve_observations import LightCurveObservations
from spacefit.studies.plate_fit import PlateLightCurve
from spacefit.studies.plates import plates_irradiance
from spacefit.studies.sweep import sweep
from spacefit.studies.target_plates import body_fixed, observation_points, plate_notes, rendered_light_curve, target_plates

# An irradiance below this fraction (10 mag) of a comparison's brightest point is dark: where both are, no
# magnitude is compared (Starlink's second bounce seen from behind, 1e-5 of its peak, beside the plates' 0).
DARK_FRACTION = 1e-4


@dataclass(frozen=True)
class PlatesVsRender:
    """The plates' light curve (:func:`target_plates`)
    against the path tracer's of the same target at the same points.

    Attributes:
        points: the scene values of each point's geometry.
        phase_deg: each point's solar phase angle (deg).
        plates_w_m2, rendered_w_m2: the irradiance at the scene's camera (W m^-2), each point.
        depth, spp: the path tracer's bounces (``render.depth``) and samples per pixel.
        notes: what the plates leave out (:func:`plate_notes`).

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> comparison = sf.compare_plates_to_render(scene, phase_deg=[10, 40])
        >>> comparison.rendered_w_m2.shape, comparison.plates_w_m2.shape
        ((2,), (2,))
    """

    points: tuple[Mapping[str, float], ...]
    phase_deg: np.ndarray
    plates_w_m2: np.ndarray
    rendered_w_m2: np.ndarray
    depth: int
    spp: int
    notes: tuple[str, ...]

    @property
    def compared(self) -> np.ndarray:
        """The points lit in one or both, above :data:`DARK_FRACTION` of the brightest point; where both
        are dark no magnitude is compared."""
        floor = DARK_FRACTION * max(float(np.max(self.plates_w_m2)), float(np.max(self.rendered_w_m2)))
        return (self.plates_w_m2 > floor) | (self.rendered_w_m2 > floor)

    @property
    def difference_mag(self) -> np.ndarray:
        """Plates minus path tracer, magnitudes: -2.5 log10(E_plates / E_rendered) (positive: plates
        fainter; +-inf where one is 0 and the other not); NaN where not :attr:`compared`."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.compared, -2.5 * np.log10(self.plates_w_m2 / self.rendered_w_m2), np.nan)

    @property
    def difference_percent(self) -> np.ndarray:
        """Plates against path tracer, per cent of the path tracer's irradiance (inf where it is 0 and the
        plates not); NaN where not :attr:`compared`."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.compared, 100.0 * (self.plates_w_m2 / self.rendered_w_m2 - 1.0), np.nan)

    @property
    def rms_mag(self) -> float:
        """The RMS of :attr:`difference_mag` over the :attr:`compared` points (inf where one is 0 and the
        other not; NaN where none is compared)."""
        return _rms(self.difference_mag)

    @property
    def rms_percent(self) -> float:
        """The RMS of :attr:`difference_percent` over the :attr:`compared` points (NaN where none is)."""
        return _rms(self.difference_percent)

    @property
    def largest_mag(self) -> float:
        """The largest absolute :attr:`difference_mag` (NaN where no point is :attr:`compared`)."""
        return float(np.max(np.abs(self.difference_mag[self.compared]))) if self.compared.any() else math.nan

    def table(self) -> str:
        """Each point's phase angle, both irradiances and their difference, the RMS, and the notes."""
        lines = [f"{'phase (deg)':>11s} {'plates (W m^-2)':>16s} {'rendered (W m^-2)':>18s} {'diff (mag)':>11s} {'diff (%)':>9s}"]
        for i in range(len(self.points)):
            diff = (f"{self.difference_mag[i]:11.4f} {self.difference_percent[i]:9.2f}" if self.compared[i]
                    else f"{'dark':>11s} {'':>9s}")
            lines.append(f"{self.phase_deg[i]:11.2f} {self.plates_w_m2[i]:16.5g} {self.rendered_w_m2[i]:18.5g} {diff}")
        dark = int((~self.compared).sum())
        lines.append(f"RMS over {int(self.compared.sum())} points: {self.rms_mag:.4f} mag, {self.rms_percent:.2f} %; largest "
                     f"{self.largest_mag:.4f} mag" + (f"; {dark} dark in both (below {DARK_FRACTION:g} of the brightest)"
                                                        if dark else "")
                     + f" (path tracer: depth {self.depth}, {self.spp} spp; plates: one bounce)")
        return "\n".join([*lines, *(f"note: {n}" for n in self.notes)])


def _rms(values: np.ndarray) -> float:
    """The RMS of the values that are not NaN (NaN where there are none)."""
    kept = values[~np.isnan(values)]
    return float(np.sqrt(np.mean(kept**2))) if kept.size else math.nan


def _body_geometry(scene: Scene) -> tuple[np.ndarray, np.ndarray, float]:
    """The directions towards the sun and the camera in the target's body frame, and the camera's range (m)."""
    to_body = attitude_matrix(np.array(deg2rad(scene.target.attitude_deg))).T
    towards = np.array(scene.camera.position_m) - np.array(scene.target.position_m)
    sun = -np.asarray(scene.sun.direction, float)
    return to_body @ (sun / np.linalg.norm(sun)), to_body @ (towards / np.linalg.norm(towards)), float(np.linalg.norm(towards))


def at_range(scene: Scene, range_m: float) -> Scene:
    """``scene`` with its camera moved along its line of sight to ``range_m`` from the target, looking at
    it, the focal length scaled with the range: the same image of the target, seen from further away
    (what the plates assume: an unresolved target, every point of it seeing the observer in one direction)."""
    check_scene(scene)
    check_range("range_m", range_m, 0.0, MAX_COORDINATE_M, lo_open=True, unit="m")
    target = np.array(scene.target.position_m)
    towards = np.array(scene.camera.position_m) - target
    now = float(np.linalg.norm(towards))
    return scene.with_values({"camera.position_m": (target + range_m * towards / now).tolist(), "camera.look_at_m": target.tolist(),
                              "camera.focal_length_mm": scene.camera.focal_length_mm * range_m / now})


def compare_plates_to_render(scene: Scene, *, phase_deg: Sequence[float] | None = None,
                             points: Sequence[Mapping[str, float]] | None = None, range_m: float | None = None,
                             quiet: bool = True, cluster: Cluster | None = None) -> PlatesVsRender:
    """The plates' light curve of ``scene``'s target (:func:`target_plates`) against the path tracer's
    (:func:`sweep`: the image's radiance x pixel solid angle summed, as
    :func:`light_curve` has it), both at the scene's camera with the scene's
    sun irradiance, at either the solar phase angles ``phase_deg`` (the sun turning about the target
    from the camera's direction) or ``points``,
    each a dict of scene values (``{"target.attitude_z_deg": 30.0}``), every one setting the same keys.
    ``range_m`` moves the camera there first (:func:`at_range`): a camera near a specular target sees
    its glint from a spread of directions, the plates from one.

    Args:
        scene: the scene.
        phase_deg: solar phase angles (deg), or ``points``: scene values per point.
        range_m: the observer's distance for the magnitudes (m); None: the camera's.
        quiet: no progress bar.
        cluster: where the renders run: None, this process; N local workers; a scheduler address; a
            dask Client.

    Returns:
        A :class:`PlatesVsRender`.

    Raises:
        InputError: neither or both of ``phase_deg`` and ``points``, a value the scene refuses, a part
            without a BRDF towards an observer.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> comparison = sf.compare_plates_to_render(scene, phase_deg=[10, 40])
        >>> comparison.phase_deg
        array([10., 40.])
    """
    cluster = cluster_of(cluster)
    scene = body_fixed(check_scene(scene))  # type: ignore[arg-type]
    if range_m is not None:
        scene = at_range(scene, range_m)
    if (phase_deg is None) == (points is None):
        raise InputError("give exactly one of `phase_deg` and `points`.")
    if phase_deg is not None:
        angles = check_vector("phase_deg", phase_deg, None)
        for a in angles:
            check_range("phase_deg", a, 0.0, 180.0, hi_open=True, unit="deg")
        sun = phase_plane_sun(scene, angles)
        points = [{key: sun[key][i] for key in sun} for i in range(len(angles))]
    points = _checked_points(points)
    keys = list(points[0])
    ds = sweep(scene, {"point": {key: [float(p[key]) for p in points] for key in keys}}, quiet=quiet, cluster=cluster)
    rendered = np.atleast_1d(np.asarray(ds.irradiance.sel(region="target").values, float))
    plates = target_plates(scene)
    geometry = [_body_geometry(scene.with_values(dict(p))) for p in points]
    sun_b, obs_b = np.array([g[0] for g in geometry]), np.array([g[1] for g in geometry])
    ranges = np.array([g[2] for g in geometry])
    modelled = np.asarray(plates_irradiance(plates, sun_b, obs_b, ranges, scene.sun.irradiance_w_m2))
    phase = np.degrees(np.arccos(np.clip(np.sum(sun_b * obs_b, axis=1), -1.0, 1.0)))
    return PlatesVsRender(tuple(points), phase, modelled, rendered, scene.render.depth, scene.render.spp, plate_notes(scene))


def _checked_points(points: object) -> list[Mapping[str, float]]:
    """``points``: a non-empty list of dicts of scene values, all setting the same keys."""
    if isinstance(points, (str, bytes, Mapping)) or not isinstance(points, Sequence) or not points:
        raise InputError(f"`points` must be a non-empty list of dicts of scene values, got {points!r}.")
    for i, p in enumerate(points):
        check_type(f"points[{i}]", p, Mapping, "a dict of scene values")
        for key, value in p.items():
            check_range(f"points[{i}].{key}", value)
    if any(set(p) != set(points[0]) for p in points):
        raise InputError(f"every point must set the same values, {sorted(points[0])}; got {[sorted(p) for p in points]}.")
    return list(points)


@dataclass(frozen=True, eq=False)
class ChosenLightCurve(LightCurveKind):
    """A light curve fitted with the model :func:`choose_light_curve_model` chose: it is the ``chosen``
    observation (a :class:`PlateLightCurve` or a
    :class:`RenderedLightCurve`) in every way, and its report adds
    which it is and why (:attr:`reason`).

    Attributes:
        chosen: the observation fitted.
        comparison: the plates against the path tracer at a sample of the observations' geometry.
        noise_mag: the observations' noise the difference was held to (mag).
        reason: the choice in words.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> phase = np.radians([20.0, 40.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2]), magnitude_sigma=np.full(2, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (2, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(2, 1.0e6), in_shadow=np.zeros(2, bool), time_utc=None, source="example")
        >>> chosen = sf.choose_light_curve_model(scene, curve, samples=2)
        >>> bool(chosen.reason)  # the choice in words
        True
    """

    chosen: PlateLightCurve | RenderedLightCurve
    comparison: PlatesVsRender
    noise_mag: float
    reason: str

    def parameters(self) -> tuple[str, ...]:
        """The chosen model's parameters."""
        return self.chosen.parameters()

    def start(self, name: str) -> float:
        """The chosen model's value of ``name``."""
        return self.chosen.start(name)

    def block(self, free: tuple[str, ...]) -> Block:
        """The chosen model's residual block."""
        return self.chosen.block(free)

    def coordinate(self, name: str) -> Bijection:
        """The chosen model's coordinate of ``name``."""
        return self.chosen.coordinate(name)

    def zero_point(self) -> tuple[float, float]:
        """The chosen model's band zero point."""
        return self.chosen.zero_point()

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """The chosen model's abscissa."""
        return self.chosen.abscissa(count)

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """The chosen model's lines, and which model it is and why."""
        return [*self.chosen.report(result, entries), f"    {self.reason}"]


def choose_light_curve_model(scene: Scene, observations: LightCurveObservations, *, samples: int = 8,
                             sigma_mag: float | None = None, quiet: bool = True, cluster: Cluster | None = None) -> ChosenLightCurve:
    """The light-curve observation of ``observations`` of ``scene``'s target to fit: the flat plates
    (:class:`PlateLightCurve` of :func:`target_plates`, the scene's sun
    irradiance) where their difference from the path tracer is below the observations' noise, else
    the path tracer (:class:`RenderedLightCurve`).

    The difference is measured (:func:`compare_plates_to_render`) at ``samples`` of the lit
    observations' geometries, spread over their phase angles, with the scene's camera (the target's
    attitude turning each observation's body-frame directions onto it, :func:`observation_points`)
    and the scene's render settings; its RMS in magnitudes is held to the observations' noise, the
    median of their ``magnitude_sigma``, or ``sigma_mag`` where they state none (which the report
    says it assumed). The rendered observation has every lit observation at that geometry, its
    magnitudes carried to their median range by the inverse square law (exact for an unresolved
    target); its attitude angles are the points' geometry, so it cannot free them as the plates can.
    ``cluster``: where the comparison's renders run (:func:`compare_plates_to_render`'s).

    Args:
        scene: the scene of the target (its parts, camera and render settings).
        observations: the measured magnitudes and their geometry.
        samples: the number of geometries the plates are compared with the path tracer at.
        sigma_mag: the observations' noise (mag) where they state none.
        quiet: no progress bar.
        cluster: where the comparison's renders run, as :func:`compare_plates_to_render` takes it.

    Returns:
        A :class:`ChosenLightCurve`, for ``sf.fit([chosen], free)``.

    Raises:
        InputError: observations without errors and no ``sigma_mag``, or none lit.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> phase = np.radians([20.0, 40.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2]), magnitude_sigma=np.full(2, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (2, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(2, 1.0e6), in_shadow=np.zeros(2, bool), time_utc=None, source="example")
        >>> chosen = sf.choose_light_curve_model(scene, curve, samples=2)
        >>> type(chosen.chosen).__name__ in ("PlateLightCurve", "RenderedLightCurve")
        True
    """
    cluster = cluster_of(cluster)
    scene = body_fixed(check_scene(scene))  # type: ignore[arg-type]
    check_type("observations", observations, LightCurveObservations, "an sf.LightCurveObservations (sf.read_light_curve)")
    check_count("samples", samples, 1, optional=False)
    lit = np.flatnonzero(~observations.in_shadow)
    if not lit.size:
        raise InputError(f"every observation of {observations.source} is in the Earth's shadow: there is nothing to fit.")
    if observations.magnitude_sigma is not None:
        if sigma_mag is not None:
            raise InputError(f"`sigma_mag` is {sigma_mag!r}, but the observations state their errors: leave it None.")
        noise = float(np.median(observations.magnitude_sigma[lit]))
        said = f"the observations' median error {noise:.3g} mag"
    elif sigma_mag is None:
        raise InputError(f"the observations {observations.source} state no magnitude errors: give `sigma_mag` (mag), the noise "
                         "the plates-vs-render difference is held to.")
    else:
        noise = check_range("sigma_mag", sigma_mag, 0.0, lo_open=True, unit="mag")
        said = f"an assumed noise of {noise:.3g} mag (sigma_mag; the observations state no errors)"
    obs = observations.subset(lit)
    phase = np.arccos(np.clip(np.sum(obs.sun * obs.observer, axis=1), -1.0, 1.0))
    order = np.argsort(phase, kind="stable")
    sample = order[np.unique(np.round(np.linspace(0, len(order) - 1, min(samples, len(order)))).astype(int))]
    points = observation_points(scene, obs)
    comparison = compare_plates_to_render(scene, points=[points[i] for i in sample], quiet=quiet, cluster=cluster)
    dark = int((~comparison.compared).sum())
    measured = (f"plates - path tracer RMS {comparison.rms_mag:.3g} mag (largest {comparison.largest_mag:.3g}) at "
                f"{int(comparison.compared.sum())} of the observations' geometries" + (f" ({dark} more dark in both)" if dark else "")
                + f" (depth {comparison.depth}, {comparison.spp} spp)")
    if comparison.rms_mag < noise:
        chosen: PlateLightCurve | RenderedLightCurve = PlateLightCurve(target_plates(scene), observations, scene.sun.irradiance_w_m2)
        reason = f"light-curve model: flat plates (sf.target_plates), {measured} < {said}"
    else:
        chosen = rendered_light_curve(scene, observations)
        reason = f"light-curve model: path tracer (sf.RenderedLightCurve), {measured} >= {said}"
    return ChosenLightCurve(chosen, comparison, noise, reason)
