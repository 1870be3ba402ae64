"""Every kind of observation as one observation of sf.fit with its own report and figure: a pass
given whole (sf.PassObservation) fits bit for bit as its frames' images with per-frame names do, it
fits jointly with a plate light curve of its legs, and each kind's report lines and figure show the
result's own numbers (the figure's residuals are the result's)."""

from __future__ import annotations

import numpy as np
import pytest

import spacefit as sf
from spacefit.scene.names import Name
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.lightcurve_observations import LightCurveObservations

OPTIONS = {"start": {"parts.legs.kd": 0.4}, "render": sf.FitRender(spp=4), "max_steps": 2}


@pytest.fixture(scope="module")
def tiny_pass(tmp_path_factory):
    """Two frames at 16 x 16 px (radiance at 16 spp) whose target is turned 0.2 and -0.2 deg about x."""
    folder = tmp_path_factory.mktemp("kinds") / "frames"
    base = sf.load_scene("spacefit/synthetic/panels.toml", {"render.resolution": [16, 16], "camera.pixel_pitch_mm": 150.0})
    frames = sf.simulate_pass(base, sf.arc_pass(2), folder, errors=[{"target.attitude_x_deg": e} for e in (0.2, -0.2)], spp=16)
    return base, frames


@pytest.fixture(scope="module")
def light_curve():
    """Magnitudes of a Lambert plate named like the pass's legs, kd 0.5, at 12 geometries (0.05 mag)."""
    rng = np.random.default_rng(3)
    n = 12
    e, a = np.radians(rng.uniform(30, 70, (2, n))), np.radians(rng.uniform(0, 360, (2, n)))
    sun, observer = (np.stack([np.cos(e[i]) * np.cos(a[i]), np.cos(e[i]) * np.sin(a[i]), np.sin(e[i])], axis=1) for i in range(2))

    def curve(magnitude: np.ndarray, kd: float) -> sf.PlateLightCurve:
        data = LightCurveObservations(magnitude, np.full(n, 0.05), "AB532", sun, observer, np.full(n, 6e5), np.zeros(n, bool), None, "test")
        return sf.PlateLightCurve([sf.Plate("legs", 2.0, (0, 0, 1), sf.Lambert(kd))], data)

    exact = sf.predict_magnitudes(curve(np.zeros(n), 0.5).plates, curve(np.zeros(n), 0.5).observations)
    return curve(exact + 0.05 * rng.standard_normal(n), 0.4)


def test_a_pass_observation_fits_as_its_frames_images_bit_for_bit(tiny_pass):
    base, frames = tiny_pass
    images = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(base))]
    listed = sf.fit(images, ["parts.legs.kd", *frames.per_frame(["target.attitude_x_deg"])], **OPTIONS)
    whole = sf.PassObservation.read(frames, base, per_frame=["target.attitude_x_deg"])
    given = sf.fit(whole, ["parts.legs.kd"], **OPTIONS)
    assert given.names == listed.names
    assert [Name(n).observation for n in given.names] == [None, 0, 1]
    assert given.values == listed.values and given.stderr == listed.stderr and given.status is listed.status
    assert [h["loss"] for h in given.history] == [h["loss"] for h in listed.history]
    assert given.entries == ((0, 1),) and given.observations == (whole,)
    # its report: one line per frame with its time, chi^2 / dof and own value
    lines = whole.report(given, given.entries[0])
    for k, line in enumerate(lines[1:]):
        value = given.values[f"target.attitude_x_deg@{k}"]
        assert f"frame {k} at {10.0 * k:.6g} s" in line and f"{given.observation_goodness[k].chi2_dof:.3g}" in line
        assert f"target.attitude_x_deg = {value:.6g}" in line
    assert "\n".join(lines) in sf.format_result(given)
    # its figure: each frame's own value against time, then chi^2 / dof
    axes = whole.plot(given, given.entries[0])
    x, y = axes[0].lines[0].get_data()
    assert list(x) == [0.0, 10.0] and list(y) == [given.values[f"target.attitude_x_deg@{k}"] for k in range(2)]


