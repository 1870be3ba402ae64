"""Observations from files and their masks: `Observation.mask` in every residual path, the
degrees of freedom and the noise floor, and `Observation.from_file` for EXR, FITS and PNG."""

from __future__ import annotations

import dataclasses
import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from astropy.io import fits
from helpers import small_scene, write_sphere_obj

import spacefit as sf
from spacefit.fitting.problem import setup
from spacefit.fitting.stopping import loss_noise
from spacefit.imageio import sidecar_path
from spacefit.precision import float64
from spacefit.rendering.exr import write_exr
from spacefit.rendering.png import write_png
from spacefit.scene.assembly import assemble
from spacefit.sensor import read_sensor_file

TRUE_KD = 0.5
# 32 x 32 px: bright enough for about 2000 DN on the sphere in a 12-bit sensor; no full well.
SENSOR = sf.Sensor(exposure_time_s=1e-6, gain_dn_per_electron=0.5, bias_dn=50.0, bit_depth=12, full_well_electrons=None)
SQUARE = (slice(4, 12), slice(14, 22))  # on the sphere's lit limb


@pytest.fixture(scope="module")
def sphere(tmp_path_factory):
    """A 32 x 32 Lambert sphere: the truth (kd 0.5, 16 spp, seed 7), the scene to fit (kd 0.3, 4 spp), a mask without SQUARE."""
    d = tmp_path_factory.mktemp("obs")
    mesh = write_sphere_obj(d / "sphere.obj", subdivisions=3)
    sections = {"camera": {"pixel_pitch_mm": 0.5}, "sun": {"direction": [0.3, 0.2, -1.0]}}
    truth = small_scene(mesh, {"material": "white_paint", "kd": TRUE_KD}, render={"spp": 16, "seed": 7}, **sections)
    scene = small_scene(mesh, {"material": "white_paint", "kd": 0.3}, render={"spp": 4}, **sections)
    mask = np.ones((32, 32), dtype=bool)
    mask[SQUARE] = False
    return d, scene, np.asarray(sf.render(truth), float), mask


def _garbage(image: np.ndarray, value: float) -> np.ndarray:
    out = image.copy()
    out[SQUARE] = value
    return out


def _fit(observation: sf.Observation) -> float:
    return sf.fit(observation, ["parts.sphere.kd"], max_steps=6, render=sf.FitRender(spp=4)).values["parts.sphere.kd"]


@pytest.mark.parametrize("sensor", [None, SENSOR], ids=["radiance", "dn"])
def test_masked_garbage_changes_nothing_and_its_residuals_are_zero(sphere, sensor):
    """A bright square under the mask: the same fitted kd as the clean image under the
    same mask (to 1e-6: two fits of the same problem differ by up to 7e-8 relative, float32 sums in threads); unmasked, the bright square pulls kd away. Masked residuals and Jacobian
    rows, NaN under the mask too, are 0 (so neither the degrees of freedom nor the noise floor counts them)."""
    d, scene, truth, mask = sphere
    clean = truth if sensor is None else sf.observe(truth, sensor, assemble(scene).intrinsics, seed=1).astype(float)
    bright = 10.0 * clean.max() if sensor is None else 0.9 * sensor.saturation_dn  # not saturated: left to the mask

    def obs(image: np.ndarray, m: np.ndarray | None) -> sf.Observation:
        return sf.Observation(scene, image, sensor=sensor, mask=m)

    kd_clean = _fit(obs(clean, mask))
    assert abs(kd_clean - TRUE_KD) < 0.03
    assert _fit(obs(_garbage(clean, bright), mask)) == pytest.approx(kd_clean, rel=1e-6)
    assert abs(_fit(obs(_garbage(clean, bright), None)) - kd_clean) > 0.05  # the test can fail

    @float64
    def rows():
        s = setup(obs(_garbage(clean, np.nan), mask), ["parts.sphere.kd"])
        x = jnp.asarray(s.x0)
        return (np.asarray(s.problem.residual_x(x)), np.asarray(jax.jacfwd(s.problem.residual_x)(x)),
                np.asarray(s.problem.residual_x_independent(x)))

    r, J, r_alt = rows()
    out = ~np.broadcast_to(mask[..., None], (32, 32, 3)).ravel()
    assert np.all(r[out] == 0) and np.all(J[out] == 0) and np.all(r_alt[out] == 0)
    assert np.count_nonzero(r[~out]) > 100
    assert loss_noise(r, r_alt) == loss_noise(r[~out], r_alt[~out])


