"""The pixel grid's fine models: an image's model made at :data:`SUPERSAMPLE` and :data:`COARSER` times the
resolution from one supersampled render (the image nuisances and the sensor's PSF at the fine scale, then the pixel's
response), beside the fit's own on the pixel grid, which :mod:`spacefit.fitting.pixel_grid` steps between; the
physics, the measurements and the citations are in its docstring.

*Its black sky.* The blur and shifts are ``factor`` times larger in fine px, and so is the black sky they need lest
light wrap round the FFT's period: the fine models are padded (:func:`fine_pad`) by ``factor`` times their reach at the
fit's result (5 sigma of the blur and the larger shift, :func:`reach_px`) and :data:`PAD_MARGIN_PX` more for the fixed
point's moves (hundredths of a px), or by the fit's pad (:data:`~spacefit.fitting.nuisance.PAD_PX`, 28) where that is
wider: a 0.8 px blur shifted up to 3 px keeps a 128 px image's 32 fine px at 4x, its models and cost as they were. The
fit's pad taken as fine px had covered a reach of 7 px at 4x, and what wraps, past twice the pad, was read by ``d_4``
as the grid's error (16 px at 4x, light at an edge: a 3 px blur shifted 2 px out of the image put 1e-4 of the peak at
the opposite edge, a 4 px blur 9e-4; a 2 px blur nothing above the round-off). A value the iterations move past the
pad makes the model NaN rather than wrap, where :func:`~spacefit.fitting.pixel_grid.grid_step` stops
(:class:`~spacefit.fitting.pixel_grid.PastBlackSky`): the fit takes no step and says so
(:attr:`~spacefit.fitting.status.Status.UNSTEPPED`, the values and their reach in its warning). The sensor's PSF at the fine scale (:func:`fine_optics`) is sized there already (its width and Airy radius in fine px).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.fitting.nuisance import PAD_PX, ImageModel, nuisance_index
from spacefit.fitting.nuisance import image_model as nuisance_model
from spacefit.fitting.observations.image import Observation, in_unit_of
from spacefit.formation import fast_pad, fourier_filter, psf_transfer
from spacefit.geometry.frames import Intrinsics
from spacefit.precision import on_device
from spacefit.psf import GAUSSIAN_RADIUS_SIGMA, psf_reach_px
from spacefit.rendering.renderer import Renderer
from spacefit.scene.schema import Scene
from spacefit.sensor import Sensor

SUPERSAMPLE = 4
"""Fine pixels per sensor pixel and axis of the render that measures the grid's model error (a 0.8 px Gaussian's
transfer at the fine grid's Nyquist frequency, 2 cycles per px, is 1e-22: nothing aliases there)."""
RESPONSES = {"box": lambda t: (np.abs(t) <= 0.5).astype(float), "tent": lambda t: np.clip(1.0 - np.abs(t), 0.0, None)}
"""A pixel's response across one axis (t in px from its centre) for each render filter the check models."""
COARSER = 2
"""Fine pixels per sensor pixel and axis of the second model (the :data:`SUPERSAMPLE` render binned), whose step to the
finer model's bounds what remains after it."""
MOVES = ("image.blur_sigma_px", "image.shift_x_px", "image.shift_y_px")
"""The image nuisances in px, which scale with the resolution."""
PAD_MARGIN_PX = 1.0
"""px (sensor) added to the blur's and shifts' reach at the fit's result when the fine models' black sky is sized
(:func:`fine_pad`): the fixed point's iterations move the values by hundredths of a px."""
STEPS_PER_FINE_PX = 16  # quadrature points per fine pixel in :func:`response_matrix`
RESPONSE_REACH_PX = 1
"""Whole px beyond a pixel's own that every response of :data:`RESPONSES` stays within (the tent's reaches the centres of
its neighbours)."""


