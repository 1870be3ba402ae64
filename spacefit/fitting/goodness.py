"""Goodness of fit: whether a fit's residuals are the noise they should be, and the misfit verdict.

With the noise known (every observation has a sensor, or a ``sigma``: each residual is divided by
its noise), the residuals at a correct model are unit normal plus two Monte Carlo noises: the
model's own render noise v (variance per value, in units of the noise squared) and, for a
simulated reference, the reference's v_ref. chi^2 = sum r^2 over the dof = (values fitted) - (free
parameters) degrees of freedom has the expectation 1 + v + v_ref per value and, with normal noises,
the spread sqrt((2 (1 + v_ref)^2 + 4 v (1 + v_ref) + 4 v^2) / dof). A fit is a *misfit* when

    chi^2 / dof > 1 + v + v_ref + max(:data:`MISFIT_SIGMAS` x spread, :data:`MISFIT_FLOOR`):

more than 5 standard deviations of chi^2 / dof above its expectation (a false alarm rate below
1e-6 for a correct model), and at least 10 % more variance than the noise model predicts (a noise
sigma wrong by 5 %, which a sensor's stated gain and read noise easily are, must not condemn the
model; with tens of thousands of pixels the 5-sigma margin alone would).

The verdict is not taken on the fit's own render. A render at few samples per pixel whose noise
is comparable to the sensor's biases the test, each way small when v is small: the noise sigma,
taken at the model's noisy DN, is low where the render is (Jensen); v measured with those sigmas
is low too; a simulated reference has render noise of its own; and a path tracer's noise has long
tails, so that chi^2 / dof scatters far more than sqrt(2 / dof) says. So the model at the fitted
point is rendered again (primal renders, no Jacobian) twice, with independent seeds, at
:func:`verdict_factor` k times the fit's samples per pixel, k the smallest power of 2 (1: the fit's
own two renders) that brings the mean's v to :data:`VERDICT_RENDER_NOISE`, at most
:data:`MAX_VERDICT_FACTOR`; the mean of the two is judged, its noise sigma taken at it, its v
measured from their difference, and the spread counts the measured variance of the noise's squares
(2 v^2 for normal noise). A reference that says what it was rendered with
(``Observation.render_spp``, a FITS ``RENDSPP`` card) adds v_ref = v x (judged spp) / (reference spp)
(an upper bound for a stratified sampler, whose noise falls faster than 1 / spp); one that does not
is taken as a real observation (no render noise), and the goodness line says which. Two renders
at k times the fit's samples, not the mean of 2k at the fit's: measured on the panels case at 32 x
32 px at the truth (a calibrated sensor, v 3.5 at 8 spp; 2026-11-25, load average 7 to 8), the mean
of 16 renders at 8 spp put chi^2 / dof 0.10 above its expectation (3 spreads), two renders at 128
spp 0.004 above it; a render's Monte Carlo error at few samples is long-tailed (its mean square
scattered by several tenths between seeds at 16 spp, a few hundredths at 64). Figures of the pass: docs/measurements/validation.md and
``experiments/pass_misfit.py``.

Where the judged model's own render noise is still larger than the data's noise (v above
:data:`MAX_JUDGED_RENDER_NOISE`: a model rendered with too few samples for its data, or one whose
verdict render could not take more), chi^2 / dof's expectation is mostly that render noise, measured
from two renders, and a misfit far larger than the data's noise hides inside it (an 8-point light
curve judged 5691 "within the expected range" of 1 + 1771): the goodness says it cannot judge, and
the fit's status says so (:attr:`~spacefit.fitting.status.Status.UNJUDGED`).

A misfit means the model or its nuisances miss something (a pose, a blur, a shift, a material):
the error bars, which assume a correct model, are then too small.

What a verdict within the range can hide (:attr:`Goodness.detectable`, beside the verdict in its line
and fit.json). An unmodelled effect e_i that the free parameters do not absorb adds sum (e_i / sigma_i)^2 /
dof to chi^2 / dof; the verdict calls a misfit once that exceeds the margin m = limit - expectation =
max(:data:`MISFIT_SIGMAS` x spread, :data:`MISFIT_FLOOR`), i.e. an effect of rms sqrt(m) noise sigmas per
value. For an effect proportional to the model's signal s_i (its value less the dark model's, a sensor's
bias: a model error of a fixed fraction epsilon, e_i = epsilon s_i) that is

    epsilon_min = sqrt(m x dof / sum (s_i / sigma_i)^2),

the smallest such fraction this data could have shown; a smaller one passes. On a bright pass of 196k values
the floor m = 0.1 is some 30 times the statistical spread (issue 34): the floor, not the data, sets what
is hidden. A model whose own render noise inflates the spread hides more, and says how much.

Without a known noise the fit's own render is judged (k = 1) and the noise is estimated from the
data, on one of two bases (:attr:`Goodness.basis`). Where every reference says what it was rendered
with, its noise is its own render noise, v_ref = v x (fit's spp) / (reference's spp) per value,
measured from the model's: the residuals are judged in units of it as with a known noise (chi^2 /
dof expected 1 + v / v_ref, the same misfit rule, not judged where v / v_ref is above
:data:`MAX_JUDGED_RENDER_NOISE`; a 6-frame pass of radiance EXR frames said "noise unknown, no
verdict" with kd 3.2 of its standard errors off). Else (a real observation without a noise model) the
noise is the residuals' own, s^2 = sum r^2 / (n - p), which leaves chi^2 no room to judge: the
report gives s, and its residuals' mean square against the render noise's (a reference rendered like the
fit, with another seed, gives 2) and their correlation between neighbouring pixels against the
render noise's (a structured misfit correlates its residuals over many pixels; render noise only
over the pixel filter's reach), and no verdict on the whole. Its verdict is relative, observation by
observation (:func:`standing_out`): an observation whose residuals' mean square over its render noise's
(:attr:`Goodness.robust_spread`, the largest :data:`TRIM` of each left out: one render's firefly moved
that ratio of a correct model's dim view from 0.5 to 6.8 between seeds) is above :data:`STANDS_OUT`
times the other observations' median is named, its errors possibly understated (a model error of its
own: a pose, a blur, a gain). The comparison assumes the references' noise scales between the
observations as the fit's render noise does (references rendered, or free of noise); a real camera's
shot noise does not, and its sensor is then the better model. Values masked out count for nothing, and
without a known noise neither do those whose residual and render noise are both 0 (black sky in a
noiseless reference).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.rendering.parts import PartImage
from spacefit.scene.sections import MAX_SPP

# A misfit is chi^2 / dof this many of its standard deviations (Goodness.expected_spread) above its expectation ...
MISFIT_SIGMAS = 5.0
# ... and at least this much above it (a 5 % error of the noise sigma is no misfit).
MISFIT_FLOOR = 0.1
# The verdict's model is rendered with enough samples to bring its render noise (per value, in
# units of the noise squared) to this or below (at 0.25, long-tailed render noise still put a correct
# model's chi^2 / dof 0.17 above its expectation: panels, 32 x 32 px, 32 spp) ...
VERDICT_RENDER_NOISE = 0.1
# ... but with at most this many times the fit's samples.
MAX_VERDICT_FACTOR = 16
# No verdict is taken on a judged model whose render noise per value is above this, in units of the
# data's noise squared: chi^2's expectation would be mostly the model's own noise (module docstring).
MAX_JUDGED_RENDER_NOISE = 1.0
# What a goodness's noise is (Goodness.basis): the stated one (a sensor's model, a sigma), the
# references' own render noise (measured from the model's), or the residuals' own spread.
NOISE_MODEL = "the noise model"
REFERENCE_RENDER_NOISE = "the references' render noise"
RESIDUALS = "the residuals (s^2 over n - p)"
# Without a known noise, the fraction of largest squares each mean of :attr:`Goodness.robust_spread` leaves out
# (a dim view's few fireflies held 43 % of its residuals' sum of squares: panels, 48 x 48 px, 64 spp) ...
TRIM = 0.01
# ... and how many times the other observations' median robust spread an observation's may be before it
# is named (:func:`standing_out`).
STANDS_OUT = 3.0


def verdict_factor(render_noise: float, spp: int = 1) -> int:
    """How many times the fit's samples per pixel ``spp`` each of the verdict's two renders takes: the
    smallest power of 2 that brings ``render_noise`` (the fit's v; the judged model, the mean of the
    two, has v / (2 k)) to :data:`VERDICT_RENDER_NOISE`, at most :data:`MAX_VERDICT_FACTOR` and
    :data:`~spacefit.scene.schema.MAX_SPP` / ``spp`` (1 where v is not finite)."""
    k = 1
    while (2 * k <= min(MAX_VERDICT_FACTOR, MAX_SPP // spp) and math.isfinite(render_noise)
           and render_noise / (2 * k) > VERDICT_RENDER_NOISE):
        k *= 2
    return k


@dataclass(frozen=True)
class Goodness:
    """How well a fit's model explains its observations, at the fitted values.

    Attributes:
        noise_known: every residual is divided by its noise (sensor or sigma): chi^2 applies.
        values: the residual values that count (a residual or a render noise not 0).
        dof: degrees of freedom, ``values`` less the free parameters (at least 1).
        chi2_dof: chi^2 / dof (NaN without a known noise).
        expected_spread: the standard deviation of chi^2 / dof for a correct model, with the
            error of the measured ``render_noise`` (the module's formula, the squares' variance measured).
        render_noise: the judged model's own Monte Carlo noise v, per value (in units of the noise
            squared when it is known, else the residuals' unit squared).
        limit: chi^2 / dof above which the fit is a misfit (NaN without a known noise).
        misfit: chi^2 / dof > limit, on a judged fit.
        judged: the verdict could be taken: the noise is known (or the references' render noise) and the
            judged model's render noise is at most :data:`MAX_JUDGED_RENDER_NOISE` (False: it cannot tell a misfit).
        basis: what the noise is: :data:`NOISE_MODEL`, :data:`REFERENCE_RENDER_NOISE` (chi^2 and the
            verdict in its units, ``render_noise`` too) or :data:`RESIDUALS` (no chi^2).
        noise_sigma: without a known noise, the noise estimated per value on that basis, in the
            residuals' unit (NaN with a known noise: 1 in its units).
        spread: mean r^2 / ``render_noise``, the residuals' spread against the render noise (NaN
            where the renders have no noise).
        correlation, render_correlation: the correlation of neighbouring pixels' residuals
            (horizontal and vertical pairs, the channels' mean) and of the render noise's (NaN
            where the residuals are not pixels).
        samples_factor: the judged model's samples per pixel over the fit's (1: the fit's own render).
        verdict_spp: per observation, the judged model's samples per pixel (empty: not recorded).
        reference_noise: the references' own render noise v_ref, per value, in ``render_noise``'s unit
            (0: real observations).
        reference_spp: per observation, the samples per pixel its reference was rendered with
            (None: a real observation, no render noise; empty: not recorded).
        detectable: the smallest unmodelled effect proportional to the signal, as a fraction of it, that the
            verdict would call a misfit (the module's epsilon_min; NaN where nothing is judged or no signal is known).
        robust_spread: ``spread`` with the largest :data:`TRIM` of the squares of each mean left out
            (NaN where the renders have no noise): what :func:`standing_out` compares.
    """

    noise_known: bool
    values: int
    dof: int
    chi2_dof: float
    expected_spread: float
    render_noise: float
    limit: float
    misfit: bool
    spread: float
    correlation: float
    render_correlation: float
    samples_factor: int = 1
    verdict_spp: tuple[int, ...] = ()
    reference_noise: float = 0.0
    reference_spp: tuple[int | None, ...] = ()
    judged: bool = True
    basis: str = NOISE_MODEL
    noise_sigma: float = math.nan
    detectable: float = math.nan
    robust_spread: float = math.nan

    @property
    def margin(self) -> float:
        """How far above its expectation chi^2 / dof may lie and pass: max(:data:`MISFIT_SIGMAS` x spread, :data:`MISFIT_FLOOR`)."""
        return self.limit - (1.0 + self.render_noise + self.reference_noise)

    def hides(self) -> str:
        """What a pass could hide, in words (empty where nothing is judged)."""
        if not (self.judged and math.isfinite(self.limit)):
            return ""
        signal = f"{100.0 * self.detectable:.2g} % of the signal, or " if math.isfinite(self.detectable) else ""
        return (f"; it cannot see an unmodelled effect below {signal}an rms of {math.sqrt(max(self.margin, 0.0)):.2g} noise sigma "
                "per value")

    def line(self) -> str:
        """One line of words: chi^2 / dof against its expected range, or the residuals against the render noise."""
        if self.basis == REFERENCE_RENDER_NOISE:
            verdict = ("a MISFIT" if self.misfit else "within the expected range" if self.judged else
                       f"CANNOT JUDGE: the model's own render noise is above {MAX_JUDGED_RENDER_NOISE:g} x the references'")
            return (f"goodness of fit (noise unknown, estimated as {self.basis}: {self.noise_sigma:.3g} per value): chi^2/dof = "
                    f"{self.chi2_dof:.3f} over {self.dof} dof, expected 1 + {self.render_noise:.3f} (the fit's render noise) "
                    f"+- {self.expected_spread:.3f}, misfit above {self.limit:.3f}: {verdict}{self.hides()}")
        if self.noise_known:
            verdict = ("a MISFIT" if self.misfit else "within the expected range" if self.judged else
                       f"CANNOT JUDGE: the model's own render noise is above {MAX_JUDGED_RENDER_NOISE:g} x the data's noise "
                       "and would hide a misfit; render with more samples")
            spp = "/".join(str(s) for s in dict.fromkeys(self.verdict_spp))
            judged = f"{spp} spp, " if spp else ""
            return (f"goodness of fit: chi^2/dof = {self.chi2_dof:.3f} over {self.dof} dof, expected 1 + {self.render_noise:.3f} "
                    f"(render noise at {judged}{self.samples_factor} x the fit's samples) + {self.reference_noise:.3f} "
                    f"({self._references()}) +- {self.expected_spread:.3f}, misfit above {self.limit:.3f}: {verdict}{self.hides()}")
        return (f"goodness of fit (noise unknown, estimated from {self.basis}: {self.noise_sigma:.3g} per value, which leaves "
                f"chi^2 no verdict): mean r^2 = {self.spread:.3g} x the render noise's ({self.robust_spread:.3g} without the "
                f"largest {100 * TRIM:g} % of each); neighbour "
                f"correlation {self.correlation:+.2f} (render noise {self.render_correlation:+.2f}) over {self.values} values")

    def _references(self) -> str:
        """What the references' render noise assumed, in words."""
        rendered = [s for s in self.reference_spp if s is not None]
        real = len(self.reference_spp) - len(rendered)
        if not rendered:
            return "references taken as real observations: no render noise"
        words = f"references rendered at {'/'.join(str(s) for s in dict.fromkeys(rendered))} spp"
        return words + (f", {real} taken as real" if real else "")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the fields, with the misfit rule's constants."""
        return {**{k: getattr(self, k) for k in self.__dataclass_fields__}, "margin": self.margin, "misfit_sigmas": MISFIT_SIGMAS,
                "misfit_floor": MISFIT_FLOOR, "verdict_render_noise": VERDICT_RENDER_NOISE,
                "max_verdict_factor": MAX_VERDICT_FACTOR, "max_judged_render_noise": MAX_JUDGED_RENDER_NOISE}


def goodness(r: np.ndarray, noise: np.ndarray, n_free: int, noise_known: bool, shapes: Sequence[tuple[int, ...]] = (), *,
             fitted: np.ndarray | None = None, reference_ratio: float | np.ndarray = 0.0, samples_factor: int = 1,
             verdict_spp: Sequence[int] = (), reference_spp: Sequence[int | None] = (), signal: np.ndarray | None = None) -> Goodness:
    """The goodness of fit of residuals ``r`` with ``n_free`` free parameters.

    Args:
        r: the judged model's residuals.
        noise: a draw of their render noise, the same shape (e.g. (r_1 - r_2) / sqrt(2) of renders
            with two seeds, for r = r_1).
        n_free: the free parameters.
        noise_known: ``r`` is in units of the noise: chi^2 and the verdict apply.
        shapes: each observation's (h, w, c) where the residuals are its pixels in order (the pixel
            loss), for the neighbour correlation.
        fitted: per value, whether it was fitted (not masked out): with the noise known such a value
            counts even where its residual and render noise are 0 (an integer DN equal to the model's,
            as a sensor's sky at its bias often is; left out, they raised a pass's chi^2 / dof by 0.13).
        reference_ratio: per value (or one for all), the reference's render noise over the judged
            model's, the model's samples per pixel over the reference's (0: a real observation).
        samples_factor, verdict_spp, reference_spp: recorded as :class:`Goodness` holds them.
        signal: per value, the model's signal in the residuals' unit (s_i / sigma_i with the noise known),
            for :attr:`Goodness.detectable`; None: not known.
    """
    r, noise = np.ravel(np.asarray(r, dtype=float)), np.ravel(np.asarray(noise, dtype=float))
    ratio = np.broadcast_to(np.ravel(np.asarray(reference_ratio, dtype=float)), r.shape)
    if not noise_known:
        counted = (r != 0) | (noise != 0)
        reference = float(np.mean((noise**2 * ratio)[counted])) if counted.any() else 0.0
        if reference > 0 and np.all(ratio[counted] > 0):  # every reference's own render noise: the data's noise
            scale = math.sqrt(reference)
            g = goodness(r / scale, noise / scale, n_free, True, shapes, fitted=fitted, samples_factor=samples_factor,
                         verdict_spp=verdict_spp, reference_spp=reference_spp, signal=None if signal is None else np.asarray(signal) / scale)
            return dataclasses.replace(g, noise_known=False, basis=REFERENCE_RENDER_NOISE, noise_sigma=scale)
    counted = (r != 0) | (noise != 0)
    if noise_known and fitted is not None:
        counted |= np.ravel(np.asarray(fitted, dtype=bool))
    values = int(counted.sum())
    dof = max(values - n_free, 1)
    render_noise = float(np.mean(noise[counted] ** 2)) if values else math.nan
    reference_noise = float(np.mean((noise**2 * ratio)[counted])) if values else 0.0
    expected = 1.0 + render_noise + reference_noise
    # chi^2 / dof's spread, and the error of the render noise measured with it: render noise is not
    # normal (a path tracer's has long tails), its squares' variance is measured, not 2 v^2
    quartic = float(np.var(noise[counted] ** 2)) if values else 0.0
    base = 1.0 + reference_noise
    spread_sd = math.sqrt((2.0 * base**2 + 4.0 * render_noise * base + 2.0 * quartic) / dof)
    if noise_known:
        chi2_dof = float(np.sum(r[counted] ** 2)) / dof
        limit = expected + max(MISFIT_SIGMAS * spread_sd, MISFIT_FLOOR)
    else:
        chi2_dof = limit = math.nan
    spread = float(np.mean(r[counted] ** 2)) / render_noise if render_noise > 0 else math.nan
    robust = _trimmed_mean(noise[counted] ** 2)
    robust_spread = _trimmed_mean(r[counted] ** 2) / robust if robust > 0 else math.nan
    judged = noise_known and render_noise <= MAX_JUDGED_RENDER_NOISE
    sigma = math.nan if noise_known else math.sqrt(float(np.sum(r[counted] ** 2)) / dof)
    detectable = math.nan
    if judged and signal is not None:
        power = float(np.sum(np.ravel(np.asarray(signal, dtype=float))[counted] ** 2))
        detectable = math.sqrt((limit - expected) * dof / power) if power > 0 else math.nan
    return Goodness(noise_known, values, dof, chi2_dof, spread_sd, render_noise, limit, judged and bool(chi2_dof > limit), spread,
                    _neighbours(r, shapes), _neighbours(noise, shapes), samples_factor, tuple(int(s) for s in verdict_spp),
                    reference_noise, tuple(None if s is None else int(s) for s in reference_spp), judged,
                    NOISE_MODEL if noise_known else RESIDUALS, sigma, detectable, robust_spread)


def _trimmed_mean(squares: np.ndarray) -> float:
    """The mean of ``squares`` without the largest :data:`TRIM` of them (NaN for none)."""
    if not squares.size:
        return math.nan
    kept = squares.size - int(TRIM * squares.size)
    return float(np.mean(np.partition(squares, kept - 1)[:kept]))


def standing_out(own: Sequence[Goodness]) -> dict[int, float]:
    """Without a known noise, the observations (by index into ``own``, each observation's own goodness)
    whose residuals stand out from the others': its :attr:`Goodness.robust_spread` over the median of the
    other observations' above :data:`STANDS_OUT` (with the noise known, or the references' render noise
    judging each on its own, none), with that ratio. Observations without render noise (value
    observations) are not compared."""
    spreads = [g.robust_spread if g.basis == RESIDUALS and math.isfinite(g.robust_spread) else math.nan for g in own]
    out = {}
    for k, q in enumerate(spreads):
        others = [p for j, p in enumerate(spreads) if j != k and math.isfinite(p)]
        if math.isfinite(q) and others and q > STANDS_OUT * (median := float(np.median(others))):
            out[k] = q / median
    return out


def _neighbours(d: np.ndarray, shapes: Sequence[tuple[int, ...]]) -> float:
    """Correlation of horizontally and vertically adjacent pixels' values (the channels' mean) where
    both are non-zero; NaN if ``d`` does not begin with the images' pixels (a value observation's
    residuals follow them)."""
    if not shapes or sum(int(np.prod(s)) for s in shapes) > d.size:
        return math.nan
    a, b, offset = [], [], 0
    for shape in shapes:
        image = d[offset:offset + int(np.prod(shape))].reshape(shape).mean(axis=-1)
        offset += int(np.prod(shape))
        for first, second in ((image[:, 1:], image[:, :-1]), (image[1:, :], image[:-1, :])):
            both = (first != 0) & (second != 0)
            a.append(first[both])
            b.append(second[both])
    a, b = np.concatenate(a), np.concatenate(b)
    if a.size < 3 or a.std() == 0 or b.std() == 0:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def part_chi2(r: np.ndarray, noise: np.ndarray, parts: PartImage, used: np.ndarray, scale: float,
              noise_known: bool = False) -> dict[str, float]:
    """Per part of one observation (and the whole ``target``): the mean r^2 of its counted values
    (chi^2 per value with the noise known), divided by ``scale`` (1 with the noise known, else the
    render noise per value). ``r``, ``noise``: the observation's (h, w, c) residuals and a draw of
    their render noise (:func:`goodness`); ``used``: its fitted pixels, every value of which counts
    with the noise known."""
    counted = (((r != 0) | (noise != 0)) | noise_known) & used[..., None]
    out = {}
    for label, mask in zip(parts.regions, parts.masks()):
        values = counted & mask[..., None]
        out[label] = float(np.mean(r[values] ** 2)) / scale if values.any() and scale > 0 else math.nan
    return out
