"""The pixel grid's model error of a fitted blur: measured at the result with one supersampled
render, stepped over, what remains bounded and carried in the standard errors (issue 34).

**The pixel-integrated blur.** A detector pixel k integrates the focal-plane image over its area:
``D_k = (L * G * P)(k)``, L the radiance, G the continuous PSF, P the pixel's response (the box
of one pixel) and ``*`` convolution. A render with Mitsuba's box filter gives the pixel-integrated
radiance ``R_k = (L * P)(k)``, so the observation is ``D_k = ((L * P) * G)(k)``: the continuous
PSF acting on the pixel-integrated image, whose Fourier transform on the pixel grid is
``R^(f) G^(f)`` for every frequency the grid carries (|f| < 1/2 cycle per px, below Nyquist),
``G^(f) = exp(-2 pi^2 sigma^2 f^2)`` for a Gaussian: :func:`spacefit.formation.fourier_filter`
with :func:`spacefit.formation.gaussian_transfer`, the fit's blur. Integrating the PSF over the
pixel again (the kernel ``c_m = Phi((m + 1/2) / sigma) - Phi((m - 1/2) / sigma)``, differences
of the normal CDF) would be ``G * P * P``: its variance ``sigma^2 + 1/12`` px^2 per axis, one box
too many (measured on a supersampled panels render at 48 px: a 0.8 px PSF fitted as 0.74 px).

**What the grid cannot carry.** ``R`` holds the pixel-integrated image only at the pixel centres:
its content above the grid's Nyquist frequency (the edges and glints a pixel does not resolve)
folds to below, ``R^(f) = sum_n A(f + n)`` with ``A = (L * P)^``, and the model blurs the folded
parts by ``G^(f)`` where the true image blurs them by ``G^(f + n)`` (Bracewell, "The Fourier
Transform and Its Applications", 3rd ed., ch. 10, sampling and aliasing). No kernel on the pixel
grid is exact: the error depends on the scene below the pixel. On the panels case (noise-free,
a 0.8 px Gaussian applied at 4 to 8 times the resolution, then binned) the blur fitted at 1x is
0.767 px at 32 px, 0.804 at 48 px, 0.771 at 96 px; with the model made at 2x, 0.806, 0.794,
0.797; at 4x, 0.8005 (32 px).

**Measured and carried.** At a fit's result (the pixel loss), for each image whose blur
(``image.blur_sigma_px``) is free, :func:`grid_error_models` renders the fitted scene at
:data:`SUPERSAMPLE` times the resolution per axis with the box filter (the fit's samples per sensor
pixel), twice with independent seeds (the fit's own plus an offset), bins each to :data:`COARSER`
times (the box-filtered render at 2x, the same samples), and :func:`fine_and_grid_models` forms
from them the model at 4x and at 2x (the blur, the shift and the sensor's PSF applied at the fine
scale and then the pixel's response, the box or tent of the fit's filter, :func:`response_matrix`)
and the fit's own model on the pixel grid of the same render's pixel response. The image nuisances
act on the renders, so the models follow the values ``y`` without another render.

*Its render noise.* The fine and grid models of one render share its samples, but not their
noise's fate: the render noise above the grid's Nyquist frequency, which the fine model blurs
away, the grid's model folds to below it, so each render's change ``d_4`` carries a share of the
render noise (measured at 48 px, the coverage study's case at the truth, 8 seeds of one render:
the step's scatter 0.0015 px for the blur, 0.6 of its statistical error; shift y 0.0012 px, 0.4;
attitude z 0.0055 deg, 0.2; the materials 0.02 to 0.06). With the scene's one seed every fit had
drawn the same noise, a bias shared by every exposure (the blur's mean z -0.61 over 20). The two
renders' mean change is stepped over, and its render noise carried as the fit's own is
(:func:`spacefit.fitting.uncertainty.render_meat` of the draw ``(d_a - d_b) / sqrt 2``, through the
sandwich at half weight: the mean of two).

*The step.* The finer model's estimate is where ``J^T r_4(x*) = 0``; with the fit's model linear
about its own estimate x (``J^T r_grid(x) = 0``), ``r_4(y) = r_grid(y) + d_4(y)`` gives the fixed
point ``x* = x + step(d_4(x*))``, ``step(d) = -(J^T J)^-1 J^T d``: :func:`grid_step` iterates it
(each iteration the model made at 4x alone, FFTs at the fine scale, and a product with the Jacobian, no
render; the model made at 2x, the render noise's draw and the feedback once, at x*). One step,
``step(d_4(x))``, overshoots: at the fit's too-narrow blur the grid passes more of what aliases,
so ``d_4`` is larger there than at the answer (noise-free, 32 px below: +0.0362 px where the 4x
model's own minimum is +0.0344; the fixed point +0.0341; in the coverage study at 48 px, where the
steps are 0.021 px, the one step left the blur 0.0027 px wide, 1.2 of its statistical errors).

*Its iterations.* The plain iteration contracts as ``D`` (below) does, each value at its own rate: on the 12-frame pass of
``experiments/bench_pass.py`` up to 0.68 (the shifts y of its last frames, stepped by 4 of their standard errors), so
that 8 iterations left them 0.17 of a standard error short at 128 px (0.03 at 64 px), unflagged; 14 (10) iterations
bring the move under a hundredth of one, and still leave 0.016 (0.013). Anderson's acceleration
(:mod:`spacefit.fitting.fixed_point`) took 7 (6) evaluations and ended 0.0011 (0.0017) of a standard error from a
long plain iteration's fixed point; the single image of ``experiments/bench_fit_process.py`` (a step of a third of a
standard error) 2, as before. Fitting a least-squares combination per frame, or per value, stalls at 0.02 on the 64 px
pass's ``D`` (the shared blur couples the frames). What remains is measured at the end with ``D`` (Newton's step, to
first order: 0.0015 where the long iteration gives 0.0011 at 128 px) and a value further than a hundredth of a standard
error is flagged (:attr:`~spacefit.fitting.status.Status.UNSETTLED`). Measured: experiments/results/pixel_grid/.

*Its feedback.* The step is taken at the fixed point and moves with it: a fit whose blur came out
wide has less of the grid's error to step over. With ``D = d step(d_4(y)) / dy`` at x*, the fixed
point moves by ``(I - D)^-1`` per change of the fit's estimate, so its covariance is the fit's through
that map (:func:`grid_step`: the columns of the image nuisances, on which ``d_4`` depends without
another render, by JAX's forward-mode derivatives of the models, ``jax.linearize``, in one program with
the models at x*; each image's in the values it reads, its own and the shared ones). Measured in the
coverage study (48 px, 55 fits): the blur's
error after the step scattered 1.32 times its error before it (0.00287 and 0.00217 px), ``D`` 0.16 for
the blur at one exposure (its error 1.19 times the fit's); the rendered parameters' columns (the pose,
the materials: d_4 moves with the render too) are not taken (a render at 4x per column and sign).

*What remains.* Write e(S) for the error of the model made at S x (fitted minus truth). If it
falls as S^-p, e(2) = 2^p e(4), and the step from the 2x model to the 4x one,
``step(d_4 - d_2) = e(2) - e(4)`` to first order, is (2^p - 1) e(4): for p = 2, e(4) is a third of
it (:data:`REMAINDER_RATIO`). The covariance carries ``b b^T``, ``b = step(d_4 - d_2) / 3`` at x*
(the two models' difference ``d_4 - d_2``: the 2x and 4x models, the fit's own cancels), in the
values' coordinates, one shared systematic direction. Measured (``experiments/pixel_grid_remainder.py``:
the panels case noise-free, box filter, the truth rendered at 8x, blurred by 0.8 px and shifted by
(0.4, -0.25) px there and binned; the blur, shifts and scale fitted with the model made at 1x, 2x
and 4x from the same render; 2026-11-28, load 5.5):

=========  ==========  ==========  ==========  ======================
32 px      e(1)        e(2)        e(4)        e(4) / (e(2) - e(4))
=========  ==========  ==========  ==========  ======================
blur       -0.03392    +0.00634    +0.00049    +0.08
shift x    -0.00025    -0.00091    -0.00030    +0.49
shift y    +0.00661    -0.00034    +0.00006    -0.15
48 px
blur       +0.00369    -0.00731    -0.00078    +0.12
shift x    -0.00501    +0.00115    -0.00017    -0.13
shift y    +0.00484    +0.00082    +0.00007    +0.10
=========  ==========  ==========  ==========  ======================

(px). The error falls faster than 1/S^2 for the blur (a Gaussian's transfer, not a power, cuts what
aliases) and a third bounds it with room (0.08 and 0.12 of the difference); only the 32 px shift x
is above it, 0.0003 px where the bound gives 0.0002 (the excess a fortieth of a shift's statistical
error in the coverage study). The
one step from the 1x estimate at 48 px was already at its fixed point (-0.00451 either way, the
4x model's minimum -0.00447). The pixel's response is taken
as the render filter's: a detector that integrates over its pixel is modelled with
``render.filter = "box"`` (the default tent adds 1/12 px^2 of blur to the model, which a fitted
PSF width absorbs: 0.75 px for 0.8).

*Its cost.* The models at the fine scales are made on black sky padded to sizes the FFT is fast for
(:func:`~spacefit.formation.fast_pad`: a padded 128 x 128 px image at 4x is 576 and 560 px, not 568 and
556 = 4 x 139), and the sensor's PSF there by the real FFT (a real, even transfer), its transfer formed in
the program (no constant of the padded image's size); both change the models by round-off alone, the
fine blur's transfer having fallen to nothing at the pads (e^-50 at the fine Nyquist frequency for a
0.8 px blur). The fit's own model on the pixel grid is made as in the fit. Each image's two programs
(the changes to the 4x model, for the fixed point's iterations; and at x* those, the change to the 2x
model and the derivatives) take the image's renders and values as operands and its other arrays (the
reference, the mask) too, so that a pass's frames alike share them
(:class:`~spacefit.fitting.frame_models.AlikePrograms`): compiled once, not once a frame, and run two at a time
(:func:`~spacefit.fitting.frame_models.concurrently`; so are the feedback's steps). Measured
in docs/measurements/performance-history.md, "The pixel grid's cost".

*Its black sky.* The blur and shifts are ``factor`` times larger in fine px, and so is the black sky they need lest
light wrap round the FFT's period: the fine models are padded (:func:`fine_pad`) by ``factor`` times their reach at the
fit's result (5 sigma of the blur and the larger shift, :func:`reach_px`) and :data:`PAD_MARGIN_PX` more for the fixed
point's moves (hundredths of a px), or by the fit's pad (:data:`~spacefit.fitting.nuisance.PAD_PX`, 28) where that is
wider: a 0.8 px blur shifted up to 3 px keeps a 128 px image's 32 fine px at 4x, its models and cost as they were. The
fit's pad taken as fine px had covered a reach of 7 px at 4x, and what wraps, past twice the pad, was read by ``d_4``
as the grid's error (16 px at 4x, light at an edge: a 3 px blur shifted 2 px out of the image put 1e-4 of the peak at
the opposite edge, a 4 px blur 9e-4; a 2 px blur nothing above the round-off). A value the iterations move past the
pad makes the model NaN, which :func:`grid_step` refuses with an error naming the values, rather than wrap. The sensor's
PSF at the fine scale (:func:`fine_optics`) is sized there already (its width and Airy radius in fine px).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.fitting.fixed_point import anderson
from spacefit.fitting.frame_models import concurrently
from spacefit.fitting.nuisance import PAD_PX, ImageModel, nuisance_index
from spacefit.fitting.nuisance import image_model as nuisance_model
from spacefit.fitting.observations.image import Observation, in_unit_of
from spacefit.formation import fast_pad, fourier_filter, psf_transfer
from spacefit.geometry.frames import Intrinsics
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
REMAINDER_RATIO = 1.0 / 3.0
"""What remains of the grid's error after the model made at :data:`SUPERSAMPLE`, per the difference of its step and the
:data:`COARSER` model's: e(4) = (e(2) - e(4)) / 3 for an error falling as 1/S^2 (measured to fall faster: module docstring)."""
FIXED_POINT_STEPS = 8
"""At most this many evaluations of the step's fixed point (:func:`grid_step`)."""
FIXED_POINT_TOLERANCE = 0.01
"""The step's fixed point is taken as reached when the estimate of every value's distance to it (:func:`~spacefit.fitting.fixed_point.anderson`'s step)
is within this many standard errors; a value measured further from it at the end is flagged (:func:`unsettled_notes`)."""
MOVES = ("image.blur_sigma_px", "image.shift_x_px", "image.shift_y_px")
"""The image nuisances in px, which scale with the resolution."""
PAD_MARGIN_PX = 1.0
"""px (sensor) added to the blur's and shifts' reach at the fit's result when the fine models' black sky is sized
(:func:`fine_pad`): the fixed point's iterations move the values by hundredths of a px."""
STEPS_PER_FINE_PX = 16  # quadrature points per fine pixel in :func:`response_matrix`