@functools.cache
def response_matrix(size: int, factor: int, pixel_filter: str) -> Float[np.ndarray, "n m"]:
    """(size, size * factor): row j averages a fine axis (``factor`` fine px per px) with the
    response of ``pixel_filter`` centred on pixel j, each fine pixel's weight its integral over
    the fine pixel (the midpoint rule, :data:`STEPS_PER_FINE_PX` points: exact for the box and the tent, whose kinks
    fall on a fine pixel's edge at an even ``factor``); rows sum to 1 (the response cut at the image's edge). One
    pixel's weights are integrated and placed along the diagonal (every row's alike but for the cut): for 2x and 4x
    the same bits as integrating every row over the whole axis (6 ms alone at 4x a 128 px image, 48 ms inside a fit: 0.4 ms). Made once per
    arguments (read-only)."""
    steps = factor * STEPS_PER_FINE_PX  # quadrature points per px
    k = np.arange(-RESPONSE_REACH_PX * steps, (RESPONSE_REACH_PX + 1) * steps)  # points from the pixel's own first
    own = RESPONSES[pixel_filter]((k + 0.5) / steps - 0.5).reshape(-1, STEPS_PER_FINE_PX).sum(axis=-1)  # per fine px
    columns = np.arange(size)[:, None] * factor + np.arange(-RESPONSE_REACH_PX * factor, (RESPONSE_REACH_PX + 1) * factor)
    inside = (columns >= 0) & (columns < size * factor)
    fine = np.zeros((size, size * factor))
    fine[np.nonzero(inside)[0], columns[inside]] = np.broadcast_to(own, columns.shape)[inside]
    matrix = fine / fine.sum(axis=1, keepdims=True)
    matrix.setflags(write=False)
    return matrix


