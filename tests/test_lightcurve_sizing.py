"""A light curve sized to a precision: the box estimator of a point's irradiance against the film's
(within noise), determinism, the pixels' allocation, the chi-squared margin, pilot seeds apart from the
final ones, the light curve's own call and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj
from scipy.stats import chi2

import spacefit as sf
from spacefit.geometry.frames import pixel_solid_angles
from spacefit.studies.lightcurve import phase_plane_sun
from spacefit.studies.lightcurve_sizing import PILOT_SPP, allocation, pilot_seeds, point_irradiance, replicate_irradiance, variance_margin


@pytest.fixture
def sphere(tmp_path):
    return small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2), {"material": "white_paint"},
                       render={"spp": 4}, camera={"focal_length_mm": 5.0})


def traced(renderer: sf.Renderer) -> tuple[np.ndarray, np.ndarray]:
    """The traced pixels (window indices) and their solid angles (sr)."""
    pixels = np.flatnonzero(renderer.traced)
    return pixels, renderer.to_window(pixel_solid_angles(renderer.assembly.intrinsics)).ravel()[pixels]


def test_the_box_estimate_is_the_films_irradiance_within_noise_and_repeats_exactly(sphere):
    """Sum of solid angle x mean sample radiance over the pixels (any allocation) against the tent-filtered
    film's sum, on a sphere half lit (phase 90 deg): the same irradiance within 4 standard errors."""
    lit = sphere.with_values({"sun.direction": [-1.0, 0.0, 0.0]})
    film = sf.light_curve(lit.with_values({"render.spp": 16}), attitude_deg=[0.0], seeds=list(range(16)), quiet=True)
    renderer = sf.Renderer(lit)
    pixels, omega = traced(renderer)
    groups = 1 + (np.arange(len(pixels)) % 3)  # an uneven allocation: its weights undo it
    box = replicate_irradiance(renderer, pixels, omega, groups, 2, 16, 11)
    assert box.shape == (16,) and np.all(box > 0)
    difference = box.mean() - film.irradiance_w_m2[0]
    assert abs(difference) < 4 * np.hypot(box.std(ddof=1) / 4, film.irradiance_se_w_m2[0])
    np.testing.assert_array_equal(replicate_irradiance(renderer, pixels, omega, groups, 2, 16, 11), box)
    assert not np.array_equal(replicate_irradiance(renderer, pixels, omega, groups, 2, 16, 12), box)


def test_the_allocation_gives_every_pixel_a_group_and_the_noisy_ones_their_share():
    omega = np.array([1.0, 1.0, 2.0, 1.0])
    groups = allocation(omega, np.array([0.0, 1.0, 1.0, 0.0]))
    np.testing.assert_array_equal(groups, 1 + np.rint(4 * np.array([0.0, 1.0, 2.0, 0.0]) / 3))
    np.testing.assert_array_equal(allocation(omega, np.zeros(4)), np.ones(4))


def test_the_margin_is_the_chi_squared_bound_and_the_pilot_seeds_are_others():
    for replicates in (4, 8, 32):
        margin = variance_margin(replicates, 0.9)
        assert chi2.cdf((replicates - 1) / margin, replicates - 1) == pytest.approx(0.1)
    assert variance_margin(8, 0.9) > variance_margin(32, 0.9) > 1.0
    assert pilot_seeds([0, 1, 2, 3]) == [4, 5]
    assert pilot_seeds([5, 1], 4) == [0, 2, 3, 4]


def test_a_light_curve_at_a_precision_reports_each_points_seeds_and_their_errors(sphere):
    """A full disc and a thin crescent at 1 %: the crescent, the noisier, traces more samples; each point is
    its seeds' estimates (the sizing rerun by hand gives them bit for bit), its error their scatter."""
    phase = [20.0, 150.0]
    curve = sf.light_curve(sphere, phase_deg=phase, precision=0.01, quiet=True)
    samples = curve.dataset["samples"].values
    assert curve.seeds == 4 and samples[1] > samples[0] > 0
    per_seed = curve.dataset.irradiance.sel(region="target").transpose("phase_angle_deg", "render.seed").values
    np.testing.assert_allclose(curve.irradiance_se_w_m2, per_seed.std(axis=1, ddof=1) / 2, rtol=1e-12)
    assert np.all(curve.irradiance_se_w_m2 < 0.02 * curve.irradiance_w_m2)  # 1 % asked, with room for the seeds' scatter
    renderer = sf.Renderer(sphere)
    renderer.set_values({k: v[1] for k, v in phase_plane_sun(sphere, np.array(phase)).items()})
    pixels, omega = traced(renderer)
    values, count, pilots = point_irradiance(renderer, pixels, omega, 0.01, [0, 1, 2, 3])
    np.testing.assert_array_equal(values, per_seed[1])
    assert count == samples[1] and pilots == curve.dataset["pilot_samples"].values[1] > len(pixels) * PILOT_SPP


def test_a_precision_is_refused_out_of_range_with_one_seed_or_off_its_path(sphere, tmp_path):
    for bad in (0.0, 1.0, -0.1):
        with pytest.raises(sf.InputError, match="precision"):
            sf.light_curve(sphere, phase_deg=[10.0], precision=bad, quiet=True)
    with pytest.raises(sf.InputError, match=r"`precision` needs two or more `seeds`"):
        sf.light_curve(sphere, phase_deg=[10.0], precision=0.01, seeds=[3], quiet=True)
    with pytest.raises(sf.InputError, match=r"the point sun.elevation_deg = \S+, sun.azimuth_deg = \S+ needs [\d,]+ samples a seed "
                                            r"for `precision` = 1e-06 with 4 seeds \(more than 16,777,216\)"):
        sf.light_curve(sphere, phase_deg=[10.0], precision=1e-6, quiet=True)
    for other in ({"attitude_deg": [0.0]}, {"phase_deg": [10.0], "store": tmp_path / "lc.zarr"}, {"phase_deg": [10.0], "cluster": 2}):
        with pytest.raises(sf.InputError, match=r"`precision` sizes a light curve over `phase_deg`"):
            sf.light_curve(sphere, precision=0.01, quiet=True, **other)