def response_matrix(size: int, factor: int, pixel_filter: str) -> Float[np.ndarray, "n m"]:
    """(size, size * factor): row j averages a fine axis (``factor`` fine px per px) with the
    response of ``pixel_filter`` centred on pixel j, each fine pixel's weight its integral over
    the fine pixel; rows sum to 1 (the response cut at the image's edge)."""
    t = (np.arange(size * factor * STEPS_PER_FINE_PX) + 0.5) / (factor * STEPS_PER_FINE_PX)  # px from the image's edge
    weights = RESPONSES[pixel_filter](t[None, :] - (np.arange(size)[:, None] + 0.5))
    fine = weights.reshape(size, size * factor, STEPS_PER_FINE_PX).sum(axis=-1)
    return fine / fine.sum(axis=1, keepdims=True)


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
    (None: not free, 0)."""
    sigma, dx, dy = (jnp.abs(y[i]) if i is not None else 0.0 for i in moves)
    return GAUSSIAN_RADIUS_SIGMA * sigma + jnp.maximum(dx, dy)


def fine_pad(shape: tuple[int, ...], x: Float[np.ndarray, " n"], moves: Sequence[int | None], factor: int) -> int:
    """The black sky (fine px on every side, a fast size: :func:`~spacefit.formation.fast_pad`) round a render of
    ``shape`` at ``factor`` times the resolution for the image nuisances at values near ``x`` (px): ``factor`` times
    their reach at ``x`` (:func:`reach_px`) and :data:`PAD_MARGIN_PX`, or the fit's pad
    (:data:`~spacefit.fitting.nuisance.PAD_PX`) where that is wider."""
    return fast_pad(shape, max(PAD_PX, math.ceil(factor * (float(reach_px(jnp.asarray(x, dtype=float), moves)) + PAD_MARGIN_PX))))


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
        fine_model = nuisance_model(names, pad)
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
    if names is not None:  # past its black sky it would wrap round: NaN, which grid_step refuses (no host callback: cached)
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
    made at :data:`COARSER` (the render binned). Both are JAX functions, for the caller's programs to trace."""

    renders: Float[Array, "renders H W 3"]
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
    renders = jnp.stack([np.asarray(renderer.render(seed=seed), dtype=np.float32) for seed in seeds])
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


