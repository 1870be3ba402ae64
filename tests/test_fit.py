"""Recovery of known parameters from synthetic references, and the fit's honesty where it cannot."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import reference
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit import InputError, Observation, fit, identifiability, render

PANELS, WRINKLES, WRINKLES_FAR = (sf.load_case(name) for name in ("panels", "wrinkles", "wrinkles_far"))


def relative_errors(result, truth):
    return {k: abs(result.values[k] / v - 1.0) for k, v in truth.items()}


@pytest.fixture(scope="module")
def panels_reference():
    return reference("panels")[0]


@pytest.mark.parametrize("solver", ["lm", "gn", "dogleg"])
def test_material_fit_recovers_truth_within_2_percent(panels_reference, solver):
    result = fit(Observation(PANELS.scene(), panels_reference), list(PANELS.free), solver=solver, start=PANELS.start)
    assert result.success, result.status
    assert max(relative_errors(result, PANELS.truth).values()) < 0.02, result.values
    assert result.history and result.history[-1]["loss"] < result.history[0]["loss"]
    assert len(result.renders) == 1 and result.renders[0].shape == (128, 128, 3)


@pytest.mark.parametrize("solver", ["bfgs", "adam"])
def test_gradient_solvers_reduce_the_loss(panels_reference, solver):
    result = fit(Observation(PANELS.scene(), panels_reference), list(PANELS.free), solver=sf.Adam(0.1) if solver == "adam" else solver,
                 start=PANELS.start, max_steps=15)
    assert result.history[-1]["loss"] < 0.5 * result.history[0]["loss"]
    assert all(np.isfinite(v) for v in result.values.values())
    assert result.status is not sf.Status.NOISE_FLOOR  # the noise-floor stop is the least-squares solvers'
    assert all(np.isnan(h["loss_noise"]) for h in result.history)  # nor does it pay the noise renders


def test_material_fit_with_2_percent_noise_within_5_percent():
    image, sigma = reference("panels", 2)
    result = fit(Observation(PANELS.scene(), image, sigma), list(PANELS.free), start=PANELS.start)
    assert max(relative_errors(result, PANELS.truth).values()) < 0.05, result.values


def test_D_and_G_recovered_where_identifiable():
    image, _ = reference("wrinkles")
    result = fit(Observation(WRINKLES.scene(), image), list(WRINKLES.free), start=WRINKLES.start, max_steps=30)
    assert abs(result.values["wrinkles.D"] - 2.4) < 0.02, result.values
    assert relative_errors(result, {"wrinkles.G": 0.04})["wrinkles.G"] < 0.05, result.values
    assert "wrinkles.rms_m" in result.extras
    # the errors are honest where D and G are identifiable: glint noise is largest where the Jacobian
    # is, and the uniform-noise form s^2 (J^T J)^-1 put D 6.6 of its standard errors off here
    for name, true in WRINKLES.truth.items():
        assert abs(result.values[name] - true) <= 3.0 * result.stderr[name], (name, result.values, result.stderr)
    # ... and not inflated to get there: below half the accuracy this test demands (D within 0.02,
    # G within 5 %); measured 0.0032 and 0.00054 m
    assert result.stderr["wrinkles.D"] < 0.01 and result.stderr["wrinkles.G"] < 0.025 * 0.04, result.stderr


@pytest.mark.slow  # 45 s; CI fits D and G noise-free and with noise where they are not identifiable
def test_D_and_G_with_2_percent_noise():
    image, sigma = reference("wrinkles", 2)
    result = fit(Observation(WRINKLES.scene(), image, sigma), list(WRINKLES.free), start=WRINKLES.start, max_steps=30)
    assert abs(result.values["wrinkles.D"] - 2.4) < 0.05, result.values
    assert relative_errors(result, {"wrinkles.G": 0.04})["wrinkles.G"] < 0.10, result.values


def test_unidentifiable_D_and_G_report_errors_that_cover_the_truth():
    """At 60 m a pixel (40 cm) is as large as the largest wrinkle: the fit must say how little it knows."""
    image, sigma = reference("wrinkles_far", 2)
    result = fit(Observation(WRINKLES_FAR.scene(), image, sigma), list(WRINKLES.free), start=WRINKLES.start, max_steps=10)
    for name, true in WRINKLES.truth.items():
        assert abs(result.values[name] - true) <= 2.0 * result.stderr[name], (name, result.values, result.stderr)
    assert result.warnings


def test_sun_direction_recovered():
    case = PANELS.with_values({"sun.direction": [0.3, 0.2, -1]})
    truth = {"sun.elevation_deg": 70.173, "sun.azimuth_deg": -146.310}  # towards the sun: -(0.3, 0.2, -1)
    result = fit(Observation(case.scene(), case.reference()[0]), list(truth), start={k: v + 5.0 for k, v in truth.items()})
    for name, value in truth.items():
        assert abs(result.values[name] - value) < 0.1, result.values


def test_several_observations_fit_jointly(panels_reference):
    other = PANELS.with_values({"camera.position_m": [-5, 2, 24]})
    observations = [Observation(PANELS.scene(), panels_reference), Observation(other.scene(), other.reference()[0])]
    result = fit(observations, list(PANELS.free), start=PANELS.start)
    assert len(result.renders) == 2
    assert max(relative_errors(result, PANELS.truth).values()) < 0.02, result.values


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"reference": np.zeros((64, 64, 3))}, "shape"),
        ({"reference": np.full((128, 128, 3), np.nan)}, "NaN"),
        ({"free": ["parts.panels.alpha_q"]}, "alpha_x"),
        ({"start": {"parts.panels.alpha_x": 1.5}}, r"parts\.panels\.alpha_x"),
        ({"start": {"parts.legs.kd": 0.0}}, r"parts\.legs\.kd"),
        ({"start": {"wrinkles.D": 2.5}}, "start"),
        ({"solver": "newton"}, "solver"),
        ({"loss": "l1"}, "loss"),
        ({"render": "prb"}, "FitRender"),
    ],
)
def test_bad_fit_input_is_refused_before_rendering(panels_reference, kwargs, message):
    ref = kwargs.pop("reference", panels_reference)
    free = kwargs.pop("free", list(PANELS.free))
    with pytest.raises(InputError, match=message):
        fit(Observation(PANELS.scene(), ref), free, **kwargs)


@pytest.mark.parametrize(("kwargs", "message"), [({"seed": 3, "seed_grad": 3}, "seed"), ({"spp": 0}, "spp"),
                                               ({"integrator": "path"}, "integrator"), ({"geometry_jacobian": "x"}, "geometry_jacobian")])
def test_render_settings_are_checked_on_construction(kwargs, message):
    with pytest.raises(InputError, match=message):
        sf.FitRender(**kwargs)


def test_identifiability_falls_with_range():
    near_image, near_sigma = reference("wrinkles", 2)
    far_image, far_sigma = reference("wrinkles_far", 2)
    near = identifiability(Observation(WRINKLES.scene(), near_image, near_sigma), list(WRINKLES.free), WRINKLES.truth)
    far = identifiability(Observation(WRINKLES_FAR.scene(), far_image, far_sigma), list(WRINKLES.free), WRINKLES.truth)
    assert near.stderr["wrinkles.D"] < 0.02
    assert far.stderr["wrinkles.D"] > 3 * near.stderr["wrinkles.D"]
    assert near.fisher_eigenvalues.shape == (2,) and np.all(near.fisher_eigenvalues >= 0)


def test_a_parameter_pushed_to_its_bound_is_reported(tmp_path):
    """A reference brighter than kd = 1 can give: kd ends at its bound, and the fit says so."""
    mesh = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=3)
    bright = small_scene(mesh, {"material": "white_paint", "kd": 0.8}, sun={"irradiance_w_m2": 2000.0},
                         camera={"pixel_pitch_mm": 0.5}, render={"spp": 4})
    scene = small_scene(mesh, {"material": "white_paint", "kd": 0.5}, camera={"pixel_pitch_mm": 0.5}, render={"spp": 4})
    result = fit(Observation(scene, render(bright)), ["parts.sphere.kd"], max_steps=20)
    assert result.values["parts.sphere.kd"] > 0.999
    assert any("upper bound" in w and "parts.sphere.kd" in w for w in result.warnings), result.warnings
    assert result.status is sf.Status.AT_BOUND and not result.success
    assert sf.format_result(result).startswith("failed: a parameter is at a bound")


def test_solver_by_name_or_object_with_its_own_tolerances():
    import optimistix as optx

    from spacefit.fitting.solvers import make_solver, solver_name

    assert isinstance(make_solver("gn"), optx.GaussNewton) and make_solver("lm").rtol == 1e-3
    own = optx.LevenbergMarquardt(rtol=1e-5, atol=1e-9)
    assert make_solver(own) is own and solver_name(own) == "lm"
    assert make_solver("adam") == sf.Adam() and solver_name(sf.Adam(0.1)) == "adam"
    with pytest.raises(InputError, match="solver"):
        make_solver(42)
    with pytest.raises(InputError, match="learning_rate"):
        sf.Adam(learning_rate=0.0)


def test_nothing_of_a_fit_outlives_it(monkeypatch, tmp_path):
    """After sf.fit returns, its problem and its executor (loaded scenes, compiled renders) are
    garbage: JAX's caches kept them, through the solver's function and the renders' callbacks, for
    the life of the process (13.6 MiB per fit; experiments/fit_memory.py measures the memory)."""
    import gc
    import weakref

    from spacefit.fitting import loop

    scene = PANELS.scene().with_values({"render.resolution": [24, 24], "render.spp": 4})
    sf.write_exr(tmp_path / "ref.exr", render(scene.with_values({"parts.legs.kd": 0.5})))
    kept: list[weakref.ref] = []
    executor_of, setup = loop.frame_executor, loop.setup

    def recorded_executor(cluster):
        executor = executor_of(cluster)
        kept.append(weakref.ref(executor))
        return executor

    def recorded_setup(*args, **kwargs):
        s = setup(*args, **kwargs)
        kept.append(weakref.ref(s.problem))
        return s

    monkeypatch.setattr(loop, "frame_executor", recorded_executor)
    monkeypatch.setattr(loop, "setup", recorded_setup)
    result = fit(Observation.from_file(tmp_path / "ref.exr", scene), ["parts.legs.kd"], start={"parts.legs.kd": 0.42}, max_steps=2)
    assert result.steps >= 1
    gc.collect()
    assert len(kept) == 2 and [ref() for ref in kept] == [None, None]
