"""The samplers a scene may name and the sample counts each takes (Mitsuba's ``stratified``,
``multijitter``, ``ldsampler`` and ``orthogonal`` need square, power-of-4 or prime-square counts)."""

from __future__ import annotations

import math

from spacefit.errors import InputError


# Mitsuba samplers; "independent" draws every sample alone, the others stratify a pixel's samples.
SAMPLERS = ("independent", "stratified", "multijitter", "ldsampler", "orthogonal")
# The counts each rounding sampler takes (Mitsuba rounds any other count up, with only a log line:
# more samples, more time than asked); spacefit refuses the others. "independent" takes any count;
# "multijitter" a grid of isqrt(spp) rows (20 = 4 x 5, not 32), and spacefit renders another count as
# passes of counts it takes (:func:`split_sample_count`: 32 = 30 + 2), exactly the samples asked.
SAMPLE_COUNTS = {"stratified": "a perfect square (1, 4, 9, 16, 25, ...)", "ldsampler": "a power of 4 (4, 16, 64, 256, ...)",
                 "orthogonal": "the square of a prime (4, 9, 25, 49, 121, ...)"}


def takes_sample_count(sampler: str, spp: int) -> bool:
    """Whether Mitsuba's ``sampler`` renders exactly ``spp`` samples per pixel (:data:`SAMPLE_COUNTS`)."""
    root = math.isqrt(spp)
    square = root * root == spp
    if sampler == "stratified":
        return square
    if sampler == "ldsampler":
        return square and spp & (spp - 1) == 0 and spp > 1
    if sampler == "multijitter":
        return spp % root == 0
    if sampler == "orthogonal":
        return square and root > 1 and all(root % k for k in range(2, math.isqrt(root) + 1))
    return True


def split_sample_count(sampler: str, spp: int) -> tuple[int, ...]:
    """``spp`` as counts that Mitsuba's ``sampler`` takes, largest first, each rendered as a pass of its own:
    ``(spp,)`` where it takes ``spp`` (always for ``independent``; refused counts are refused before, by
    :func:`check_sample_count`), else for ``multijitter`` the largest grid below and the rest split alike."""
    counts = []
    while spp:
        count = next(n for n in range(spp, 0, -1) if takes_sample_count(sampler, n))
        counts.append(count)
        spp -= count
    return tuple(counts)


def check_sample_count(name: str, spp: int, sampler: str) -> None:
    """Refuse a count of samples per pixel that ``sampler`` would round (the policy: refuse, never round
    silently; ``multijitter`` splits it instead, :func:`split_sample_count`); ``name`` is the argument's,
    e.g. ``render.spp``."""
    if sampler in SAMPLE_COUNTS and not takes_sample_count(sampler, spp):
        nearest = [n for n in range(max(1, spp // 2), 2 * spp + 2) if takes_sample_count(sampler, n)]
        below, above = [n for n in nearest if n < spp], [n for n in nearest if n > spp]
        near = " or ".join(str(n) for n in (below[-1:] + above[:1]))
        raise InputError(f"`{name}` = {spp} must be {SAMPLE_COUNTS[sampler]} with render.sampler = {sampler!r}"
                         f"{f' (nearest: {near})' if near else ''}; 'independent' takes any count.")