class ImageColumns(Sequence[np.ndarray]):
    """The columns of a (columns, rows) matrix whose rows are images' (``sizes`` each, in order), held as each image's
    block: ``blocks[k]`` = (the columns it has, their rows in image k, (len, sizes[k])), 0 in the others; a column made
    whole when read. Held whole, the pixel grid's derivatives of a pass (a column per image nuisance, a row per pixel of
    every frame) grew as frames^2: 2.7 GB at 48 frames of 128 x 128 px, 5 own values a frame."""

    def __init__(self, count: int, sizes: Sequence[int], blocks: Sequence[tuple[Sequence[int], np.ndarray]]) -> None:
        self.count, self.blocks = count, [(list(columns), rows) for columns, rows in blocks]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, i: int) -> np.ndarray:  # type: ignore[override]
        if not -self.count <= i < self.count:
            raise IndexError(f"column {i} of {self.count}")
        i %= self.count
        out = np.zeros(self.offsets[-1])
        for start, stop, (columns, rows) in zip(self.offsets[:-1], self.offsets[1:], self.blocks):
            if i in columns:
                out[start:stop] = rows[columns.index(i)]
        return out


@dataclasses.dataclass(frozen=True)
class GridChanges:
    """The residuals' changes from the fit's models on the pixel grid to the finer ones, as functions of the free
    values ``y`` (the renders fixed): ``fine(y)``, (renders, rows), each render's change to the model made at
    :data:`SUPERSAMPLE`; ``settled(y, columns)``, the same, the renders' mean change to the model made at
    :data:`COARSER` (rows) and the derivatives of the renders' mean change to the model made at :data:`SUPERSAMPLE`
    in each of the free values ``columns`` (len(columns) of rows, :class:`ImageColumns`; forward mode, no render)."""

    fine: Callable[[np.ndarray], np.ndarray]
    settled: Callable[[np.ndarray, Sequence[int]], tuple[np.ndarray, np.ndarray, Sequence[np.ndarray]]]


