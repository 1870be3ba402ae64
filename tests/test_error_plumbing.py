"""The error plumbing pinned in closed form (issue 18, item 9): the sensitivities' standard error and
t quantile, the correlation warning's sign, how the sensor's and a fitted PSF width combine in the
render noise's reach, and a sweep that dies between a point's data and its ``done`` flag. Each has a
named mutant in tools/mutants.py that these tests kill (the light curve's averaging over seeds is
pinned in test_lightcurve.py)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.studies import sweep as sweep_module
from spacefit.studies import worker


def sphere(tmp_path: Path) -> sf.Scene:
    return small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2), {"material": "white_paint", "kd": 0.4},
                       render={"spp": 2, "resolution": [16, 16]}, camera={"focal_length_mm": 5.0},
                       sun={"direction": [-0.5, 0.0, -0.75**0.5]})


def test_standard_error_is_the_sample_std_over_sqrt_n():
    from spacefit.studies.sensitivity import mean_and_error

    mean, se = mean_and_error(np.array([[1.0, 10.0], [2.0, 10.0], [3.0, 10.0], [4.0, 10.0]]))
    np.testing.assert_allclose(mean, [2.5, 10.0])
    np.testing.assert_allclose(se, [math.sqrt(5.0 / 3.0) / 2.0, 0.0])  # std with n - 1 = sqrt(5/3), over sqrt(4)


@pytest.mark.parametrize(("seeds", "t"), [(2, 12.706204736), (3, 4.302652730), (4, 3.182446305), (31, 2.042272456)])
def test_t_quantile_has_seeds_minus_one_degrees_of_freedom(seeds, t):
    """The two-sided 95 % quantiles of Student's t with 1, 2, 3 and 30 degrees of freedom (tables)."""
    from spacefit.studies.sensitivity import t_critical

    assert t_critical(seeds) == pytest.approx(t, rel=1e-8)


def test_sensitivity_error_is_that_of_its_independent_estimates(tmp_path):
    """sf.sensitivity's standard error of the target's mean-radiance derivative equals the sample std
    over sqrt(seeds) of the same seeds' Jacobians taken one by one, and its interval uses t(seeds - 1)."""
    from spacefit.fitting.problem import fit_scene
    from spacefit.rendering.derivatives import jacobians

    scene, names = sphere(tmp_path), ("parts.sphere.kd", "sun.elevation_deg")
    s = sf.sensitivity(scene, names, seeds=3, quiet=True)
    results, renderer = jacobians(fit_scene(scene, names), names, s.seeds)
    seen = renderer.part_image().ids >= 0
    per_seed = np.array([[r.columns[n].mean(axis=-1)[seen].mean() for n in names] for r in results])  # (seeds, n)
    target = s.regions.index("target")
    np.testing.assert_allclose(s.d_mean_radiance[:, target], per_seed.mean(axis=0), rtol=1e-4)
    np.testing.assert_allclose(s.d_mean_radiance_se[:, target], per_seed.std(axis=0, ddof=1) / math.sqrt(3), rtol=1e-3)
    assert np.all(s.d_mean_radiance_se[:, target] > 0)
    assert s.t == pytest.approx(4.302652730)


class FixedBijection:
    lo, hi = -np.inf, np.inf

    def at_bound(self, value: float) -> None:
        return None


@pytest.mark.parametrize(("rho", "warned"), [(-0.99, "(-0.990)"), (0.99, "(+0.990)"), (-0.9, None), (0.9, None)])
def test_correlation_warning_for_either_sign(rho, warned):
    """|rho| > 0.95 warns, a strong anticorrelation as much as a correlation, with its sign."""
    from spacefit.fitting.value_warnings import warnings_for

    params = SimpleNamespace(names=("parts.a.kd", "parts.b.kd"), bijections=(FixedBijection(), FixedBijection()))
    out = warnings_for(params, np.array([0.5, 0.5]), np.array([0.01, 0.01]), np.array([[1.0, rho], [rho, 1.0]]))
    assert [w for w in out if "correlated" in w] == ([] if warned is None else [
        f"parts.a.kd and parts.b.kd are correlated {warned}: the images determine a combination of them better than each; "
        "add views, resolution or samples."])


