"""The adaptive render (``render.adaptive``): a uniform first pass, a second spent in proportion to its spread,
unbiased against a high-spp reference pixel by pixel; the allocation and the counts it refuses."""

from __future__ import annotations

import numpy as np
import pytest

import spacefit as sf
from spacefit.rendering.allocation import allocate, ladder, neighbourhood_mean, to_ladder
from spacefit.scene.schema import pilot_count

# The close view (25 m) at 96 px: the panels, legs and the wrinkled body's glints, where the spread varies most.
CLOSE = {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 25.0, "wrinkles.spacing_m": 0.1,
         "camera.position_m": [0.0, 0.0, 25.0], "render.deterministic": False}


@pytest.mark.parametrize(("pixel_filter", "spp"), [("box", 8), ("tent", 16)])
def test_the_adaptive_render_is_unbiased_against_a_high_spp_reference(pixel_filter, spp):
    """Every lit pixel, in standard errors: the mean of 32 adaptive renders (first pass a quarter of ``spp`` per
    pixel, the second's counts chosen from it) against 16 uniform whole-film renders at 256 spp (4096 in all; the
    default sampler, unbiased against ``independent`` in tests/test_sampler.py), whose own standard error counts too:
    one render of ``independent`` is noisier per pixel than the mean of 32 stratified ones. A glinting pixel's mean
    over 32 renders is skewed (its z's tails are heavy: the uniform render's own z has mean -0.2 and spread 1.8 here
    with the box), so the sharp test is the lit pixels' total, in its standard error over the renders. With the box a
    pixel's estimate is its own samples' mean, so the first pass's values and its counts meet in one pixel: weighting
    the passes by those counts biases the glints (mutant ``adaptive-weights-by-realised-counts``: total -2.2 %, -29
    standard errors, against -0.06 %, -0.55 here); the tent's is the film's filter-weighted mean of the pixel's
    neighbourhood, as in every render."""
    scene = {**CLOSE, "render.filter": pixel_filter}
    ours = sf.Renderer(sf.load_scene(None, {**scene, "render.adaptive": True}))
    images = np.stack([ours.render(spp=spp, seed=s).mean(axis=-1) for s in range(1, 33)])
    whole = sf.Renderer(sf.load_scene(None, scene), crop=False)
    references = np.stack([whole.render(spp=256, seed=s).mean(axis=-1) for s in range(101, 117)])
    reference = references.mean(axis=0)
    lit = reference > 0
    seen = lit & (images.max(axis=0) > 0)  # a rim pixel no render reached has no spread to compare with
    se = np.sqrt(images.var(axis=0, ddof=1) / len(images) + references.var(axis=0, ddof=1) / len(references))[seen]
    z = (images.mean(axis=0) - reference)[seen] / np.maximum(se, 1e-12)
    ours_total, reference_total = images[:, lit].sum(axis=1), references[:, lit].sum(axis=1)
    z_total = (ours_total.mean() - reference_total.mean()) / np.sqrt(ours_total.var(ddof=1) / len(ours_total)
                                                                      + reference_total.var(ddof=1) / len(reference_total))
    print(f"z mean {z.mean():.3f}, std {z.std():.3f}, over {seen.sum()} of {lit.sum()} lit px; total {z_total:.2f} standard errors")
    assert seen.sum() > 800 and reference[lit & ~seen].sum() < 1e-4 * reference[lit].sum()
    assert abs(z_total) < 3
    assert abs(z.mean()) < 0.15
    assert 0.8 < z.std() < 1.6


def test_an_adaptive_render_keeps_one_image_per_seed():
    scene = sf.load_scene(None, {**CLOSE, "render.adaptive": True, "render.deterministic": True, "render.spp": 16})
    renderer = sf.Renderer(scene)
    a, b, c = renderer.render(seed=3), renderer.render(seed=3), renderer.render(seed=4)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    uniform = sf.Renderer(sf.load_scene(None, {**CLOSE, "render.deterministic": True})).render(spp=16, seed=3)
    assert not np.array_equal(a, uniform) and a.mean() == pytest.approx(uniform.mean(), rel=0.05)


def test_samples_go_in_proportion_to_the_spread_with_one_for_every_pixel_then_to_counts_the_sampler_takes():
    sigma = np.array([0.0, 1.0, 2.0, 7.0, 0.01])
    slots = allocate(sigma, 20)
    assert slots.sum() == 20 and slots.min() >= 1
    assert slots.tolist() == [1, 2, 4, 12, 1]  # the floored pixels' 2 slots taken, the other 18 as 1 : 2 : 7 (2, 4, 12)
    assert allocate(np.zeros((2, 3)), 14).tolist() == [[3, 3, 2], [2, 2, 2]]
    assert allocate(np.array([5.0, 0.0]), 2).tolist() == [1, 1]
    with pytest.raises(ValueError, match="3 samples cannot give each of 4 pixels one"):
        allocate(np.ones(4), 3)
    assert ladder("multijitter", 100).tolist() == [1, 2, 4, 8, 16, 30, 64, 121]
    assert ladder("stratified", 20).tolist() == [1, 4, 16, 25]
    rounded = to_ladder(np.array([3] * 4000 + [40] * 4000 + [1]), "multijitter", np.random.default_rng(0))
    assert set(rounded[:4000]) == {2, 4} and set(rounded[4000:-1]) == {30, 64} and rounded[-1] == 1
    assert rounded[:4000].mean() == pytest.approx(3, rel=0.02) and rounded[4000:-1].mean() == pytest.approx(40, rel=0.02)
    spread = np.zeros((3, 3))
    spread[1, 1] = 9.0
    assert neighbourhood_mean(spread, 1).tolist() == [[1.0] * 3] * 3 and neighbourhood_mean(spread, 0) is spread


def test_the_first_pass_takes_a_quarter_at_counts_the_sampler_takes_and_too_few_samples_are_refused():
    assert [pilot_count("render.spp", spp, "multijitter") for spp in (4, 5, 8, 16, 20, 64)] == [2, 2, 2, 4, 4, 16]
    assert pilot_count("render.spp", 64, "stratified") == 16 and pilot_count("render.spp", 16, "ldsampler") == 4
    for spp, sampler, least in ((3, "multijitter", 4), (1, "independent", 4), (9, "stratified", 16), (9, "orthogonal", 16)):
        with pytest.raises(sf.InputError, match=rf"`render.spp` = {spp} is too few .*{sampler}.*use {least} or more"):
            sf.load_scene(None, {"render.adaptive": True, "render.sampler": sampler, "render.spp": spp})
    renderer = sf.Renderer(sf.load_scene(None, {**CLOSE, "render.adaptive": True, "render.spp": 8}))
    with pytest.raises(sf.InputError, match=r"`spp` = 2 is too few"):
        renderer.render(spp=2)