@dataclasses.dataclass(frozen=True)
class GridStep:
    """The pixel grid's step of :func:`grid_step`, in the fit's values' coordinates: ``delta``, from the fit's estimate
    to the model made at :data:`SUPERSAMPLE`'s; ``remainder``, the bound on what remains of the grid's error after it;
    ``noise``, one draw of the render noise of the residuals' change; ``feedback``, ``D`` (n x n); ``short``, each
    value's distance from ``x + delta`` to the fixed point, ``(I - D)^-1 (step(d_S(x + delta)) - delta)`` (first order),
    in the standard errors the iterations were scaled by; and ``evaluations``, the changes to the model made at
    :data:`SUPERSAMPLE` its iterations took."""

    delta: np.ndarray
    remainder: np.ndarray
    noise: np.ndarray
    feedback: np.ndarray
    short: np.ndarray
    evaluations: int


def finite(changes: np.ndarray, y: Float[np.ndarray, " n"]) -> np.ndarray:
    """``changes`` (the residuals' changes at the values ``y``), raising where one is not finite: a value whose blur and
    shift reach past the fine models' black sky (sized at the fit's result, :func:`fine_pad`), which would wrap round."""
    if not np.all(np.isfinite(changes)):
        raise RuntimeError(f"the pixel grid's change to a finer model is not finite at the values {np.round(y, 4).tolist()}: "
                           f"a blur or shift moved further than {PAD_MARGIN_PX:g} px from the fit's result, past the black sky "
                           "its finer models were sized for (spacefit.fitting.pixel_grid.fine_pad), or a render is not finite")
    return changes


