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
(``image.blur_sigma_px``) is free, :func:`~spacefit.fitting.fine_models.grid_error_models` renders the fitted scene at
:data:`~spacefit.fitting.fine_models.SUPERSAMPLE` times the resolution per axis with the box filter (the fit's samples per sensor
pixel), twice with independent seeds (the fit's own plus an offset), bins each to :data:`~spacefit.fitting.fine_models.COARSER`
times (the box-filtered render at 2x, the same samples), and :func:`~spacefit.fitting.fine_models.fine_and_grid_models` forms
from them the model at 4x and at 2x (the blur, the shift and the sensor's PSF applied at the fine
scale and then the pixel's response, the box or tent of the fit's filter, :func:`~spacefit.fitting.fine_models.response_matrix`)
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
0.8 px blur). The blur and shift there are by the real FFT too, as the Hermitian part of their transfer
(:func:`~spacefit.formation.fourier_filter`'s ``real``: the complex FFT's result to the round-off, its
transforms half the work; issue 33's fit: the step's CPU 1.11 -> 1.04 s in its process, its values 1e-12 of a
standard error apart: experiments/results/grid/). The fit's own model on the pixel grid is made as in the fit. Each image's two programs
(the changes to the 4x model, for the fixed point's iterations; and at x* those, the change to the 2x
model and the derivatives) take the image's renders and values as operands and its other arrays (the
reference, the mask) too, so that a pass's frames alike share them
(:class:`~spacefit.fitting.frame_models.AlikePrograms`): compiled once, not once a frame, and run two at a time
(:func:`~spacefit.fitting.frame_models.concurrently`; so are the feedback's steps). Measured
in docs/measurements/performance-history.md, "The pixel grid's cost".

*Its black sky*: the fine models' padding, sized to the blur's and shifts' reach, is described in
:mod:`spacefit.fitting.fine_models`, which makes them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from jaxtyping import Float

from spacefit.fitting.fine_models import COARSER, MOVES, PAD_MARGIN_PX, SUPERSAMPLE, reach_px
from spacefit.fitting.fixed_point import anderson
from spacefit.fitting.frame_models import concurrently, meanwhile
from spacefit.fitting.nuisance import nuisance_index

REMAINDER_RATIO = 1.0 / 3.0
"""What remains of the grid's error after the model made at :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`, per the difference of its step and the
:data:`~spacefit.fitting.fine_models.COARSER` model's: e(4) = (e(2) - e(4)) / 3 for an error falling as 1/S^2 (measured to fall faster: module docstring)."""
FIXED_POINT_STEPS = 8
"""At most this many evaluations of the step's fixed point (:func:`grid_step`)."""
FIXED_POINT_TOLERANCE = 0.01
"""The step's fixed point is taken as reached when the estimate of every value's distance to it (:func:`~spacefit.fitting.fixed_point.anderson`'s step)
is within this many standard errors; a value measured further from it at the end is flagged (:func:`unsettled_notes`)."""


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
    :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`; ``settled(y, columns)``, the same, the renders' mean change to the model made at
    :data:`~spacefit.fitting.fine_models.COARSER` (rows) and the derivatives of the renders' mean change to the model made at :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`
    in each of the free values ``columns`` (len(columns) of rows, :class:`ImageColumns`; forward mode, no render);
    ``settled(y, columns, last=True)``: the same, the renders dropped as each image's are read (the last evaluation: neither
    may be called after it; at 48 frames of 128 x 128 px the renders are 6.3 MiB a frame, and the outputs 2.6);
    ``ahead(y, columns)``: ``settled``'s programs traced and compiled for values shaped as ``y`` and these ``columns``,
    not run (:func:`grid_step` makes them on a thread while the fixed point's iterations run; none: nothing ahead)."""

    fine: Callable[[np.ndarray], np.ndarray]
    settled: Callable[..., tuple[np.ndarray, np.ndarray, Sequence[np.ndarray]]]
    ahead: Callable[[np.ndarray, Sequence[int]], None] | None = None


@dataclasses.dataclass(frozen=True)
class GridStep:
    """The pixel grid's step of :func:`grid_step`, in the fit's values' coordinates: ``delta``, from the fit's estimate
    to the model made at :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`'s; ``remainder``, the bound on what remains of the grid's error after it;
    ``noise``, one draw of the render noise of the residuals' change; ``feedback``, ``D`` (n x n); ``short``, each
    value's distance from ``x + delta`` to the fixed point, ``(I - D)^-1 (step(d_S(x + delta)) - delta)`` (first order),
    in the standard errors the iterations were scaled by; and ``evaluations``, the changes to the model made at
    :data:`~spacefit.fitting.fine_models.SUPERSAMPLE` its iterations took."""

    delta: np.ndarray
    remainder: np.ndarray
    noise: np.ndarray
    feedback: np.ndarray
    short: np.ndarray
    evaluations: int


class PastBlackSky(Exception):
    """The pixel grid's change to a finer model not finite at the values ``tried`` (solver coordinates): a blur or shift
    moved past the black sky the finer models were sized for at the fit's result
    (:func:`~spacefit.fitting.fine_models.fine_pad`), where light would wrap round, or a render is not finite.
    :func:`grid_step` stops there; the fit takes no step, records :func:`past_black_sky` and is
    :attr:`~spacefit.fitting.status.Status.UNSTEPPED`."""

    def __init__(self, tried: Float[np.ndarray, " n"]) -> None:
        super().__init__(f"the pixel grid's change to a finer model is not finite at the values {np.round(tried, 4).tolist()}")
        self.tried = tried


def finite(changes: np.ndarray, y: Float[np.ndarray, " n"]) -> np.ndarray:
    """``changes`` (the residuals' changes at the values ``y``), raising :class:`PastBlackSky` where one is not finite."""
    if not np.all(np.isfinite(changes)):
        raise PastBlackSky(y)
    return changes


def grid_step(changes: GridChanges, step: Callable[[np.ndarray], np.ndarray], x: Float[np.ndarray, " n"], stderr: Float[np.ndarray, " n"],
              columns: Sequence[int]) -> GridStep:
    """The step ``delta`` from the fit's estimate ``x`` to the model made at :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`'s, the
    bound on what remains of the grid's error after it (both in x's coordinates), one draw of
    the render noise of the residuals' change and the step's feedback ``D``, all at ``x + delta`` (:class:`GridStep`).
    ``changes``: the residuals' changes from the fit's model to the finer ones (:class:`GridChanges`, the renders' mean
    ``d_S`` to the one made at :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`); ``step(d)``: the Gauss-Newton step of a change ``d`` of the residuals.
    ``delta`` is the fixed point ``x + delta = x + step(d_S(x + delta))`` by Anderson's acceleration
    (:func:`~spacefit.fitting.fixed_point.anderson`) in standard errors ``stderr``; what it leaves, ``short``, is
    measured at ``x + delta`` with ``D`` (in standard errors), a value more than :data:`FIXED_POINT_TOLERANCE` short flagged
    (:func:`unsettled_notes`); a change not finite at the values tried, past the finer models' black sky, raises
    :class:`PastBlackSky`. The bound is :data:`REMAINDER_RATIO` times
    ``step(d_S - d_C)``, the step from the model made at :data:`~spacefit.fitting.fine_models.COARSER` to the one made at :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`; the
    draw is the two renders' changes' difference over sqrt 2. ``D = d step(d_S(y)) / dy``, n x n, in its ``columns``
    (the image nuisances, on which ``d_S`` depends without another render; the others 0): the fixed point
    ``x* = x + step(d_S(x*))`` moves by ``(I - D)^-1`` per change of the fit's estimate x, so the finer model's
    estimate has the covariance ``(I - D)^-1 C (I - D)^-T`` where the fit's has C: the step's feedback, which a step
    taken as a constant leaves out (measured in the coverage study: the blur's error 1.2 times its pre-step error,
    ``D`` 0.16 for the blur)."""
    scale = np.where(stderr > 0, stderr, 1.0)  # a value without a standard error (no information in the pixels: its step 0) in its units
    # settled's programs traced and compiled on a thread while the iterations' programs run (0.1 s of the 8-parameter fit's
    # wall: docs/measurements/performance.md, "The pixel grid's last programs made ahead")
    with meanwhile(None if changes.ahead is None else lambda: changes.ahead(x, columns)):
        delta, evaluations = anderson(lambda y: step(finite(changes.fine(x + y), x + y).mean(axis=0)), scale, FIXED_POINT_STEPS,
                                      FIXED_POINT_TOLERANCE)
    each, coarser, derivatives = changes.settled(x + delta, columns, last=True)
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


def past_black_sky(names: Sequence[str], x: Float[np.ndarray, " n"], tried: Float[np.ndarray, " n"], images: int) -> dict[str, Any]:
    """What a fit records where :func:`grid_step` stopped at :class:`PastBlackSky` (extras ``pixel_grid_past_black_sky``):
    ``values``, each free blur and shift (``names``, solver coordinates) of the ``images`` whose blur is free, at the
    fit's result ``x`` and at the values ``tried``; ``reach_px``, per image, their reach
    (:func:`~spacefit.fitting.fine_models.reach_px`: 5 sigma of the blur and the larger shift, px) at both, None where
    the blur is not free."""
    values, reach = {}, []
    for k in range(images):
        moves = [nuisance_index(names, n, k) for n in MOVES]
        free = moves[0] is not None
        values.update({names[i]: [float(x[i]), float(tried[i])] for i in moves if i is not None and free})
        reach.append([float(reach_px(np.asarray(v, dtype=float), moves)) for v in (x, tried)] if free else None)
    return {"values": values, "reach_px": reach}


def black_sky_notes(past: dict[str, Any] | None) -> list[str]:
    """The warning of a fit whose pixel-grid step was not taken (``past``, :func:`past_black_sky`'s record; none without
    one): the values tried and each image whose reach grew past its finer models' black sky (sized for the reach at the
    result and :data:`~spacefit.fitting.fine_models.PAD_MARGIN_PX`), or, none grown, a render at
    :data:`~spacefit.fitting.fine_models.SUPERSAMPLE`x not finite; the fit's status is then
    :attr:`~spacefit.fitting.status.Status.UNSTEPPED`."""
    if not past:
        return []
    tried = ", ".join(f"{name} {v[1]:.4g} ({v[0]:.4g} at the result)" for name, v in past["values"].items())
    grown = [f"image {k}'s reach {r[1]:.3g} px ({r[0]:.3g} px at the result)" for k, r in enumerate(past["reach_px"])
             if r is not None and r[1] - r[0] > PAD_MARGIN_PX]
    why = (f"there {', '.join(grown)}: past the black sky its finer models were sized for (the reach at the result and "
           f"{PAD_MARGIN_PX:g} px; the reach is 5 sigma of the blur and the larger shift)" if grown
           else f"there the change is not finite with no reach past the black sky: a render at {SUPERSAMPLE}x is not finite")
    return [f"the pixel grid's step to the model made at {SUPERSAMPLE}x was not taken: its fixed point's iterations tried {tried}; "
            f"{why}. The values and their standard errors are the fit's on the pixel grid, without the step, and carry neither "
            "the grid's model error nor a bound on it; fit at a finer resolution, or with the blur fixed."]
