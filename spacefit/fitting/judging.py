"""The goodness of fit a fit's verdict judges at its result (:mod:`spacefit.fitting.goodness`): the
judged model (the mean of two independent renders, at more samples where the noise is known), the
residuals and a draw of their render noise, each observation's own goodness and each part's."""

from __future__ import annotations

import math
from collections.abc import Mapping

import jax
import numpy as np

from spacefit.errors import InputError
from spacefit.fitting.goodness import Goodness, goodness, part_chi2, verdict_factor
from spacefit.fitting.problem import Setup
from spacefit.fitting.residuals import Problem
from spacefit.rendering.memory import check_memory
from spacefit.rendering.parts import PartImage
from spacefit.scene.names import Name
from spacefit.units import DN_UNIT


def judged_goodness(s: Setup, x: jax.Array, loss: str) -> tuple[Goodness, np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
    """The goodness of fit at ``x`` (:mod:`~spacefit.fitting.goodness`), the residuals it judged and a
    draw of their render noise, each observation's model (images, then value observations) at the
    fit's seeds. With the noise known the judged model is the mean of two renders with independent
    seeds at :func:`verdict_factor` times the fit's samples per pixel (the fit's own two where that is
    1; primal renders only; a rendered value observation's too, :attr:`~spacefit.fitting.observations.base.Block.resampled`), the noise sigma taken at it; else the fit's own render; and the judged models' signal (:func:`_signal`).
    A model that is not rendered is the same at every seed: its render noise is 0."""
    problem = s.problem
    renders = [problem.models_seeded(x, 0), problem.models_seeded(x, 1)]
    judged_models = [(a + b) / 2 for a, b in zip(*renders)]
    if s.noise_given:
        r, noise = _mean_and_noise(problem, renders)
        spps = [*problem.spp, *(b.spp for b in problem.blocks if b.resampled is not None and b.spp)]
        k = verdict_factor(2.0 * goodness(r, noise, 0, True).render_noise, max(spps)) if spps else 1
        while k > 1 and not affordable(problem, k):
            k //= 2
        if k > 1:
            finer = problem.resampled(k)
            fine = [finer.models_seeded(x, 0), finer.models_seeded(x, 1)]
            r, noise = _mean_and_noise(finer, fine)
            judged_models = [(a + b) / 2 for a, b in zip(*fine)]
        judged = 2 * k
    else:
        judged, judged_models = 1, renders[0]
        r, r_alt = (np.asarray(problem.residual_of(m), dtype=np.float64) for m in renders)
        noise = (r - r_alt) / math.sqrt(2.0)
    verdict_spp = [judged * spp for spp in problem.spp]
    ratios = [_reference_ratio(spp, ref) for spp, ref in zip(verdict_spp, problem.reference_spp)]
    pixels = loss == "pixel"
    if pixels:
        values = r.size - problem.pixels  # the value observations' residuals, after the pixels: no reference render noise
        ratio = np.concatenate([np.repeat(ratios, [ref.size for ref in problem.references]), np.zeros(values)])
        fitted = np.concatenate([*(np.broadcast_to(used[..., None], ref.shape).ravel() for ref, used in zip(problem.references, problem.used)),
                                 np.ones(values, dtype=bool)])
    else:
        ratio, fitted = float(np.mean(ratios or [0.0])), None
    signal = _signal(problem, judged_models)
    quality = goodness(r, noise, len(s.x0), s.noise_given, [ref.shape for ref in problem.references] if pixels else [],
                       fitted=fitted, reference_ratio=ratio, samples_factor=judged, verdict_spp=verdict_spp,
                       reference_spp=problem.reference_spp, signal=signal if pixels else None)
    return quality, r, noise, [np.asarray(m) for m in renders[0]], signal


def _signal(problem: Problem, models: list[jax.Array]) -> np.ndarray:
    """Per residual, the models' signal in the residuals' unit: each model less its model of no light
    (:attr:`~spacefit.fitting.residuals.Problem.dark`; a value observation's 0), weighted as the residuals
    are (their derivative along it: s_i / sigma_i with the noise known), for :attr:`~spacefit.fitting.goodness.Goodness.detectable`."""
    dark = [*problem.dark, *(0.0 for _ in models[len(problem.dark):])]
    return np.asarray(jax.jvp(problem.residual_of, (models,), ([m - d for m, d in zip(models, dark)],))[1], dtype=float)


def _reference_ratio(spp: int, reference_spp: int | None) -> float:
    """A reference's render noise over the judged model's, per value: the model's samples per pixel
    ``spp`` over the reference's (0 for a real observation, ``reference_spp`` None)."""
    return spp / reference_spp if reference_spp else 0.0


def affordable(problem: Problem, factor: int) -> bool:
    """Whether every observation's whole film rendered at ``factor`` times its samples per pixel in one
    wavefront (a fit's render) fits this machine (:func:`~spacefit.rendering.memory.check_memory`):
    a verdict render takes fewer samples rather than lose the fit's result."""
    try:
        for ref, spp in zip(problem.references, problem.spp):
            check_memory(ref.shape[1], ref.shape[0], ref.shape[0] * ref.shape[1], factor * spp, split=False)
    except InputError:
        return False
    return True


def _mean_and_noise(problem: Problem, renders: list[list[jax.Array]]) -> tuple[np.ndarray, np.ndarray]:
    """The residuals of the mean of two renders (each a list of model images), the noise sigma taken
    at that mean, and a draw of their render noise: half the two renders' difference, weighted as the
    residuals are (their derivative along it)."""
    mean = [(a + b) / 2 for a, b in zip(*renders)]
    half = [(a - b) / 2 for a, b in zip(*renders)]
    r, noise = jax.jvp(problem.residual_of, (mean,), (half,))
    return np.asarray(r, dtype=float), np.asarray(noise, dtype=float)


def per_observation(r: np.ndarray, noise: np.ndarray, s: Setup, factor: int, signal: np.ndarray | None = None) -> list[Goodness]:
    """Per observation (images, then value observations), the goodness of fit of its own residuals
    (pixel loss), with the shared free parameters and its own (``name@k``) counted as free (a value
    observation: those it depends on); ``factor``: the judged model's samples over the fit's; ``signal``:
    the judged models' (:func:`_signal`), for what each verdict could hide."""
    out, offset, problem = [], 0, s.problem
    for k, ref in enumerate(problem.references):
        rows = slice(offset, offset + ref.size)
        offset = rows.stop
        n_k = sum(1 for name in s.user.names if Name(name).observation in (None, k))
        spp, reference = factor * problem.spp[k], problem.reference_spp[k]
        out.append(goodness(r[rows], noise[rows], n_k, s.noise_given, [ref.shape], fitted=np.broadcast_to(problem.used[k][..., None], ref.shape),
                            reference_ratio=_reference_ratio(spp, reference), samples_factor=factor, verdict_spp=[spp],
                            reference_spp=[reference], signal=None if signal is None else signal[rows]))
    for block in problem.blocks:
        rows = slice(offset, offset + block.data.value.size)
        offset = rows.stop
        out.append(goodness(r[rows], noise[rows], len(block.known), block.noise_known, fitted=np.ones(rows.stop - rows.start, bool),
                            samples_factor=factor, signal=None if signal is None else signal[rows]))
    return out


def part_goodness(r: np.ndarray, noise: np.ndarray, problem: Problem, quality: Goodness) -> list[dict[str, dict[str, float]]]:
    """Per observation, per part: ``chi2_per_value`` (noise known) or ``r2_over_render_noise``."""
    key = "chi2_per_value" if quality.noise_known else "r2_over_render_noise"
    out, offset = [], 0
    for parts, ref, used in zip(problem.part_images, problem.references, problem.used):
        rows = slice(offset, offset + ref.size)
        offset = rows.stop
        values = part_chi2(r[rows].reshape(ref.shape), noise[rows].reshape(ref.shape), parts, used,
                           1.0 if quality.noise_known else quality.render_noise, quality.noise_known)
        out.append({name: {key: value} for name, value in values.items()})
    return out


def part_rows(parts: PartImage, reference: np.ndarray, render: np.ndarray, unit: str, used: np.ndarray,
               spread: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """Per part: its fitted pixels (``used``), the mean of the reference and of the fit's render there, in ``unit``,
    and ``spread``'s value (chi^2 per value, or mean r^2 over the render noise's; absent for the losses that
    are not per pixel)."""
    (pixels, ref), (_, fitted) = parts.means(reference, used), parts.means(render, used)
    suffix = "dn" if unit == DN_UNIT else "w_m2_sr"
    return {name: {"pixels": int(n), f"reference_mean_{suffix}": float(r), f"fit_mean_{suffix}": float(f), **spread.get(name, {})}
            for name, n, r, f in zip(parts.regions, pixels, ref, fitted)}