def grid_step(changes: GridChanges, step: Callable[[np.ndarray], np.ndarray], x: Float[np.ndarray, " n"], stderr: Float[np.ndarray, " n"],
              columns: Sequence[int]) -> GridStep:
    """The step ``delta`` from the fit's estimate ``x`` to the model made at :data:`SUPERSAMPLE`'s, the
    bound on what remains of the grid's error after it (both in x's coordinates), one draw of
    the render noise of the residuals' change and the step's feedback ``D``, all at ``x + delta`` (:class:`GridStep`).
    ``changes``: the residuals' changes from the fit's model to the finer ones (:class:`GridChanges`, the renders' mean
    ``d_S`` to the one made at :data:`SUPERSAMPLE`); ``step(d)``: the Gauss-Newton step of a change ``d`` of the residuals.
    ``delta`` is the fixed point ``x + delta = x + step(d_S(x + delta))`` by Anderson's acceleration
    (:func:`~spacefit.fitting.fixed_point.anderson`) in standard errors ``stderr``; what it leaves, ``short``, is
    measured at ``x + delta`` with ``D`` (in standard errors), a value more than :data:`FIXED_POINT_TOLERANCE` short flagged
    (:func:`unsettled_notes`). The bound is :data:`REMAINDER_RATIO` times
    ``step(d_S - d_C)``, the step from the model made at :data:`COARSER` to the one made at :data:`SUPERSAMPLE`; the
    draw is the two renders' changes' difference over sqrt 2. ``D = d step(d_S(y)) / dy``, n x n, in its ``columns``
    (the image nuisances, on which ``d_S`` depends without another render; the others 0): the fixed point
    ``x* = x + step(d_S(x*))`` moves by ``(I - D)^-1`` per change of the fit's estimate x, so the finer model's
    estimate has the covariance ``(I - D)^-1 C (I - D)^-T`` where the fit's has C: the step's feedback, which a step
    taken as a constant leaves out (measured in the coverage study: the blur's error 1.2 times its pre-step error,
    ``D`` 0.16 for the blur)."""
    scale = np.where(stderr > 0, stderr, 1.0)  # a value without a standard error (no information in the pixels: its step 0) in its units
    delta, evaluations = anderson(lambda y: step(finite(changes.fine(x + y), x + y).mean(axis=0)), scale, FIXED_POINT_STEPS,
                                  FIXED_POINT_TOLERANCE)
    each, coarser, derivatives = changes.settled(x + delta, columns)
    finite(each, x + delta)
    finite(coarser, x + delta)
    feedback = np.zeros((len(x), len(x)))
    # the columns' steps two at a time (each mostly on one core), each column read as its step starts
    for j, moved in zip(columns, concurrently([lambda i=i: step(derivatives[i]) for i in range(len(columns))])):
        feedback[:, j] = moved
    # the distance left, Newton's step: D is the whole derivative of the step's map (which reads the image nuisances alone)
    short = np.linalg.solve(np.eye(len(x)) - feedback, step(each.mean(axis=0)) - delta)
    return GridStep(delta, REMAINDER_RATIO * step(each.mean(axis=0) - coarser), (each[0] - each[1]) / math.sqrt(2.0), feedback,
                    short / scale, evaluations)


