"""The default sampler (multijitter): its images unbiased against a high-spp reference of the independent
sampler, and the policy for counts a sampler would round. (Its AD derivatives against finite differences:
tests/test_bridge.py, which renders with the default.)"""

from __future__ import annotations

import numpy as np
import pytest

import spacefit as sf
from spacefit.rendering.sample_passes import pass_seeds
from spacefit.scene.sections import RenderSettings
from spacefit.scene.sampling import split_sample_count

SMALL = {"wrinkles.spacing_m": 0.1, "render.resolution": [64, 64], "camera.pixel_pitch_mm": 37.5, "render.spp": 4,
         "wrinkles.model": "geometry"}


def test_the_default_sampler_s_images_are_unbiased_against_a_high_spp_reference():
    """Pixel by pixel, in standard errors: the mean of 16 renders at 4 spp against 1024 spp of ``independent``
    on the whole film (panels, legs and the wrinkled body's glints in the close view)."""
    assert RenderSettings().sampler == "multijitter"
    base = {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 25.0, "wrinkles.spacing_m": 0.1,
            "camera.position_m": [0.0, 0.0, 25.0], "render.deterministic": False}
    ours = sf.Renderer(sf.load_scene(None, base))
    images = np.stack([ours.render(spp=4, seed=s).mean(axis=-1) for s in range(1, 17)])
    reference = sf.Renderer(sf.load_scene(None, {**base, "render.sampler": "independent"}), crop=False).render(spp=1024, seed=99)
    reference = reference.mean(axis=-1)
    lit = (reference > 0) & (images.min(axis=0) > 0)  # rim pixels some renders miss have no spread to compare with
    se = images.std(axis=0, ddof=1)[lit] / np.sqrt(len(images))
    z = (images.mean(axis=0)[lit] - reference[lit]) / np.maximum(se, 1e-12)
    assert lit.sum() > 500
    print(f"z mean {z.mean():.3f}, std {z.std():.3f}")
    assert abs(z.mean()) < 0.15
    assert 0.8 < z.std() < 1.4
    everywhere = reference > 0
    assert images.mean(axis=0)[everywhere].sum() == pytest.approx(reference[everywhere].sum(), rel=0.005)


def test_samplers_keep_one_image_per_seed_and_refuse_counts_they_would_round():
    """The policy: stratified, ldsampler and orthogonal refuse a count they would round (at load and at
    each render); multijitter, the default, renders one as passes of counts it takes, exactly the samples asked."""
    scene = sf.load_scene(None, SMALL)
    assert scene.render.sampler == "multijitter"
    renderer = sf.Renderer(scene)
    a, b, c = renderer.render(seed=3), renderer.render(seed=3), renderer.render(seed=4)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert renderer.scene.sensors()[0].sampler().sample_count() == scene.render.spp
    for spp, counts in ((32, (30, 2)), (20, (20,)), (5, (4, 1)), (128, (121, 6, 1))):
        assert split_sample_count("multijitter", spp) == counts
        passes = pass_seeds(7, spp, 100, "multijitter")
        assert [p[1] for p in passes] == list(counts) and passes[0][0] == 7 and len({p[0] for p in passes}) == len(passes)
    assert split_sample_count("independent", 32) == (32,)
    for sampler, spp in (("stratified", 20), ("ldsampler", 32), ("ldsampler", 36), ("orthogonal", 16), ("nope", 16)):
        with pytest.raises(sf.InputError, match="render.s"):
            sf.load_scene(None, {"render.sampler": sampler, "render.spp": spp})
    with pytest.raises(sf.InputError, match=r"`spp` = 16 must be the square of a prime .*nearest: 9 or 25"):
        sf.Renderer(sf.load_scene(None, {**SMALL, "render.sampler": "orthogonal"})).render(spp=16)
    for sampler, spp in (("ldsampler", 64), ("orthogonal", 49), ("stratified", 36), ("multijitter", 7)):
        sf.load_scene(None, {"render.sampler": sampler, "render.spp": spp})
