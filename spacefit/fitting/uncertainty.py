"""How far to trust a fit: the sandwich covariance, the delta method (what its values' errors warn of:
:mod:`spacefit.fitting.value_warnings`).

References:
    White, H. (1980), "A heteroskedasticity-consistent covariance matrix estimator and a direct
    test for heteroskedasticity", Econometrica 48(4). MacKinnon & White (1985) for the HC1 factor.
    Conley, T. G. (1999), "GMM estimation with cross sectional dependence", Journal of
    Econometrics 92(1): the spatial HAC estimate of the render noise's share.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.fitting.noise_weight import weight_bias
from spacefit.fitting.normal_equations import by_columns, chunk_for
from spacefit.fitting.nuisance import nuisance_index
from spacefit.fitting.pixel_grid import PastBlackSky, grid_step, past_black_sky
from spacefit.fitting.problem import Setup
from spacefit.fitting.render_seeds import seed_excess, seed_shift
from spacefit.fitting.residuals import Problem, column_owners
from spacefit.precision import on_device
from spacefit.rendering.memory import release_freed_memory
from spacefit.scene.parameters import is_image

@dataclass(frozen=True)
class Linearisation:
    """A problem's residuals at x with the fit's seeds (``r``) and with independent ones (``r_alt``),
    and their Jacobians J1, J2: as linear maps (``J1``, ``J2``: a direction of x to the residuals' change)
    with their transposes (``J1T``, ``J2T``), the products the errors need formed a few columns at a time
    (:func:`~spacefit.fitting.normal_equations.by_columns`), no rows x columns matrix held; or, where every
    value is shared (an image fitted alone: ``owners`` None), as their columns (``held``: J1's and J2's, each
    (n, rows), float64), which the solver's normal equations hold too
    (:func:`~spacefit.fitting.normal_equations.all_shared`): the products are then NumPy's, summed in float64,
    with no program of the maps' transposes or of their products traced and lowered in each process."""

    x: jax.Array
    r: np.ndarray
    r_alt: np.ndarray
    J1: Callable[[jax.Array], jax.Array]
    J2: Callable[[jax.Array], jax.Array]
    J1T: Callable[[jax.Array], jax.Array] | None = None  # None where held
    J2T: Callable[[jax.Array], jax.Array] | None = None
    owners: tuple[int, ...] | None = None  # per value, the image whose residuals alone it moves (column_owners)
    held: tuple[np.ndarray, np.ndarray] | None = None

    def columns(self, fn: Callable[[jax.Array], jax.Array], transposed: Callable[[jax.Array], jax.Array] | None = None) -> np.ndarray:
        """The n x n matrix M whose column j is ``fn(e_j)``, for a map J^T W J that joins no two images'
        residuals in W, applied to one direction per shared value and one per kind of own value
        (:func:`~spacefit.fitting.normal_equations.by_columns`); ``transposed``: M^T's map (None: M is symmetric)."""
        m = np.asarray(by_columns(fn, len(self.x), self.x.dtype, chunk_for(self.r.size), self.owners, transposed), dtype=float)
        release_freed_memory()  # the pages the products' threads freed (rows-long vectors, a pass's 20 to 130 MiB each)
        return m

    def cross(self, weight: Callable[[jax.Array], jax.Array]) -> np.ndarray:
        """sym(J1^T W J2) for a symmetric linear map W of the residuals that joins no two images' residuals."""
        if self.held is not None:
            c1, c2 = self.held
            m = c1 @ np.stack([np.asarray(weight(on_device(c, np.float64)), dtype=float) for c in c2]).T
        else:
            m = self.columns(lambda e: self.J1T(weight(self.J2(e))), lambda e: self.J2T(weight(self.J1(e))))
        return 0.5 * (m + m.T)

    def difference(self, w: np.ndarray) -> np.ndarray:
        """(J1 - J2)^T diag(w) (J1 - J2), for per-residual weights ``w``."""
        if self.held is not None:
            d = self.held[0] - self.held[1]
            return (d * w) @ d.T
        wj = on_device(w, np.float64)

        def difference_column(e: jax.Array) -> jax.Array:
            v = _weighted_difference(wj, self.J1(e), self.J2(e))
            return self.J1T(v) - self.J2T(v)

        return self.columns(difference_column)

    def images(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """J1 v and J2 v, for a direction ``v`` of x."""
        if self.held is not None:
            return self.held[0].T @ v, self.held[1].T @ v
        vj = on_device(v, np.float64)
        return np.asarray(self.J1(vj), dtype=float), np.asarray(self.J2(vj), dtype=float)

    def adjoint(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """J1^T a + J2^T b, for residual changes ``a`` and ``b``."""
        if self.held is not None:
            return self.held[0] @ a + self.held[1] @ b
        return np.asarray(self.J1T(on_device(a, np.float64))) + np.asarray(self.J2T(on_device(b, np.float64)))

    @cached_property
    def information(self) -> np.ndarray:
        """sym(J1^T J2): J^T J estimated free of the Jacobians' own Monte Carlo noise."""
        return self.cross(lambda v: v)

    def step(self, difference: np.ndarray) -> np.ndarray:
        """The Gauss-Newton step -(J^T J)^+ J^T d that a change ``d`` of the residuals moves the estimate
        by, with J^T J as :attr:`information` and J^T as (J1 + J2)^T / 2; 0 in directions it leaves
        undetermined, and for a non-finite ``d``."""
        if not np.all(np.isfinite(difference)):
            return np.zeros(len(self.x))
        return -_pseudo_inverse(self.information)[0] @ (0.5 * self.adjoint(difference, difference))


def linearise(problem: Problem, x: np.ndarray) -> Linearisation:
    """The problem's :class:`Linearisation` at ``x`` (physical units): one Jacobian render per seed, the independent
    seeds' begun while the fit's seeds' tangents are traced (:meth:`~spacefit.fitting.residuals.Problem.render_ahead`);
    the Jacobians' columns held where every value is shared (:func:`~spacefit.fitting.residuals.column_owners` None)."""
    xj = on_device(x, np.float64)
    problem.render_ahead(xj, 1)
    r, J1 = problem.linearised(xj, 0)
    r_alt, J2 = problem.linearised(xj, 1)
    owners, dtype = column_owners(problem.free, problem.blocks), r.dtype
    r, r_alt = np.asarray(r, dtype=float), np.asarray(r_alt, dtype=float)
    if owners is None:  # one column at a time: vmapped, JAX batched the tangent's program anew in each process (0.2 s of CPU)
        eye = [on_device(e, np.float64) for e in np.eye(len(x))]
        held = tuple(np.stack([np.asarray(J(e), dtype=float) for e in eye]) for J in (J1, J2))
        # the pages the solve freed handed back, as the products by columns do (Linearisation.columns): kept, the pixel
        # grid's programs at 4x came on top of them (the 8-parameter observation fit's peak 120 MiB higher)
        release_freed_memory()
        return Linearisation(xj, r, r_alt, J1, J2, held=held)
    # the transposes take the residuals' dtype (float32 renders: J^T v sums in float32, ~1e-6 relative)
    J1T, J2T = ((lambda v, t=jax.linear_transpose(J, xj): t(v.astype(dtype))[0]) for J in (J1, J2))
    return Linearisation(xj, r, r_alt, J1, J2, J1T, J2T, owners)


def _pseudo_inverse(information: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pseudo-inverse of J^T J (eigenvalues not clearly positive left out), its eigenvalues, its
    eigenvectors and which eigenvalues were left out."""
    eigval, eigvec = np.linalg.eigh(information)
    tiny = eigval <= 1e-9 * max(np.abs(eigval).max(), 1e-300)
    return (eigvec[:, ~tiny] / eigval[~tiny]) @ eigvec[:, ~tiny].T, eigval, eigvec, tiny


def covariance(problem: Problem, x: np.ndarray,
               lin: Linearisation | None = None) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """Covariance of the estimate at ``x`` (physical units), the loss, the eigenvalues of the
    Fisher information (J^T J) / s^2 under uniform noise, and the correction that takes the fit's
    ``x`` to the estimate the covariance is of (0 where a direction is undetermined).

    The covariance is the heteroscedasticity-consistent "sandwich" (White 1980, with the HC1
    small-sample factor), (J^T J)^-1 J^T diag(r^2) J (J^T J)^-1: glints make the image noise
    largest in the pixels where the Jacobian is largest, and the uniform-noise form s^2 (J^T J)^-1
    understated the scatter of the estimates threefold (D 6.6 of its standard errors off in the
    wrinkles case; 2.3 with the sandwich). Monte Carlo noise in the Jacobian columns would add to
    J^T J as if it were information and shrink the errors, so the products are estimated from two
    Jacobians with independent seeds, sym(J1^T W J2). Rows where neither the residual nor the
    Jacobian is non-zero (black sky) carry no information and are not counted in the degrees of
    freedom. Directions the images do not constrain (eigenvalues of sym(J1^T J2) that are not
    clearly positive) give infinite variance to every parameter they touch.

    With the noise known (``problem.noise_known``: every observation has a sensor, each residual is
    divided by its predicted noise), the residuals are unit normal at the truth and the covariance
    is the noise model's own, sym(J1^T J2)^-1, with no scale estimated from the residuals, plus
    the part of the fit's own render noise (not in the sensor's model; measured at 32 spp it made
    the errors 1.4 to 2.1 times the noise model's): :func:`render_meat` of the render noise
    (r - r_alt) / sqrt(2), r_alt rendered with independent seeds, with its correlation between
    neighbouring pixels (spatial HAC); and the Monte Carlo noise of the
    Jacobian the fit steered by, which moves the point where J^T r = 0 by (J^T J)^-1 dJ^T r: per
    residual r^2 (J1 - J2)(J1 - J2)^T / 2 through the same bread.

    The fit's minimum of 0.5 |r|^2 is biased: the loss's expectation holds the render noise's own
    variance, which the parameters change (a wider PSF smooths the render noise away, so the PSF
    width came out 0.8 of its standard error too wide, README), and the noisy Jacobian the fit
    steers by shares the render's seed. The estimate is therefore the root of the unbiased
    estimating equation 0.5 (J1^T r_alt + J2^T r) = 0 (each Jacobian against the other seed's
    residuals), one Gauss-Newton step from ``x`` (the returned correction); it averages the two
    seeds' render and Jacobian noise, so those two terms enter the covariance at half weight.

    Without a known noise the same estimate holds (the bias is the model's render noise, whatever the
    data's), and the meat is :func:`render_meat` of the two seeds' mean residual at that root,
    (r + r_alt) / 2 + (J1 + J2) c / 2 (with the HC1 factor): its variance per value is the data's
    noise plus half the fit's render noise, the terms of the equation's variance, and their
    correlation between neighbouring pixels is counted as the render noise's is. Measured on two views
    of the panels case (references at 256 spp, fits at 64, 16 seeds; docs/measurements/validation.md):
    the fit's own minimum with the per-residual r^2 meat put the values' rms error at 2.3 to 7.8 of
    their standard errors, one render's firefly pulling an attitude 8 standard errors off. A value
    observation's values count alone (:func:`_unknown_noise_draw`). The Jacobian's noise enters as
    with the noise known.

    ``lin``: the problem's :func:`linearise` at ``x`` where the caller has it.
    """
    lin = linearise(problem, x) if lin is None else lin
    r, r_alt, n = lin.r, lin.r_alt, len(x)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(lin.information))):
        return np.full((n, n), np.nan), math.nan, np.full(n, np.nan), np.zeros(n)
    bread, eigval, eigvec, tiny = _pseudo_inverse(lin.information)
    # a row no parameter moves shows as 0 in J1 times a random direction (with probability 1)
    probe = lin.images(np.random.default_rng(0).normal(size=n))[0]
    informative = int(((probe != 0) | (r != 0)).sum())
    dof = max(informative - len(x), 1)
    s2 = float(r @ r) / dof
    # the fit stops where J^T r = 0 for its noisy J, off by (J^T J)^-1 dJ^T r, whose covariance per
    # row is r^2 (J1 - J2)(J1 - J2)^T / 2
    jacobian_noise = 0.5 * lin.difference(r**2)
    correction = -bread @ (0.5 * lin.adjoint(r_alt, r))
    if problem.noise_known:
        # the observation's noise, (J^T J)^-1, plus the fit's own render noise, per residual
        # (r - r_alt)^2 / 2 from the two seeds, and the Jacobian's, both at half weight
        noise = render_meat(lin.cross, (r - r_alt) / math.sqrt(2.0), problem, x) + jacobian_noise
        cov, s2 = bread + 0.5 * bread @ noise @ bread, 1.0
    else:
        # the data's noise and half the render noise: the two seeds' mean residual at the root
        mean = 0.5 * (r + r_alt + sum(lin.images(correction)))
        meat = render_meat(lin.cross, _unknown_noise_draw(problem, mean, r, informative, dof), problem, x)
        cov = bread @ (meat + 0.5 * jacobian_noise) @ bread
    if tiny.any():
        touched = np.any(np.abs(eigvec[:, tiny]) > 1e-6, axis=1)
        cov[touched, :] = np.inf
        cov[:, touched] = np.inf
        correction = np.zeros(len(x))  # a step in the determined directions alone would move the undetermined
    return cov, 0.5 * float(r @ r), np.clip(eigval, 0.0, None) / s2, correction


# one program: run operation by operation (the products are), two single-operation programs
@jax.jit
def _weighted_difference(w: jax.Array, a: jax.Array, b: jax.Array) -> jax.Array:
    """``w * (a - b)``."""
    return w * (a - b)


def _unknown_noise_draw(problem: Problem, mean: np.ndarray, r: np.ndarray, informative: int, dof: int) -> np.ndarray:
    """Per residual, a draw of its noise for the sandwich's meat where the noise is not known: an image's
    pixel the two seeds' ``mean`` residual (heteroscedastic: glints), with the HC1 factor ``informative / dof``
    on its square; a value observation's value 1 where its errors are stated, else the root of its block's
    sum of squares of the fit's residuals ``r`` over its degrees of freedom (the errors then scale as
    s^2 (J^T J)^-1: one unknown noise level per table)."""
    d, offset = mean * math.sqrt(informative / dof), problem.pixels
    for block in problem.blocks:
        rows = slice(offset, offset + block.data.value.size)
        offset = rows.stop
        if block.noise_known:
            d[rows] = 1.0
        else:
            d[rows] = math.sqrt(float(r[rows] @ r[rows]) / max(rows.stop - rows.start - len(block.known), 1))
    return d


def render_meat(cross: Callable[[Callable[[jax.Array], jax.Array]], np.ndarray], d: np.ndarray, problem: Problem,
                x: np.ndarray) -> np.ndarray:
    """The fit's render noise through the sandwich's meat: a spatial HAC estimate (Conley 1999)
    with a flat kernel, sym(sum_i s1_i sum_{j near i} s2_j^T) with s_i = sum over pixel i's channels
    of J_i d_i, j within :func:`noise_reach_px` of i (Chebyshev distance). One path lights all
    channels of a pixel, and the pixel filter and the PSF spread a sample's noise over the
    neighbours; a per-residual variance, or blocks of 4 x 4 px, missed 40 to 60 % of that
    covariance (measured on the panels case with a 1 px PSF, where neighbours 1, 2, 3 px apart
    share 83, 47, 18 % of their render noise). ``d`` is one draw of the render noise per residual,
    (r - r_alt) / sqrt(2); ``cross(W)`` is sym(J1^T W J2) for a symmetric linear map W of the
    residuals, here v -> d * (the box sum over the reach of the per-pixel sums of d * v). The values
    after the images' pixels (value observations), and every residual where they are not laid out
    as pixels (the losses that are not per pixel), count alone: W is d^2 v there."""
    shapes = [np.shape(ref) for ref in problem.references]
    laid_out = problem.pixels if problem.pixels + sum(b.data.value.size for b in problem.blocks) == d.size else 0
    images = shapes if laid_out else []
    sizes = [2 * noise_reach_px(problem, x, k) + 1 for k in range(len(images))]
    dj, shaped = on_device(d, np.float64), tuple(tuple(shape) for shape in images)
    return _psd_part(cross(lambda v: _near_weighted(shaped, tuple(sizes), dj, v)))


# one program, its draw an operand: run operation by operation (the products are), some 12 single-operation programs per fit
@functools.partial(jax.jit, static_argnums=(0, 1))
def _near_weighted(images: tuple[tuple[int, ...], ...], sizes: tuple[int, ...], d: jax.Array, v: jax.Array) -> jax.Array:
    """:func:`render_meat`'s W v: per image (its ``images`` shape, laid out first in order), ``d`` times the box sum over
    ``sizes`` px of the per-pixel sums of ``d * v``; after the images, ``d^2 v``."""
    parts, offset = [], 0
    for shape, size in zip(images, sizes):
        rows = slice(offset, offset + int(np.prod(shape)))
        offset = rows.stop
        per_pixel = (d[rows] * v[rows]).reshape(shape).sum(axis=2)
        reach = (size - 1) // 2
        near = jax.lax.reduce_window(per_pixel, 0.0, jax.lax.add, (size, size), (1, 1), ((reach, reach), (reach, reach)))
        parts.append(d[rows] * jnp.repeat(near.reshape(-1), shape[2]))
    return jnp.concatenate([*parts, d[offset:] ** 2 * v[offset:]])


def noise_reach_px(problem: Problem, x: np.ndarray, k: int) -> int:
    """How far apart (px, Chebyshev) two pixels of observation k may share render noise: pixels
    closer than twice the pixel filter's radius share samples, and a blur of rms width sigma (the
    sensor's PSF and a free ``image.blur_sigma_px`` at ``x``, in quadrature) correlates the noise
    over about 2 sqrt(2) sigma more (twice the width of the blur's autocorrelation)."""
    filter_radius, blur = problem.noise_spread_px[k]
    i = nuisance_index(problem.free.names, "image.blur_sigma_px", k)
    sigma = math.hypot(blur, 0.0 if i is None else float(x[i]))
    return max(0, math.ceil(2.0 * filter_radius - 1.0 + 2.0 * math.sqrt(2.0) * sigma))


def _psd_part(m: np.ndarray) -> np.ndarray:
    """A symmetric matrix less its negative part: a cross form sym(a^T b) of two independent
    estimates is not positive semi-definite by construction."""
    m_val, m_vec = np.linalg.eigh(m)
    return (m_vec * np.clip(m_val, 0.0, None)) @ m_vec.T


def map_covariance(T: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Delta method: covariance of y(x) from that of x, with T = dy/dx; undetermined stays undetermined."""
    undetermined = ~np.isfinite(np.diag(cov))
    out = T @ np.where(np.isfinite(cov), cov, 0.0) @ T.T
    touched = np.any(np.abs(T[:, undetermined]) > 0, axis=1)
    out[touched, :] = np.inf
    out[:, touched] = np.inf
    return out


def stderr_corr(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stderr = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(stderr, stderr)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    return stderr, corr


def estimate(s: Setup, x: np.ndarray, correct: bool = True) -> tuple[np.ndarray, np.ndarray, float, dict[str, Any]]:
    """User-facing values, their covariance, the loss and extras at solver values ``x``: the
    values are ``x`` moved by :func:`covariance`'s correction for the render noise's bias (where
    ``correct`` and it keeps every value in its range; extras ``noise_bias_correction``, solver
    coordinates). A fit that never moved passes ``correct=False``: its values are its start. With
    a blur width free (the pixel loss), the values take the step ``delta`` from the fit's model on the pixel grid to
    one made at 4x the resolution (:func:`~spacefit.fitting.pixel_grid.grid_step`; extras ``pixel_grid_error``,
    solver coordinates; skipped where it would leave a range; ``pixel_grid_evaluations``, its fixed point's iterations,
    and where taken ``pixel_grid_short``, each value's distance to the fixed point in standard errors; none of them, and
    the values and covariance the fit's on the pixel grid, where its iterations reach past the finer models' black sky:
    extras ``pixel_grid_past_black_sky``, :func:`~spacefit.fitting.pixel_grid.past_black_sky`), and the
    covariance carries ``b b^T``, ``b``
    the bound on what remains of the grid's error after it (a third of the step from the model made at 2x
    to the one made at 4x; extras ``pixel_grid_remainder``, its magnitude), and the step's render noise
    (two renders at 4x, their change's difference through :func:`render_meat` at half weight); the
    covariance of the step's fixed point is the fit's through ``(I - D)^-1``, ``D`` how the step moves
    with the image nuisances it is taken at (also :func:`~spacefit.fitting.pixel_grid.grid_step`). Where no noise is given
    (no sensor or ``sigma``: the residuals are the noise's basis) and the fit moved, the render-seed check (:mod:`spacefit.fitting.render_seeds`)
    adds to each value's variance what fresh renders measure of its own renders' error beyond the render noise the
    sandwich carries (extras ``render_seed_shift``, the step to the fresh renders, and ``render_seed_widened``, the
    factor each standard error grew by; user coordinates). With a sensor, extras ``noise_weight_bias``: the bias its noise
    weights, taken at the fit's noisy renders, leave in each value (:mod:`spacefit.fitting.noise_weight`; user units)."""
    lin = linearise(s.problem, x)
    cov, loss_value, fisher, correction = covariance(s.problem, x, lin)
    if correct and all(b.contains(float(v)) for b, v in zip(s.solver_params.bijections, x + correction)):
        x = x + correction
    else:
        correction = np.zeros(len(x))
    extras: dict[str, Any] = {"fisher_eigenvalues": fisher.tolist(),
                              "noise_bias_correction": dict(zip(s.solver_params.names, correction.tolist()))}
    if (bias := weight_bias(s.problem, lin.r, lin.r_alt, lin.step)) is not None and correct:  # flagged, not subtracted
        extras["noise_weight_bias"] = dict(zip(s.user.names, (s.user_jacobian(x) @ bias).tolist()))
    changes = s.problem.pixel_grid(x) if s.problem.pixel_grid is not None and np.all(np.isfinite(cov)) else None
    grid = None
    if changes is not None:  # the pixel grid's model error of a free blur: stepped over, what remains carried (spacefit.fitting.pixel_grid)
        padding = np.zeros(lin.r.size - s.problem.pixels)
        columns = [i for i, n in enumerate(s.solver_params.names) if is_image(n)]
        joint = len(s.problem.references) > 1

        def grid_moves(d: np.ndarray) -> np.ndarray:
            moved = lin.step(np.concatenate([d, padding]) if padding.size else d)
            if joint:  # a pass's feedback: each column's rows-long vectors, freed on the threads that take them two at a time
                release_freed_memory()
            return moved

        try:
            grid = grid_step(changes, grid_moves, x, np.sqrt(np.diag(cov)), columns)
        except PastBlackSky as past:  # no step: the values and errors the fit's on the pixel grid, flagged (Status.UNSTEPPED)
            extras["pixel_grid_past_black_sky"] = past_black_sky(s.solver_params.names, x, past.tried, len(s.problem.references))
        # the models at 4x (each image's renders at 4x, 6.3 MiB a 128 x 128 px frame) dropped before the products below,
        # whose intermediates would come on top of them, and the pages their programs' threads freed handed back
        del changes
        release_freed_memory()
    if grid is not None:
        delta, remainder, noise, feedback = grid.delta, grid.remainder, grid.noise, grid.feedback
        # the step's render noise: the mean of two renders' changes, through the sandwich as the fit's own render noise
        bread = _pseudo_inverse(lin.information)[0]
        cov = cov + 0.5 * bread @ render_meat(lin.cross, np.concatenate([noise, padding]), s.problem, x) @ bread
        # the step moves with the image nuisances it is taken at: the fixed point's estimate moves by (I - D)^-1 per the fit's
        moves = np.linalg.inv(np.eye(len(x)) - feedback)
        cov = moves @ cov @ moves.T + np.outer(remainder, remainder)
        if correct and all(b.contains(float(v)) for b, v in zip(s.solver_params.bijections, x + delta)):
            x = x + delta
            extras["pixel_grid_short"] = dict(zip(s.solver_params.names, grid.short.tolist()))
        extras["pixel_grid_error"] = dict(zip(s.solver_params.names, delta.tolist()))
        extras["pixel_grid_remainder"] = dict(zip(s.solver_params.names, np.abs(remainder).tolist()))
        extras["pixel_grid_evaluations"] = grid.evaluations
    if correct and s.problem.rendered and not s.noise_given:  # the render-seed check (spacefit.fitting.render_seeds)
        shift = seed_shift(s.problem, lin.x, (lin.r, lin.r_alt), lin.step)
        # the render noise the error carries: the meat's half of the render noise's (the mean residual's share)
        bread = _pseudo_inverse(lin.information)[0]
        modelled = 0.5 * bread @ render_meat(lin.cross, (lin.r - lin.r_alt) / math.sqrt(2.0), s.problem, x) @ bread
        T = s.user_jacobian(x)
        before = np.sqrt(np.diag(map_covariance(T, cov)))
        cov = cov + np.diag(seed_excess(shift, np.diag(modelled)))
        with np.errstate(invalid="ignore", divide="ignore"):
            widened = np.sqrt(np.diag(map_covariance(T, cov))) / before
        extras["render_seed_shift"] = dict(zip(s.user.names, (T @ shift).tolist()))
        extras["render_seed_widened"] = dict(zip(s.user.names, widened.tolist()))
    if s.rms_index is not None:
        i = s.rms_index
        extras.update({"wrinkles.rms_m": float(x[i]), "wrinkles.rms_m.stderr": float(np.sqrt(cov[i, i]))})
        cov = map_covariance(s.user_jacobian(x), cov)
    return np.asarray(s.to_user(on_device(x, np.float64)), dtype=float), cov, loss_value, extras