def test_mask_is_checked(sphere):
    _, scene, truth, mask = sphere
    with pytest.raises(sf.InputError, match="`Observation.mask` must be a bool array.*got dtype int64"):
        sf.Observation(scene, truth, mask=mask.astype(np.int64))
    with pytest.raises(sf.InputError, match=r"`Observation.mask` is False everywhere \(1024 values\)"):
        sf.Observation(scene, truth, mask=np.zeros((32, 32), dtype=bool))
    with pytest.raises(sf.InputError, match=r"mask 0 .* has shape \(16, 32, 1\); its reference is \(32, 32, 3\)"):
        sf.fit(sf.Observation(scene, truth, mask=np.ones((16, 32), dtype=bool)), ["parts.sphere.kd"])
    with pytest.raises(sf.InputError, match=r"reference 0 holds NaN or infinite pixels \(64\); leave them out with its mask"):
        sf.fit(sf.Observation(scene, _garbage(truth, np.nan)), ["parts.sphere.kd"])
    with pytest.raises(sf.InputError, match="reference 0 holds 64 pixels with negative values"):
        sf.fit(sf.Observation(scene, _garbage(truth, -1.0)), ["parts.sphere.kd"])


@pytest.mark.parametrize("name", ["obs.fits", "obs.png"])
def test_from_file_round_trip_gives_the_sensor_and_the_dn(sphere, tmp_path, name):
    _, scene, truth, _ = sphere
    dn = sf.observe(truth, SENSOR, assemble(scene).intrinsics, seed=2)
    dn[0, 0] = SENSOR.adc_max_dn  # one saturated pixel
    sf.write_observation(tmp_path / name, dn, SENSOR)
    obs = sf.Observation.from_file(tmp_path / name, scene)
    assert obs.sensor == SENSOR and obs.sigma is None
    assert np.array_equal(obs.reference, dn.astype(float))
    assert np.array_equal(obs.mask, dn < SENSOR.saturation_dn) and not obs.mask[0, 0].any()
    # a sensor given whole replaces the file's; a mapping replaces the fields it names
    other = sf.Sensor(bit_depth=16)
    assert sf.Observation.from_file(tmp_path / name, scene, sensor=other).sensor == other
    assert sf.Observation.from_file(tmp_path / name, scene, sensor={"read_noise_electrons": 2.0}).sensor == sf.Sensor(
        **{**SENSOR.to_dict(), "read_noise_electrons": 2.0})


def test_from_file_refuses_dn_without_a_sensor_and_takes_a_sensor_file(sphere, tmp_path):
    _, scene, truth, _ = sphere
    dn = sf.observe(truth, SENSOR, assemble(scene).intrinsics, seed=2)
    sf.write_observation(tmp_path / "obs.png", dn, SENSOR)
    sidecar_path(tmp_path / "obs.png").unlink()
    with pytest.raises(sf.InputError, match="obs.png' holds DN .*needs 8 sensor value.*: exposure_time_s .or radiometric_scale"):
        sf.Observation.from_file(tmp_path / "obs.png", scene, response="linear")
    (tmp_path / "sensor.json").write_text(json.dumps(SENSOR.to_dict()))
    obs = sf.Observation.from_file(tmp_path / "obs.png", scene, response="linear", sensor_file=tmp_path / "sensor.json")
    assert obs.sensor == SENSOR and np.array_equal(obs.reference, dn.astype(float))
    assert obs.sensor_sources["bias_dn"] == "sensor file" and obs.sensor_sources["diffraction"] == "sensor file"
    # a foreign FITS with EXPTIME and GAIN and a sensor file of bias and bits only: what is missing is
    # named with its three ways, never filled in silently
    header = fits.Header([("EXPTIME", 2e-6), ("GAIN", 4.0), ("ROWORDER", "TOP-DOWN")])
    fits.PrimaryHDU(dn[:, :, 0].astype(np.int32), header=header).writeto(tmp_path / "foreign.fits")
    (tmp_path / "sensor.toml").write_text("[sensor]\nbias_dn = 50.0\nbit_depth = 12\n")
    with pytest.raises(sf.InputError) as refused:
        sf.Observation.from_file(tmp_path / "foreign.fits", scene, sensor_file=tmp_path / "sensor.toml")
    message = str(refused.value)
    for missing in ("aperture_diameter_m", "wavelength_m", "quantum_efficiency", "read_noise_electrons", "psf_sigma_px"):
        assert f"{missing} " in message, missing
    assert "header keyword RDNOISE / READNOIS / RON / HIERARCH SPACEFIT SENSOR read_noise_electrons; sensor file key " \
           "read_noise_electrons (--sensor FILE); option --sensor-value read_noise_electrons=VALUE" in message
    assert "sensor_defaults='illustrative' (--sensor-defaults illustrative)" in message and "exposure_time_s" not in message
    # the illustrative defaults only when asked for by name, and named as such
    obs = sf.Observation.from_file(tmp_path / "foreign.fits", scene, sensor_file=tmp_path / "sensor.toml", sensor_defaults="illustrative")
    assert obs.sensor == sf.Sensor(exposure_time_s=2e-6, gain_dn_per_electron=0.25, bias_dn=50.0, bit_depth=12)
    assert obs.sensor_sources["exposure_time_s"] == "header EXPTIME" and obs.sensor_sources["gain_dn_per_electron"] == "header GAIN"
    assert obs.sensor_sources["quantum_efficiency"] == "default (illustrative)" and obs.sensor_sources["bit_depth"] == "sensor file"
    assert obs.reference.shape == (32, 32, 1) and np.array_equal(obs.reference, dn[..., :1])  # one channel: grey
    # or every missing value as an argument
    given = {"aperture_diameter_m": 0.01, "wavelength_m": [5.5e-7], "quantum_efficiency": 0.6, "read_noise_electrons": 5.0,
             "psf_sigma_px": 0.0, "full_well_electrons": 20000.0}
    obs = sf.Observation.from_file(tmp_path / "foreign.fits", scene, sensor_file=tmp_path / "sensor.toml", sensor=given)
    assert obs.sensor == sf.Sensor(exposure_time_s=2e-6, gain_dn_per_electron=0.25, bias_dn=50.0, bit_depth=12)
    assert obs.sensor_sources["read_noise_electrons"] == "option/argument" and obs.sensor_sources["diffraction"].startswith("rule: on")
    with pytest.raises(sf.InputError, match="`sensor_defaults` must be one of 'illustrative'"):
        sf.Observation.from_file(tmp_path / "foreign.fits", scene, sensor_defaults="typical")