def grid_notes(errors: dict[str, float], stderr: dict[str, float]) -> list[str]:
    """A line for each parameter whose pixel-grid step (``errors``, of :func:`grid_step`) is more than
    half its standard error ``stderr`` (which carries the bound on what remains of it)."""
    return [f"{name}: the pixel grid's model error, {d:+.3g} (the fit's model against one made at {SUPERSAMPLE}x the resolution "
            f"at the result), is added to its value; what may remain of it (the step from a model made at {COARSER}x to the "
            f"{SUPERSAMPLE}x one, a third) is carried in its standard error; fit at a finer resolution to shrink it."
            for name, d in errors.items() if name in stderr and abs(d) > 0.5 * stderr[name]]


def unsettled_notes(short: dict[str, float]) -> list[str]:
    """A line for each value whose distance to the pixel grid's fixed point after its step (``short``, in standard
    errors: :attr:`GridStep.short`) is more than :data:`FIXED_POINT_TOLERANCE`; the fit's status is then
    :attr:`~spacefit.fitting.status.Status.UNSETTLED`."""
    return [f"{name}: the pixel grid's step did not settle in {FIXED_POINT_STEPS} evaluations of the model made at {SUPERSAMPLE}x: "
            f"its fixed point is {s:+.2g} standard errors from the value (the tolerance {FIXED_POINT_TOLERANCE:g}); the value and "
            "its error are taken where the iterations stopped."
            for name, s in short.items() if abs(s) > FIXED_POINT_TOLERANCE]