def supersampled(scene: Scene, factor: int) -> Scene:
    """``scene`` at ``factor`` times the resolution per axis, the same field of view and principal
    point, with the box filter and as many samples per sensor pixel as its own (at least one per
    fine pixel): a render of about the fit's own cost and memory."""
    w, h = scene.render.resolution
    cam = scene.camera
    values = {"render.resolution": [factor * w, factor * h], "render.filter": "box", "render.spp": max(1, scene.render.spp // factor**2),
              "camera.principal_offset_px": [factor * c for c in cam.principal_offset_px]}
    if not cam.fov_deg:  # a field of view sets the pitch from the width
        values["camera.pixel_pitch_mm"] = cam.pixel_pitch_mm / factor
    return scene.with_values(values)


def fine_optics(sensor: Sensor | None, intrinsics: Intrinsics, factor: int, channels: int) -> Callable[[Array], Array]:
    """The sensor's PSF (its Gaussian and Airy pattern, :func:`~spacefit.formation.psf_transfer`) on
    the grid of ``factor`` times the resolution of ``intrinsics``, padded to a fast size
    (:func:`~spacefit.formation.fast_pad`) and by the real FFT; none without a sensor."""
    if sensor is None:
        return lambda image: image
    fine_sensor = dataclasses.replace(sensor, psf_sigma_px=factor * sensor.psf_sigma_px)
    fine = dataclasses.replace(intrinsics, width=factor * intrinsics.width, height=factor * intrinsics.height,
                               pixel_pitch=intrinsics.pixel_pitch / factor)
    waves = fine_sensor.wavelengths(channels)
    transfers = [psf_transfer(fine_sensor, fine, w) for w in waves]
    pad = max(psf_reach_px(fine_sensor, fine, w) for w in waves)
    if pad == 0:
        return lambda image: image
    pad = fast_pad((fine.height, fine.width), pad)
    # JAX's frequencies: the transfer formed in the program (NumPy's would be constants of the padded image's size in it)
    transfer = lambda fy, fx: jnp.concatenate([t(jnp.asarray(fy), jnp.asarray(fx)) for t in transfers], axis=-1)  # noqa: E731
    return lambda image: fourier_filter(image, transfer, pad, even=True)


def reach_px(y: Float[Array, " n"], moves: Sequence[int | None]) -> Float[Array, ""]:
    """How far (px of ``y``'s scale) the blur and shift of the values ``y`` carry light: 5 sigma of the blur (the
    fit's pad's own measure, :data:`~spacefit.fitting.nuisance.PAD_PX`) and the larger shift; ``moves`` their indices in ``y``
    (None: not free, 0); NumPy's for a NumPy array (no program)."""
    xp = np if isinstance(y, np.ndarray) else jnp
    sigma, dx, dy = (xp.abs(y[i]) if i is not None else 0.0 for i in moves)
    return GAUSSIAN_RADIUS_SIGMA * sigma + xp.maximum(dx, dy)


def fine_pad(shape: tuple[int, ...], x: Float[np.ndarray, " n"], moves: Sequence[int | None], factor: int) -> int:
    """The black sky (fine px on every side, a fast size: :func:`~spacefit.formation.fast_pad`) round a render of
    ``shape`` at ``factor`` times the resolution for the image nuisances at values near ``x`` (px): ``factor`` times
    their reach at ``x`` (:func:`reach_px`) and :data:`PAD_MARGIN_PX`, or the fit's pad
    (:data:`~spacefit.fitting.nuisance.PAD_PX`) where that is wider."""
    return fast_pad(shape, max(PAD_PX, math.ceil(factor * (float(reach_px(np.asarray(x, dtype=float), moves)) + PAD_MARGIN_PX))))


def without_psf(sensor: Sensor | None) -> Sensor | None:
    """``sensor`` with no PSF of its own (its blur applied elsewhere)."""
    return None if sensor is None else dataclasses.replace(sensor, psf_sigma_px=0.0, diffraction=False)


def fine_and_grid_models(fine: Float[Array, "H W c"], pixel_filter: str, x: Float[np.ndarray, " n"], k: int, image_model: ImageModel,
                         fine_units: Callable[[Array], Array], grid_units: Callable[[Array], Array], optics: Callable[[Array], Array],
                         moves: Sequence[int | None], factor: int = SUPERSAMPLE, names: Sequence[str] | None = None,
                         pad: int | None = None) -> tuple[Array, Array]:
    """Observation k's model at ``x`` made twice from ``fine``, a box-filtered render at ``factor``
    times the resolution per axis: the image nuisances and ``optics`` (the sensor's PSF) at the
    fine scale then the response of a pixel of ``pixel_filter`` (:func:`response_matrix`) and
    ``fine_units``; and the fit's own, the pixel response first, then the nuisances on the pixel
    grid and ``grid_units`` (with the sensor's PSF). ``moves``: the indices in ``x`` of the blur
    width and the two shifts (None: not free), which are ``factor`` times larger in fine px. ``names``: the
    free parameters', whose image model (:func:`~spacefit.fitting.nuisance.image_model`) acts at the fine scale
    on ``pad`` fine px of black sky (a fast size; None: :func:`fine_pad` at ``x``, which must then be concrete), the
    model all NaN where the blur's and shifts' reach at ``x`` (:func:`reach_px`) exceeds it (light would wrap round the
    FFT's period); None: ``image_model`` there too."""
    h, w = fine.shape[0] // factor, fine.shape[1] // factor
    if names is not None:
        pad = fine_pad(fine.shape, x, moves, factor) if pad is None else pad
        fine_model = nuisance_model(names, pad, real=True)  # by the real FFT: half the transforms' work, the same to the round-off
    else:
        fine_model = image_model
    rows, cols = (jnp.asarray(response_matrix(n, factor, pixel_filter)) for n in (h, w))
    respond = lambda image: jnp.einsum("iy,yxc,jx->ijc", rows, image, cols)  # noqa: E731
    x = jnp.asarray(x, dtype=float)
    x_fine = x
    for i in moves:
        if i is not None:
            x_fine = x_fine.at[i].multiply(factor)
    image = jnp.asarray(fine, dtype=float)
    finer = fine_units(respond(optics(fine_model(image, x_fine, k))))
    if names is not None:  # past its black sky it would wrap round: NaN, where grid_step stops (no host callback: cached)
        finer = jnp.where(reach_px(x_fine, moves) > pad, jnp.nan, finer)
    return finer, grid_units(image_model(respond(image), x, k))


def binned(image: Float[Array, "H W c"], by: int) -> Float[Array, "h w c"]:
    """``image`` averaged over blocks of ``by`` x ``by`` pixels: a box-filtered render at ``by`` times
    the resolution made the box-filtered render at 1x (the same samples)."""
    h, w, c = image.shape
    return image.reshape(h // by, by, w // by, by, c).mean(axis=(1, 3))


@dataclasses.dataclass(frozen=True)
class GridModels:
    """Image observation k's renders at :data:`SUPERSAMPLE` times the resolution (float32, as rendered) and its
    models made from one of them at the free values ``y`` (:func:`fine_and_grid_models`): ``fine(render, y)``,
    the model made at :data:`SUPERSAMPLE` and the fit's own on the pixel grid; ``coarser(render, y)``, the model
    made at :data:`COARSER` (the render binned). Both are JAX functions, for the caller's programs to trace. ``renders``
    None: dropped after their last use (the pixel grid's last settled evaluation, :class:`~spacefit.fitting.pixel_grid.GridChanges`)."""

    renders: Float[Array, "renders H W 3"] | None
    fine: Callable[[Array, Array], tuple[Array, Array]]
    coarser: Callable[[Array, Array], Array]


def grid_error_models(obs: Observation, scene: Scene, x: Float[np.ndarray, " n"], k: int, names: Sequence[str], channels: int,
                      image_model: ImageModel, grid_units: Callable[[Array], Array], seeds: Sequence[int]) -> GridModels | None:
    """Image observation k's (``obs``; ``scene`` its scene at the values ``x``, ``channels`` its
    reference's) :class:`GridModels` from a render of ``scene`` at :data:`SUPERSAMPLE` times the resolution per
    seed of ``seeds``, as functions of the free values ``y`` (``names``; the renders stay ``x``'s, the image
    nuisances are ``y``'s), the fit's own model in ``grid_units``; None for a pixel filter :data:`RESPONSES` lacks."""
    if scene.render.filter not in RESPONSES:
        return None
    intrinsics = Intrinsics.from_scene(scene)
    fine_units = in_unit_of(dataclasses.replace(obs, sensor=without_psf(obs.sensor)), channels, intrinsics)
    # kept as rendered (float32) while every image's are held, widened where used: 3 MiB less a 128 x 128 px image's render
    # one loaded scene for the seeds' renders (each load costs a scene's set-up, and Mitsuba keeps some of its memory: mitsuba3#1890)
    renderer = Renderer(supersampled(scene, SUPERSAMPLE))
    renders = on_device([np.asarray(renderer.render(seed=seed), dtype=np.float32) for seed in seeds], np.float32)
    moves = [nuisance_index(names, n, k) for n in MOVES]
    optics = {f: fine_optics(obs.sensor, intrinsics, f, channels) for f in (SUPERSAMPLE, COARSER)}
    # the black sky sized at x (static shapes), for the values y near it that the fixed point's iterations try
    pads = {f: fine_pad((f * intrinsics.height, f * intrinsics.width), x, moves, f) for f in (SUPERSAMPLE, COARSER)}

    def fine(render: Float[Array, "H W 3"], y: Array) -> tuple[Array, Array]:
        return fine_and_grid_models(render.astype(float), scene.render.filter, y, k, image_model, fine_units, grid_units,
                                    optics[SUPERSAMPLE], moves, names=names, pad=pads[SUPERSAMPLE])

    def coarser(render: Float[Array, "H W 3"], y: Array) -> Array:
        return fine_and_grid_models(binned(render.astype(float), SUPERSAMPLE // COARSER), scene.render.filter, y, k, image_model,
                                    fine_units, grid_units, optics[COARSER], moves, COARSER, names, pads[COARSER])[0]

    return GridModels(renders, fine, coarser)
