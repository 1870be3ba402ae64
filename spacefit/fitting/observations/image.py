"""The image kind of observation: a reference image, the scene it was taken in, its noise and
mask, and how its model image and residuals are made (:mod:`spacefit.fitting.observations`).

A fit renders every image of a step in one batch (:func:`spacefit.fitting.problem.setup`); this
module holds what is each image's own: its checks, its unit and its residuals.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import NEGATIVE_SIGMAS, InputError, InputTypeError, check_array, check_count, negative_pixels, quote
from spacefit.formation import dn_fn, noise_variance_terms
from spacefit.fitting.losses import AffineVariance, residual_fn
from spacefit.fitting.result import FitResult
from spacefit.geometry.frames import Intrinsics
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.sensor import Sensor, check_flat, read_sensor_file
from spacefit.units import RADIANCE_UNIT

if TYPE_CHECKING:  # types only: matplotlib loads where a figure is drawn
    from spacefit.plotting import AxesArg, FigureArg


@dataclass(frozen=True)
class Observation:
    """A reference radiance image (h, w, 3), W m^-2 sr^-1, and the scene it was taken in.

    ``sigma``: the reference's noise standard deviation (scalar or per pixel), or None.
    ``sensor``: the camera that measured it, if known: the reference is then in DN (as
    :func:`read_image` gives it), the model is the sensor's
    :func:`expected_dn` of the render, each pixel is weighted by its predicted
    Poisson-Gaussian noise (:func:`noise_variance_dn` at the model's DN, held fixed in derivatives),
    saturated pixels are left out, and the standard errors are the noise model's (J^T W J)^-1
    instead of the sandwich. ``sigma`` must then be None.
    ``mask``: which values to fit, (h, w) or (h, w, channels) bool, True = use (None: all). The
    residuals of the others are 0 in every loss and they count for nothing (not in the degrees of
    freedom, not in the noise floor); they may hold anything, NaN included.
    ``sensor_sources``: where each sensor value came from (field -> "header KEY", "sensor file",
    ...; :func:`sensor_of`), None for a sensor given whole.
    ``notes``: what a report should say about the file (e.g. a row order it did not state).
    ``flat``: with a sensor, a flat-field map ((h, w) or (h, w, channels), > 0) multiplying the
    expected signal above the bias (:func:`expected_dn`); None: uniform.
    ``render_spp``: the samples per pixel a simulated reference was rendered with, whose Monte Carlo
    noise the goodness of fit then expects (the goodness of fit, :attr:`FitResult.goodness`); None: a real
    observation, without render noise.
    :meth:`from_file` reads all of these from an image file (``render_spp`` from a FITS ``RENDSPP``
    card or a spacefit sidecar).

    Raises:
        InputError: a scene that is not a :class:`Scene`, a reference that is not a real array, a
            sigma or mask of another shape, a mask that leaves nothing, ``sigma`` given with a
            ``sensor`` or ``flat`` without one; :func:`fit` checks the reference's size against the scene.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48]})
        >>> observation = sf.Observation(scene, np.zeros((48, 48, 3)), sigma=0.01)  # sf.fit([observation], free)
        >>> observation.sigma
        0.01
    """

    scene: Scene
    reference: np.ndarray
    sigma: float | np.ndarray | None = None
    sensor: Sensor | None = None
    mask: np.ndarray | None = None
    sensor_sources: Mapping[str, str] | None = None
    notes: tuple[str, ...] = ()
    flat: np.ndarray | None = None
    render_spp: int | None = None

    def __post_init__(self) -> None:
        check_scene(self.scene, "Observation.scene")
        check_count("Observation.render_spp", self.render_spp)
        if self.sensor is not None and not isinstance(self.sensor, Sensor):
            raise InputTypeError(f"`Observation.sensor` must be an sf.Sensor or None, got {quote(self.sensor)}.")
        if self.flat is not None and self.sensor is None:
            raise InputError("`Observation.flat` multiplies a sensor's expected DN: give the sensor too (or divide a radiance image by it).")
        if self.sensor is not None and self.sigma is not None:
            raise InputError("`Observation.sigma` must be None when `Observation.sensor` is given: the sensor predicts each pixel's noise.")
        ref = check_array("Observation.reference", self.reference)
        if self.sigma is not None:
            _check_sigma(check_array("Observation.sigma", self.sigma), ref.shape)
        if self.mask is not None:
            mask = check_array("Observation.mask", self.mask, "a bool array")
            if not mask.any():
                raise InputError(f"`Observation.mask` is False everywhere ({mask.size} values): it leaves nothing to fit.")

    @classmethod
    def from_file(
        cls, path: str | Path, scene: Scene, *, sensor: Sensor | Mapping[str, Any] | None = None, unit: str | None = None,
        response: str | None = None, mask: str | Path | np.ndarray | None = None, sigma: float | np.ndarray | None = None,
        sensor_file: str | Path | None = None, sensor_defaults: str | None = None, row_order: str | None = None,
        flat: str | Path | np.ndarray | None = None,
    ) -> Observation:
        """The observation in an image file (EXR, FITS, PNG, TIFF; :func:`read_image`,
        which takes ``unit``, ``response``, ``mask``, ``sigma`` and ``row_order``), with its
        usable-pixel mask (saturated, transparent and user-masked pixels left out).

        Radiance is fitted as radiance (``sigma`` its noise). DN are fitted with their sensor
        (:func:`sensor_of`): ``sensor`` as given (an sf.Sensor), or the file's own
        values (FITS header keywords, spacefit sidecar) replaced by those of the sensor file
        ``sensor_file`` (:func:`read_sensor_file`) and then of a mapping ``sensor``;
        a value the fit needs that none gives is refused unless ``sensor_defaults="illustrative"``.
        The sources are kept in ``sensor_sources``. ``flat``: a flat-field map of a DN image, an
        array or an image file (FITS, or PNG / TIFF read as linear), multiplying the expected
        signal above the bias. A one-channel image is fitted as grey (one
        residual per pixel, against the mean of the render's channels).

        Raises:
            InputError: DN with a sensor value missing (naming each and the three ways to give it),
                a ``sensor`` for radiance or a ``sigma`` for DN, and every refusal of ``read_image``,
                naming the file.
        """
        from spacefit.imageio import read_image, sensor_of  # deferred: FITS and TIFF readers (astropy, tifffile): only files need them

        image = read_image(path, unit=unit, response=response, mask=mask, sigma=sigma, row_order=row_order)
        notes, render_spp = tuple(image.metadata["notes"]), image.metadata.get("render_spp")
        if image.unit == RADIANCE_UNIT:
            if sensor is not None or sensor_file is not None or flat is not None:
                raise InputError(f"{image.path!r} holds radiance ({RADIANCE_UNIT}); `sensor` describes the camera of a DN "
                                 "image: leave it out.")
            return cls(scene, image.data, sigma, mask=image.mask, notes=notes, render_spp=render_spp)
        if sigma is not None:
            raise InputError(f"{image.path!r} holds DN: its noise is its sensor's; leave `sigma` out.")
        from_file = read_sensor_file(sensor_file) if sensor_file is not None else None
        measured, sources = sensor_of(image, sensor, sensor_file=from_file, defaults=sensor_defaults)
        if isinstance(flat, (str, Path)):
            flat = read_image(flat, unit="DN", response="linear", row_order=row_order).data
        relative = None if flat is None else check_flat(flat, image.data.shape, f"the flat field of {image.path!r}")
        return cls(scene, image.data, sensor=measured, mask=image.mask, sensor_sources=sources, notes=notes, flat=relative,
                   render_spp=render_spp)

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """Its chi^2 per value (the noise known) or mean r^2 over the render noise, by part
        (:attr:`FitResult.parts`)."""
        return [line for k in entries for line in part_lines(result, k)]

    def plot(self, result: FitResult, entries: Sequence[int], *, ax: AxesArg = None, fig: FigureArg = None) -> np.ndarray:
        """Its residual image, reference - model (the residual panel of :func:`plot_comparison`), into
        ``ax`` (one Axes) or ``fig``; where the fit has none (a failed solve), the panel says so."""
        from spacefit.fitting.plots import residual_panel  # deferred: matplotlib, which only figures need
        from spacefit.plotting import panels  # deferred: matplotlib, which only figures need

        axes = panels(ax, fig, 1, (4.0, 3.6), lambda f: f.subplots(1, 1, squeeze=False))
        if entries[0] < len(result.residuals):
            residual_panel(axes[0], result, entries[0])
        else:  # not an empty panel: it says why
            axes[0].text(0.5, 0.5, "no residual: the fit has no render", ha="center", va="center", transform=axes[0].transAxes)
        return axes


def part_lines(result: FitResult, k: int) -> list[str]:
    """Image ``k``'s goodness of fit by part, one line (none where the fit has no such row)."""
    parts = result.parts[k] if k < len(result.parts) else {}
    spread = {name: row[key] for name, row in parts.items() for key in ("chi2_per_value", "r2_over_render_noise") if key in row}
    if not spread:
        return []
    what = "chi^2 per value" if result.goodness is not None and result.goodness.noise_known else "mean r^2 / render noise"
    return [f"  {what}, observation {k}: " + ", ".join(f"{name} {value:.3g}" for name, value in spread.items())]


def _check_sigma(sigma: np.ndarray, shape: tuple[int, ...]) -> None:
    """Refuse a noise sigma whose shape is neither a scalar's nor that of the reference (``shape``)
    or of its pixels; its values are checked with the residuals (:func:`~spacefit.fitting.losses.residual_fn`)."""
    if sigma.ndim and sigma.shape not in (shape, shape[:2]):
        raise InputError(f"`Observation.sigma` has shape {sigma.shape}; its reference is {shape}: give one number, "
                         f"(height, width) = {shape[:2]} or {shape}.")


def check_reference(obs: Observation, index: int) -> tuple[np.ndarray, np.ndarray]:
    """The observation's reference as a float32 (h, w, 3) array, or (h, w, 1) for a one-channel
    (grey) image, checked against its scene, with masked-out values set to 0, and its bool mask of
    the values to fit (same shape)."""
    ref = np.asarray(obs.reference, dtype=np.float32)
    w, h = obs.scene.render.resolution
    if ref.ndim == 2:
        ref = ref[..., None]
    if ref.ndim != 3 or ref.shape[:2] != (h, w) or ref.shape[-1] not in (1, 3):
        raise InputError(
            f"reference {index} has shape {ref.shape}, but its scene renders (height, width) = ({h}, {w}) with 1 (grey) "
            "or 3 (RGB) channels; render the reference at the scene's resolution or set `render.resolution`."
        )
    used = np.ones(ref.shape, dtype=bool) if obs.mask is None else _mask(obs.mask, ref.shape, index)
    nonfinite = int(np.any(~np.isfinite(ref) & used, axis=-1).sum())
    if nonfinite:
        raise InputError(f"reference {index} holds NaN or infinite pixels ({nonfinite}); leave them out with its mask "
                         "(`Observation.mask` False there).")
    if obs.sensor is not None:  # DN: bias + gain * electrons, rounded; read noise the only way below the bias
        s = obs.sensor
        read_dn, floor = s.read_noise_electrons * s.gain_dn_per_electron, s.bias_dn - 0.5
        below = negative_pixels(ref - np.float32(floor), read_dn, used)
        if below:
            raise InputError(f"reference {index} holds {below} pixels below {floor - NEGATIVE_SIGMAS * read_dn:g} DN: its "
                             f"sensor's bias ({s.bias_dn:g} DN) less half a DN and {NEGATIVE_SIGMAS:g} sigma of read noise "
                             f"({read_dn:g} DN), which its DN never reach; give the sensor's bias_dn, read_noise_electrons and "
                             "gain_dn_per_electron (a bias-subtracted image has bias_dn = 0), or mask the pixels.")
    elif below := negative_pixels(ref, obs.sigma, used):
        noise = "" if obs.sigma is None else f" by more than {NEGATIVE_SIGMAS:g} of its stated sigma"
        raise InputError(f"reference {index} holds {below} pixels with negative values{noise}: radiance is never negative; give "
                         "the image's noise sigma, or fit the DN it was measured in with its sensor.")
    return np.where(used, ref, np.float32(0.0)), used


def _mask(mask: np.ndarray, shape: tuple[int, ...], index: int) -> np.ndarray:
    """An observation's mask broadcast to its reference's (h, w, c) shape."""
    m = np.asarray(mask)
    m = m[..., None] if m.ndim == 2 else m
    if m.ndim != 3 or m.shape[:2] != shape[:2] or m.shape[2] not in (1, shape[2]):
        raise InputError(f"mask {index} (`Observation.mask`) has shape {m.shape}; its reference is {shape}: give "
                         f"(height, width) = {shape[:2]} or (height, width, channels) = {shape}.")
    return np.broadcast_to(m, shape)


def in_unit_of(obs: Observation, channels: int, intrinsics: Intrinsics) -> Callable[[jax.Array], jax.Array]:
    """A model radiance image (h, w, 3) as the observation sees it: its ``channels`` (a grey image
    sees the mean of the render's channels, which are equal: the scene is grey), in radiance or,
    with a sensor, in the sensor's expected DN."""
    to_dn = (lambda image: image) if obs.sensor is None else dn_fn(obs.sensor, intrinsics, channels, obs.flat)
    if channels == 1:
        return lambda image: to_dn(jnp.mean(image, axis=-1, keepdims=True))
    return to_dn


def image_residual(obs: Observation, reference: np.ndarray, used: np.ndarray, loss: str,
                   descent: bool = False) -> Callable[[jax.Array], jax.Array]:
    """The residuals of a model image in the reference's unit, 0 where ``used`` is False: in
    radiance, or with a sensor, in DN divided by the noise the sensor predicts at the model's DN
    (``descent``: the deviance residuals a solver descends, :mod:`~spacefit.fitting.losses`)."""
    if obs.sensor is None:
        return residual_fn(reference, loss, obs.sigma, used)
    return residual_fn(reference, loss, AffineVariance(*noise_variance_terms(obs.sensor)), used, descent=descent)