def test_a_pass_and_a_light_curve_fit_jointly_and_each_reports_its_part(tiny_pass, light_curve):
    base, frames = tiny_pass
    whole = sf.PassObservation.read(frames, base, per_frame=["target.attitude_x_deg"])
    result = sf.fit([light_curve, whole], ["parts.legs.kd"], **OPTIONS)
    # the light curve comes first as given, its values after the images' in the per-observation lists
    assert result.entries == ((2,), (0, 1)) and result.units[2] == "W m^-2"
    assert "target.attitude_x_deg@0" in result.names and "target.attitude_x_deg@1" in result.names
    text = sf.format_result(result)
    assert f"observation 2 (W m^-2 values): {result.observation_goodness[2].line()}" in text and "pass of 2 frames" in text
    # the light curve's figure: observed and predicted magnitudes against the phase angle, and their difference
    axes = light_curve.plot(result, result.entries[0])
    predicted = np.asarray(result.renders[2])
    observed = predicted + np.asarray(result.residuals[2])
    sun_magnitude, sun_irradiance = light_curve.zero_point()
    data_x, data_y = axes[0].lines[0].get_data()
    diff_y = axes[1].lines[0].get_ydata()
    np.testing.assert_allclose(data_y, light_curve.observations.magnitude, rtol=0, atol=1e-9)
    np.testing.assert_allclose(diff_y, -2.5 * np.log10(observed / predicted), rtol=0, atol=1e-9)
    obs = light_curve.observations
    np.testing.assert_allclose(data_x, np.degrees(np.arccos(np.sum(obs.sun * obs.observer, axis=1))))
    assert sun_irradiance == light_curve.sun_irradiance_w_m2 and sun_magnitude == SUN_MAGNITUDES["AB532"]


def test_a_brdf_tables_figure_is_its_values_against_angle_and_the_results_residuals():
    rng = np.random.default_rng(1)
    n = 20
    theta = np.radians(rng.uniform(5, 70, (2, n)))
    wi, wo = (np.stack([np.sin(t), np.zeros(n), np.cos(t)], axis=1) for t in theta)
    value = 0.6 / np.pi * np.exp(0.03 * rng.standard_normal(n))
    result = sf.fit_brdf_table(sf.BRDFTable(wi, wo, value, None, "test"), "lambert", relative_error=0.03)
    table, entries = result.observations[0], result.entries[0]
    assert entries == (0,)
    assert table.report(result, entries) == [f"  observation 0 (sr^-1 values): {result.observation_goodness[0].line()}"]
    axes = table.plot(result, entries)
    x, measured = axes[0].lines[0].get_data()
    np.testing.assert_allclose(x, np.degrees(theta[1]))
    np.testing.assert_allclose(measured, value, rtol=1e-12)
    np.testing.assert_array_equal(axes[1].lines[0].get_ydata(), result.residuals[0])
    assert axes[0].get_yscale() == "log"


def test_an_images_report_is_its_chi2_by_part_and_its_figure_its_residual(tiny_pass):
    base, frames = tiny_pass
    image = sf.Observation.from_file(frames.frames[0].file, frames.scenes(base)[0])
    result = sf.fit(image, ["parts.legs.kd"], **OPTIONS)
    (line,) = image.report(result, (0,))
    assert line.startswith("  mean r^2 / render noise, observation 0: ") or line.startswith("  chi^2 per value, observation 0: ")
    assert line in sf.format_result(result)
    axes = image.plot(result, (0,))
    shown = axes[0].images[0].get_array()
    x0, x1, y1, y0 = (round(v + 0.5) for v in axes[0].images[0].get_extent())
    np.testing.assert_allclose(shown.filled(np.nan), np.asarray(result.residuals[0]).mean(axis=-1)[y0:y1, x0:x1], equal_nan=True)
