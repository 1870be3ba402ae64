"""A light curve sized to a precision: each point's samples per pixel from its own pilot error (the
1 / sqrt(samples) law with the pilot's chi-squared margin), pilot seeds apart from the final ones, the
sampler's counts, refusals, and the light curve's own call."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj
from scipy.stats import chi2

import spacefit as sf
from spacefit.studies.lightcurve import phase_plane_sun
from spacefit.studies.lightcurve_sizing import PILOT_SEEDS, PILOT_SPP, pilot_seeds, sample_counts, variance_margin
from spacefit.studies.sweep import sweep


def pilot_of(means: list[float], relative: list[float], seeds: int = 8) -> np.ndarray:
    """(seeds, points) irradiance whose seeds' relative standard deviation is exactly ``relative``."""
    z = np.linspace(-1.0, 1.0, seeds)
    z = (z - z.mean()) / z.std(ddof=1)
    return np.array(means) * (1.0 + np.outer(z, relative))


def predicted(relative: float, spp: int, seeds: int, margin: float, pilot_spp: int = PILOT_SPP) -> float:
    """The relative standard error the sizing predicts, its margin included."""
    return math.sqrt(margin) * relative * math.sqrt(pilot_spp / spp) / math.sqrt(seeds)


def test_each_point_gets_the_fewest_samples_that_reach_the_precision():
    relative = [0.002, 0.03, 0.2]
    counts = sample_counts(pilot_of([1.0, 2.0, 0.5], relative), 0.005, 4, "independent", ["a", "b", "c"])
    margin = variance_margin(8)
    assert counts[0] == PILOT_SPP  # precise already at the pilot's count: never fewer
    for r, n in zip(relative[1:], counts[1:]):
        assert predicted(r, n, 4, margin) <= 0.005 < predicted(r, n - 1, 4, margin)
    assert counts[2] > counts[1] > counts[0]
    assert sample_counts(pilot_of([1.0], [0.03]), 0.005, 8, "independent", ["b"])[0] == math.ceil(counts[1] / 2)


def test_a_dark_point_keeps_the_pilots_count_and_the_sampler_rounds_up():
    pilot = np.hstack([np.zeros((8, 1)), pilot_of([1.0], [0.03])])
    loose = sample_counts(pilot, 0.005, 4, "independent", ["dark", "lit"])
    square = sample_counts(pilot, 0.005, 4, "stratified", ["dark", "lit"])
    assert loose[0] == square[0] == PILOT_SPP
    root = math.isqrt(square[1])
    assert root * root == square[1] and (root - 1) ** 2 < loose[1] <= square[1]


def test_a_point_past_the_sample_limit_is_named():
    with pytest.raises(sf.InputError, match=r"point phase = 120 needs more than 65536 spp for `precision` = 1e-05"):
        sample_counts(pilot_of([1.0], [0.5]), 1e-5, 4, "independent", ["phase = 120"])


def test_the_margin_is_the_chi_squared_bound_and_the_pilot_seeds_are_others():
    for seeds in (4, 8, 32):
        margin = variance_margin(seeds, 0.9)
        assert chi2.cdf((seeds - 1) / margin, seeds - 1) == pytest.approx(0.1)
    assert variance_margin(8, 0.9) > variance_margin(32, 0.9) > 1.0
    assert pilot_seeds([0, 1, 2, 3]) == list(range(4, 4 + PILOT_SEEDS))
    assert pilot_seeds([5, 1], 4) == [0, 2, 3, 4]


@pytest.fixture
def sphere(tmp_path):
    return small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2), {"material": "white_paint"},
                       render={"spp": 4}, camera={"focal_length_mm": 5.0})


def test_a_light_curve_at_a_precision_renders_each_point_at_its_pilots_count(sphere):
    """The counts are those of the pilot sweep (other seeds, the pilot's spp); the final renders are
    plain renders of the final seeds at those counts (the same numbers: deterministic), their own
    errors reported."""
    phase = [20.0, 150.0]  # a full disc and a thin crescent: the crescent is the noisier
    curve = sf.light_curve(sphere, phase_deg=phase, precision=0.01, quiet=True)
    spp = curve.dataset["render.spp"].values.tolist()
    assert curve.seeds == 4 and spp[1] > spp[0] >= PILOT_SPP
    pilot = sweep(sphere.with_values({"render.spp": PILOT_SPP}),
                  {"phase_angle_deg": phase_plane_sun(sphere, np.array(phase)), "render.seed": pilot_seeds([0, 1, 2, 3])}, quiet=True)
    irradiance = pilot.irradiance.sel(region="target").transpose("render.seed", "phase_angle_deg").values
    assert spp == sample_counts(irradiance, 0.01, 4, sphere.render.sampler, ["a", "b"])
    plain = sf.light_curve(sphere.with_values({"render.spp": spp[1]}), phase_deg=phase[1:], seeds=[0, 1, 2, 3], quiet=True)
    assert curve.irradiance_w_m2[1] == plain.irradiance_w_m2[0]  # the final renders are plain renders at that count
    assert curve.irradiance_se_w_m2[1] == plain.irradiance_se_w_m2[0]


def test_a_precision_is_refused_out_of_range_or_with_one_seed(sphere):
    for bad in (0.0, 1.0, -0.1):
        with pytest.raises(sf.InputError, match="precision"):
            sf.light_curve(sphere, phase_deg=[10.0], precision=bad, quiet=True)
    with pytest.raises(sf.InputError, match=r"`precision` needs two or more `seeds`"):
        sf.light_curve(sphere, phase_deg=[10.0], precision=0.01, seeds=[3], quiet=True)