@pytest.mark.parametrize(("spread", "free_psf", "reach"), [((1.0, 1.5), 2.0, 9), ((0.5, 0.6), 0.8, 3), ((1.0, 0.0), 2.0, 7)])
def test_sensor_and_fitted_psf_widths_add_in_quadrature(spread, free_psf, reach):
    """sigma = hypot(sensor's PSF rms, fitted width): hypot(1.5, 2) = 2.5 reaches ceil(2 - 1 + 2 sqrt(2) 2.5) = 9 px
    (a linear sum, 3.5, would reach 11); hypot(0.6, 0.8) = 1 reaches ceil(2 sqrt 2) = 3 (linear: 4)."""
    from spacefit.fitting.uncertainty import noise_reach_px

    problem = SimpleNamespace(noise_spread_px=(spread,), free=SimpleNamespace(names=("parts.a.kd", "image.blur_sigma_px")))
    assert noise_reach_px(problem, np.array([0.5, free_psf]), 0) == reach


def test_problem_spreads_render_noise_by_the_sensors_psf(tmp_path):
    """Each observation's render-noise spread is (its pixel filter's radius, its sensor's PSF rms width; 0 without one)."""
    from spacefit.fitting.problem import setup
    from spacefit.scene.assembly import assemble
    from spacefit.scene.sections import FILTER_RADIUS_PX
    from spacefit.psf import psf_rms_px

    # 1e-5 rad a pixel: the default sensor's diffraction spreads over several pixels
    scene = sphere(tmp_path).with_values({"camera.focal_length_mm": 500.0, "camera.pixel_pitch_mm": 0.005})
    sensor = sf.Sensor()
    observations = [sf.Observation(scene, np.full((16, 16, 3), 100.0), sensor=sensor), sf.Observation(scene, np.full((16, 16, 3), 0.1))]
    s = setup(observations, ["parts.sphere.kd"])
    blur = psf_rms_px(sensor, assemble(scene).intrinsics, 3)
    assert blur > 1.0
    assert s.problem.noise_spread_px == ((FILTER_RADIUS_PX[scene.render.filter], blur), (FILTER_RADIUS_PX[scene.render.filter], 0.0))


class Died(Exception):
    """The process died here."""


class DiesWritingData:
    """A sweep store that dies (raises) while writing the ``n``-th point's ``irradiance``: after the
    point's other data, before its ``done`` flag when data are written first."""

    def __init__(self, group, n: int) -> None:
        self.group, self.n, self.writes = group, n, 0

    def __getitem__(self, name: str):
        array = self.group[name]
        if name != "irradiance":
            return array
        store = self

        class Array:
            def __getitem__(self, index):
                return array[index]

            def __setitem__(self, index, value) -> None:
                store.writes += 1
                if store.writes == store.n:
                    raise Died
                array[index] = value

        return Array()


def test_sweep_dying_between_a_points_data_and_its_flag_recomputes_that_point(tmp_path, monkeypatch):
    scene, axes, store = sphere(tmp_path), {"sun.elevation_deg": [30, 60], "render.seed": [1, 2]}, tmp_path / "store.zarr"
    opened = sweep_module.open_store
    monkeypatch.setattr(sweep_module, "open_store", lambda *a: DiesWritingData(opened(*a), 3))
    with pytest.raises(Died):
        sf.sweep(scene, axes, store=store, quiet=True)
    monkeypatch.setattr(sweep_module, "open_store", opened)
    assert int(xr.open_zarr(store).done.sum()) == 2  # the two points before the death, not the third

    calls = []
    run = worker.run_task
    monkeypatch.setattr(worker, "run_task", lambda task: (calls.append(task), run(task))[1])
    resumed = sf.sweep(scene, axes, store=store, quiet=True).load()
    assert len(calls) == 2  # the point that died and the one never reached
    monkeypatch.setattr(worker, "run_task", run)
    full = sf.sweep(scene, axes, quiet=True).load()
    xr.testing.assert_identical(resumed.drop_attrs(), full.drop_attrs())
