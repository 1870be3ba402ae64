"""Goodness of fit: whether a fit's residuals are the noise they should be, and the misfit verdict.

With the noise known (every observation has a sensor, or a ``sigma``: each residual is divided by
its noise), the residuals at a correct model are unit normal plus the fit's own Monte Carlo render
noise, so chi^2 = sum r^2 over the dof = (values fitted) - (free parameters) degrees of freedom has
the expectation 1 + v per value, v = mean (r - r_alt)^2 / 2 the render noise's variance measured
from two independent seeds, and the spread sqrt(2 / dof). A fit is a *misfit* when

    chi^2 / dof > 1 + v + max(:data:`MISFIT_SIGMAS` sqrt(2 / dof), :data:`MISFIT_FLOOR`):

more than 5 standard deviations of chi^2 / dof above its expectation (a false alarm rate below
1e-6 for a correct model), and at least 10 % more variance than the noise model predicts (a noise
sigma wrong by 5 %, which a sensor's stated gain and read noise easily are, must not condemn the
model; with tens of thousands of pixels the 5-sigma margin alone would). A misfit means the model
or its nuisances miss something (a pose, a blur, a shift, a material): the error bars, which
assume a correct model, are then too small. Measured on the panels case at 32 x 32 px with a
sensor, 16 spp: the correct model gives chi^2 / dof 1.077 with v = 0.060 (limit 1.188); the target
turned 1 deg with the materials alone free gives 2.41 (limit 1.20), alpha_y 0.060 +- 0.0017
against a truth of 0.03.

Without a known noise the residuals' scale is unknown: the report gives their mean square against
the render noise's (a reference rendered like the fit, with another seed, gives 2) and their
correlation between neighbouring pixels against the render noise's (a structured misfit
correlates its residuals over many pixels; render noise only over the pixel filter's reach), and
no verdict. Values whose residual is 0 in both renders (masked out, or black sky in a noiseless
reference) count for nothing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.rendering.renderer import PartImage

# A misfit is chi^2 / dof this many standard deviations sqrt(2 / dof) above its expectation ...
MISFIT_SIGMAS = 5.0
# ... and at least this much above it (a 5 % error of the noise sigma is no misfit).
MISFIT_FLOOR = 0.1


@dataclass(frozen=True)
class Goodness:
    """How well a fit's model explains its observations, at the fitted values.

    Attributes:
        noise_known: every residual is divided by its noise (sensor or sigma): chi^2 applies.
        values: the residual values that count (non-zero in either of two renders with independent seeds).
        dof: degrees of freedom, ``values`` less the free parameters (at least 1).
        chi2_dof: chi^2 / dof (NaN without a known noise).
        expected_spread: the standard deviation of chi^2 / dof for a correct model, sqrt(2 / dof).
        render_noise: the fit's own Monte Carlo noise, the mean (r - r_alt)^2 / 2 per value (in
            units of the noise squared when it is known, else the residuals' unit squared).
        limit: chi^2 / dof above which the fit is a misfit (NaN without a known noise).
        misfit: chi^2 / dof > limit.
        spread: mean r^2 / ``render_noise``, the residuals' spread against the render noise (NaN
            where the renders have no noise).
        correlation, render_correlation: the correlation of neighbouring pixels' residuals
            (horizontal and vertical pairs, the channels' mean) and of the render noise's (NaN
            where the residuals are not pixels).
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

    def line(self) -> str:
        """One line of words: chi^2 / dof against its expected range, or the residuals against the render noise."""
        if self.noise_known:
            verdict = "a MISFIT" if self.misfit else "within the expected range"
            return (f"goodness of fit: chi^2/dof = {self.chi2_dof:.3f} over {self.dof} dof, expected 1 + {self.render_noise:.3f} "
                    f"(render noise) +- {self.expected_spread:.3f}, misfit above {self.limit:.3f}: {verdict}")
        return (f"goodness of fit (noise unknown, no verdict): mean r^2 = {self.spread:.3g} x the render noise's; neighbour "
                f"correlation {self.correlation:+.2f} (render noise {self.render_correlation:+.2f}) over {self.values} values")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the fields, with the misfit rule's constants."""
        return {**{k: getattr(self, k) for k in self.__dataclass_fields__}, "misfit_sigmas": MISFIT_SIGMAS,
                "misfit_floor": MISFIT_FLOOR}


def goodness(r: np.ndarray, r_alt: np.ndarray, n_free: int, noise_known: bool,
             shapes: Sequence[tuple[int, ...]] = ()) -> Goodness:
    """The goodness of fit of residuals ``r`` and ``r_alt`` (the same point rendered with independent
    seeds) with ``n_free`` free parameters; ``shapes``: each observation's (h, w, c) where the
    residuals are its pixels in order (the pixel loss), for the neighbour correlation."""
    r, r_alt = np.ravel(np.asarray(r, dtype=float)), np.ravel(np.asarray(r_alt, dtype=float))
    counted = (r != 0) | (r_alt != 0)
    values = int(counted.sum())
    dof = max(values - n_free, 1)
    render_noise = float(np.mean(0.5 * (r - r_alt)[counted] ** 2)) if values else math.nan
    spread_sd = math.sqrt(2.0 / dof)
    if noise_known:
        chi2_dof = float(np.sum(r[counted] ** 2)) / dof
        limit = 1.0 + render_noise + max(MISFIT_SIGMAS * spread_sd, MISFIT_FLOOR)
    else:
        chi2_dof = limit = math.nan
    spread = float(np.mean(r[counted] ** 2)) / render_noise if render_noise > 0 else math.nan
    return Goodness(noise_known, values, dof, chi2_dof, spread_sd, render_noise, limit, bool(chi2_dof > limit), spread,
                    _neighbours(r, shapes), _neighbours(r - r_alt, shapes))


def _neighbours(d: np.ndarray, shapes: Sequence[tuple[int, ...]]) -> float:
    """Correlation of horizontally and vertically adjacent pixels' values (the channels' mean) where
    both are non-zero; NaN if ``d`` is not laid out as the images' pixels."""
    if not shapes or sum(int(np.prod(s)) for s in shapes) != d.size:
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


def part_chi2(r: np.ndarray, r_alt: np.ndarray, parts: PartImage, used: np.ndarray, noise: float) -> dict[str, float]:
    """Per part of one observation (and the whole ``target``): the mean r^2 of its counted values
    (chi^2 per value with the noise known), divided by ``noise`` (1 with the noise known, else the
    render noise per value). ``r``, ``r_alt``: the observation's (h, w, c) residuals."""
    counted = ((r != 0) | (r_alt != 0)) & used[..., None]
    out = {}
    for label, mask in zip(parts.regions, parts.masks()):
        values = counted & mask[..., None]
        out[label] = float(np.mean(r[values] ** 2)) / noise if values.any() and noise > 0 else math.nan
    return out