def test_cli_refuses_a_missing_sensor_value_and_writes_nothing(sphere, tmp_path, capsys):
    """The CLI: exit 2 naming the missing value and the three ways; the fit folder is not made."""
    from spacefit.cli import main

    d, scene, truth, _ = sphere
    dn = sf.observe(truth, SENSOR, assemble(scene).intrinsics, seed=2)
    fits.PrimaryHDU(dn[::-1, :, 0].astype(np.uint16), header=fits.Header([
        ("ROWORDER", "BOTTOM-UP"), ("EXPTIME", 1e-6), ("GAIN", 2.0), ("BIAS", 50.0), ("SATURATE", 4095.0), ("PSFSIGMA", 0.0)])).writeto(tmp_path / "cam.fits")
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    args = ["fit", str(tmp_path / "cam.fits"), "--scene", str(tmp_path / "scene.toml"), "--free", "parts.sphere.kd", "--out", str(tmp_path / "out")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "read_noise_electrons: header keyword RDNOISE" in err and "--sensor-value read_noise_electrons=VALUE" in err
    assert "aperture_diameter_m (or radiometric_scale_dn_per_w_m2_sr)" in err
    assert not (tmp_path / "out").exists()
    assert main([*args, "--sensor-value", "read_noise_electrons=x"]) == 2
    assert "`--sensor-value read_noise_electrons=x`: 'x' is not a number" in capsys.readouterr().err


@pytest.mark.parametrize("text, suffix, match", [
    ('{"bitdepth": 12}', ".json", "field` must be one of .*Did you mean 'bit_depth'"),
    ("bit_depth = 40", ".toml", r"`Sensor.bit_depth` must be an integer in \[1, 32\], got 40"),
    ("bit_depth = ", ".toml", "could not be read as TOML"),
    ("{}", ".yaml", "must be .json or .toml, got '.yaml'"),
])
def test_bad_sensor_files_are_refused(tmp_path, text, suffix, match):
    path = tmp_path / f"sensor{suffix}"
    path.write_text(text)
    with pytest.raises(sf.InputError, match=match):
        read_sensor_file(path)


def test_from_file_radiance_refusals_and_masked_nan(sphere, tmp_path):
    d, scene, truth, mask = sphere
    write_exr(tmp_path / "nan.exr", _garbage(truth, np.nan).astype(np.float32))
    with pytest.raises(sf.InputError, match="nan.exr': 64 pixels are NaN or infinite"):
        sf.Observation.from_file(tmp_path / "nan.exr", scene)
    obs = sf.Observation.from_file(tmp_path / "nan.exr", scene, mask=mask)  # a dead region the user masked
    assert obs.sensor is None and np.all(obs.reference[SQUARE] == 0) and np.array_equal(obs.mask[..., 0], mask)
    write_exr(tmp_path / "low.exr", _garbage(truth, -0.01).astype(np.float32))
    with pytest.raises(sf.InputError, match="low.exr': 64 pixels have negative radiance"):
        sf.Observation.from_file(tmp_path / "low.exr", scene)
    assert sf.Observation.from_file(tmp_path / "low.exr", scene, sigma=0.01).sigma == 0.01  # within 8 sigma
    with pytest.raises(sf.InputError, match="holds radiance .*`sensor` describes the camera of a DN image"):
        sf.Observation.from_file(tmp_path / "nan.exr", scene, mask=mask, sensor=SENSOR)
    write_png(tmp_path / "preview.png", np.full((32, 32, 3), 200, dtype=np.uint8))
    with pytest.raises(sf.InputError, match="8-bit PNG: a display image; it holds digital numbers, not radiance"):
        sf.Observation.from_file(tmp_path / "preview.png", scene, unit="radiance")


# SENSOR's exposure saturates the sphere's brightest pixels, which the part means would count.
DIM = dataclasses.replace(SENSOR, exposure_time_s=4e-7)


@pytest.mark.parametrize("sensor", [None, DIM], ids=["radiance", "dn"])
def test_the_fits_model_image_is_in_the_references_unit(sphere, sensor):
    """A fit's renders, part means and comparison are in its reference's unit: DN with a sensor
    (the sensor's expected DN of the render, bias included), radiance without. The part means
    count only the fitted pixels (here a square of NaN is masked out)."""
    _, scene, truth, mask = sphere
    reference = truth if sensor is None else sf.observe(truth, sensor, assemble(scene).intrinsics, seed=1).astype(float)
    observation = sf.Observation(scene, _garbage(reference, np.nan), sensor=sensor, mask=mask)
    result = sf.fit(observation, ["parts.sphere.kd"], max_steps=6, render=sf.FitRender(spp=4))
    unit = "W m^-2 sr^-1" if sensor is None else "DN"
    assert result.units == [unit]
    suffix = "w_m2_sr" if sensor is None else "dn"
    target = result.parts[0]["target"]
    assert target[f"fit_mean_{suffix}"] == pytest.approx(target[f"reference_mean_{suffix}"], rel=0.03)
    assert target["pixels"] == int((sf.Renderer(scene).part_image().ids >= 0)[mask].sum())
    # a corner sees black sky: 0 radiance, or the sensor's bias (read noise 2.5 DN rms) and the far
    # rings of the Airy pattern (0.04 DN here)
    sky, rings = (0.0, 1e-6) if sensor is None else (sensor.bias_dn, 0.1)
    assert result.renders[0][0, 0, 0] == pytest.approx(sky, abs=rings) and reference[0, 0, 0] == pytest.approx(sky, abs=10.0)
    if sensor is not None:
        assert not sf.saturated_mask(reference, sensor).any() and result.renders[0].max() > 100 * truth.max()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the masked NaN is shown as 0, with no warning
        axes = sf.plot_comparison(result, [observation.reference])
    assert unit.split()[0] in axes[0, 0].get_title()


def test_a_grey_observation_counts_each_pixel_once(sphere):
    """A one-channel image is one measurement per pixel, not three copies: with the noise known, its
    errors are sqrt(3) those of an RGB image whose three channels are independent exposures of the
    same light (photon-limited, render noise negligible at 256 spp), and a fit of it works."""
    _, scene, truth, _ = sphere
    dim = dataclasses.replace(SENSOR, exposure_time_s=1e-7, read_noise_electrons=1.0)
    intrinsics = assemble(scene).intrinsics
    grey = sf.observe(truth[..., :1], dim, intrinsics, seed=3).astype(float)
    rgb = sf.observe(truth, dim, intrinsics, seed=4).astype(float)
    assert grey.shape == (32, 32, 1)
    errors = [sf.identifiability(sf.Observation(scene, image, sensor=dim), ["parts.sphere.kd"], {"parts.sphere.kd": TRUE_KD},
                                 spp=256).stderr["parts.sphere.kd"] for image in (grey[..., 0], rgb)]
    assert errors[0] / errors[1] == pytest.approx(np.sqrt(3.0), rel=0.1)
    result = sf.fit(sf.Observation(scene, grey, sensor=dim), ["parts.sphere.kd"], max_steps=6, render=sf.FitRender(spp=4))
    assert abs(result.values["parts.sphere.kd"] - TRUE_KD) < 4 * result.stderr["parts.sphere.kd"]
    assert result.renders[0].shape == (32, 32, 1)
    sf.plot_comparison(result, [grey])


@pytest.mark.slow  # 13 s on a quiet machine (the suite is over its 10 min)
def test_a_continuous_gaussian_psf_of_08_px_is_fitted_within_its_error_with_the_pixel_grid_carried():
    """The optical convention end to end, made as issue 34's hidden observations: the panels case
    rendered with a box filter at 4x the resolution, blurred there by a continuous Gaussian of 0.8 px
    and binned 4 x 4 (the pixel integrates the blurred image); fitted at 1x with the box filter, the
    blur and the exposure scale free. On the pixel grid the glints alias and the fit's model gives
    0.767 px (noise-free; spacefit.fitting.pixel_grid): the result steps (by 0.034) to the model made
    with one render at 4x the resolution, 0.801, says so, and carries a bound on what remains (a
    third of the step from the model made at 2x to the 4x one: 0.002 px) in its standard error,
    which then holds the truth. (A blur integrated over the pixel again would give about 0.75.)"""
    from spacefit.fitting.nuisance import blur

    case, n = sf.load_case("panels"), 32
    grid = {"render.resolution": [n, n], "camera.pixel_pitch_mm": 18.75 * 128 / n, "render.filter": "box"}
    fine = case.truth_scene.with_values({**grid, "render.resolution": [4 * n, 4 * n], "camera.pixel_pitch_mm": 18.75 * 32 / n,
                                         "render.spp": 64})
    sharp = jnp.asarray(sf.render(fine), dtype=jnp.float32)
    camera = np.asarray(blur(sharp, 4.0 * 0.8), dtype=float)
    reference = np.maximum(camera.reshape(n, 4, n, 4, 3).mean(axis=(1, 3)), 0.0)  # FFT round-off leaves -1e-8 in the sky
    result = sf.fit(sf.Observation(case.truth_scene.with_values({**grid, "render.spp": 16}), reference),
                    ["image.blur_sigma_px", "image.scale"], start={"image.blur_sigma_px": 0.5}, render=sf.FitRender(spp=16), max_steps=10)
    sigma, stderr = result.values["image.blur_sigma_px"], result.stderr["image.blur_sigma_px"]
    step, remainder = (result.extras[f"pixel_grid_{e}"]["image.blur_sigma_px"] for e in ("error", "remainder"))
    assert abs(sigma - 0.8) < stderr and 0.02 < step and 0.001 < remainder < stderr, (sigma, stderr, step, remainder)
    assert any(w.startswith("image.blur_sigma_px: the pixel grid's model error") for w in result.warnings), result.warnings


def test_from_file_takes_a_flat_field_and_a_calibrated_header(sphere, tmp_path):
    """A calibrated camera's FITS (RADSCALE) with a flat-field file: the model's DN is
    flat x scale x radiance + bias, and the flat is refused for radiance."""
    _, scene, truth, _ = sphere
    cards = [("ROWORDER", "TOP-DOWN"), ("RADSCALE", 400.0), ("GAIN", 2.0), ("RDNOISE", 3.0), ("BIAS", 50.0), ("PSFSIGMA", 0.0)]
    fits.PrimaryHDU(np.full((32, 32), 60, dtype=np.uint16), header=fits.Header(cards)).writeto(tmp_path / "cal.fits")
    flat = np.linspace(0.9, 1.1, 32 * 32).reshape(32, 32)
    fits.PrimaryHDU(flat, header=fits.Header([("ROWORDER", "TOP-DOWN")])).writeto(tmp_path / "flat.fits")
    obs = sf.Observation.from_file(tmp_path / "cal.fits", scene, flat=tmp_path / "flat.fits")
    assert np.array_equal(obs.flat[..., 0], flat) and obs.sensor_sources["bit_depth"] == "header BITPIX"
    s = setup(obs, ["parts.sphere.kd"])
    model = np.asarray(s.problem.renders_x(jnp.asarray(s.x0))[0])[..., 0]
    np.testing.assert_allclose(model, 50.0 + 400.0 * flat * np.asarray(sf.render(scene), float).mean(axis=-1), rtol=2e-4, atol=1e-3)
    write_exr(tmp_path / "r.exr", truth.astype(np.float32))
    with pytest.raises(sf.InputError, match="holds radiance"):
        sf.Observation.from_file(tmp_path / "r.exr", scene, flat=flat)
