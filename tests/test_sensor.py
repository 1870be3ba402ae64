"""The sensor model, each stage against its closed form: solid angles, electrons, PSF, noise, ADC, distortion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import constants, integrate, optimize, special

from spacefit.errors import InputError
from spacefit.formation import distort_image, expected_dn, expected_electrons, noise_variance_dn, observe
from spacefit.geometry.distortion import Distortion, distort, undistort
from spacefit.geometry.frames import Intrinsics, pixel_solid_angles
from spacefit.formation import choose_exposure
from spacefit.detector import quantise
from spacefit.sensor import Sensor, saturated_mask
from spacefit.psf import AIRY_RADIUS_X, AIRY_RMS_X, PSF_ENERGY, airy_psf, airy_transfer, psf_reach_px, psf_rms_px

THESIS = Intrinsics(7.0, 4e-3, 601, 601)  # Table 4-2's optics; odd size puts a pixel centre on the axis
SHARP = dict(diffraction=False, psf_sigma_px=0.0)


def test_pixel_solid_angles_exact_and_small_pixel_forms():
    # one pixel half as wide as f, centred: a square of side 2a at distance d subtends 4 asin(a^2 / (a^2 + d^2))
    assert pixel_solid_angles(Intrinsics(1.0, 0.5, 1, 1))[0, 0] == pytest.approx(4 * np.arcsin(0.25**2 / (0.25**2 + 1)), rel=1e-12)
    omega = pixel_solid_angles(THESIS)
    # the pixels tile the sensor: their sum is the whole rectangle's solid angle
    assert omega.sum() == pytest.approx(pixel_solid_angles(Intrinsics(7.0, 601 * 4e-3, 1, 1))[0, 0], rel=1e-10)
    # small pixels: (p / f)^2 cos^3(theta) at each pixel centre
    v, u = np.mgrid[0:601, 0:601] + 0.5
    tan2 = ((u - 300.5) ** 2 + (v - 300.5) ** 2) * (4e-3 / 7.0) ** 2
    assert np.allclose(omega, (4e-3 / 7.0) ** 2 / (1 + tan2) ** 1.5, rtol=1e-6)
    shifted = pixel_solid_angles(Intrinsics(7.0, 4e-3, 601, 601, (100.0, 0.0)))
    assert shifted[300, 400] == pytest.approx(omega[300, 300], rel=1e-9)  # the axis follows the principal point


def test_electrons_for_uniform_radiance_are_the_hand_formula():
    sensor = Sensor(quantum_efficiency=0.7, exposure_time_s=2e-3, wavelength_m=(450e-9, 550e-9, 650e-9), **SHARP)
    e = np.asarray(expected_electrons(np.ones((601, 601, 3)), sensor, THESIS))
    area, omega = np.pi * 0.01**2 / 4, (4e-3 / 7.0) ** 2
    for c, lam in enumerate((450e-9, 550e-9, 650e-9)):
        hand = 0.7 * 1.0 * area * omega * 2e-3 / (constants.h * constants.c / lam)
        assert e[300, 300, c] == pytest.approx(hand, rel=1e-6)
        # the corner pixel: cos^4 of its centre's angle off the axis (cos^3 of the solid angle, cos of the aperture)
        tan2 = 2 * (300 * 4e-3 / 7.0) ** 2
        assert e[0, 0, c] == pytest.approx(hand / (1 + tan2) ** 2, rel=1e-5)
    dn = np.asarray(expected_dn(np.ones((601, 601, 3)), sensor, THESIS))
    assert np.allclose(dn, sensor.bias_dn + sensor.gain_dn_per_electron * e)


def _spot(sensor: Sensor, intr: Intrinsics) -> np.ndarray:
    """A single lit pixel at the centre through the sensor's PSF, as the fraction of its electrons in each pixel."""
    spot = np.zeros((intr.height, intr.width, 1))
    spot[intr.height // 2, intr.width // 2] = 1.0
    out = np.asarray(expected_electrons(spot, sensor, intr), dtype=float)[..., 0]
    return out / np.asarray(expected_electrons(spot, Sensor(**{**sensor.to_dict(), **SHARP}), intr)).sum()


def test_gaussian_psf_is_continuous_with_the_stated_width():
    """The optical convention: a continuous Gaussian applied to the pixel-integrated render, so a
    point's blurred image has variance sigma^2 per axis (not sigma^2 + 1/12: no second pixel integration)."""
    intr = Intrinsics(7.0, 4e-3, 41, 41)
    k = _spot(Sensor(psf_sigma_px=1.5, diffraction=False), intr)
    assert k.sum() == pytest.approx(1.0, abs=1e-6)
    offsets = np.arange(41) - 20
    row = k.sum(axis=0)
    assert row @ offsets == pytest.approx(0.0, abs=1e-6)
    assert row @ offsets**2 == pytest.approx(1.5**2, rel=1e-4)
    assert np.allclose(k, np.outer(row, k.sum(axis=1)), atol=1e-7)
    assert np.array_equal(_spot(Sensor(**SHARP), intr)[20, 20], 1.0)
    assert psf_rms_px(Sensor(psf_sigma_px=1.5, diffraction=False), intr, 1) == pytest.approx(1.5)


def test_airy_first_zero_and_transfer_function():
    lam, d = 550e-9, 0.01
    theta = np.linspace(1.0, 1.5, 50001) * lam / d
    assert theta[np.argmin(airy_psf(theta, lam, d))] / (lam / d) == pytest.approx(1.21967, abs=2e-5)
    assert airy_psf(0.0, lam, d) == pytest.approx(np.pi * d**2 / (4 * lam**2))
    # the MTF is the Hankel transform of the Airy pattern: 2 pi int PSF(theta) J0(2 pi nu theta) theta dtheta
    for rho in (0.0, 0.3, 0.8):
        nu = rho * d / lam
        hankel = integrate.quad(lambda t, nu=nu: 2 * np.pi * t * airy_psf(t, lam, d) * special.j0(2 * np.pi * nu * t), 0, 400 * lam / d, limit=2000)[0]
        assert airy_transfer(rho) == pytest.approx(hankel, abs=3e-3)
    assert airy_transfer(1.0) == 0.0 and airy_transfer(2.0) == 0.0
    # a camera whose first dark ring lies 6 px out (band-limited below Nyquist): the blurred spot has its minimum there
    wide = Intrinsics(1.0, 1.21967 * lam / d / 6.0, 64, 64)
    k = _spot(Sensor(psf_sigma_px=0.0), wide)
    assert 0.95 < k.sum() < 1.0 and np.allclose(k[1:, 1:], k[1:, 1:].T, atol=1e-7)  # the far rings leave the 64 px image
    assert np.argmin(k[32, 32:42]) == 6
    # the thesis camera: the Airy disc (0.12 px) is far inside a pixel: a point stays in its pixel
    assert _spot(Sensor(), Intrinsics(7.0, 4e-3, 41, 41))[20, 20] > 0.95
    # diffraction of a huge aperture adds (almost) nothing to a Gaussian
    both = _spot(Sensor(psf_sigma_px=1.5, aperture_diameter_m=2.0), Intrinsics(7.0, 4e-3, 41, 41))
    gauss = _spot(Sensor(psf_sigma_px=1.5, diffraction=False), Intrinsics(7.0, 4e-3, 41, 41))
    assert np.abs(both - gauss).max() < 2e-3


def test_calibrated_sensor_is_scale_times_radiance_plus_bias_without_vignetting():
    """A radiometric scale s (DN per W m^-2 sr^-1): expected DN = s L + bias in every pixel, the
    corners included (vignetting off by default); vignetting on darkens them by cos^4 as for an exposure."""
    intr = Intrinsics(1.0, 0.02, 21, 21)  # wide field: the corners are 19 degrees off axis
    radiance = np.random.default_rng(0).uniform(0.0, 3.0, (21, 21, 2))
    calibrated = Sensor(radiometric_scale_dn_per_w_m2_sr=250.0, bias_dn=90.0, gain_dn_per_electron=0.4, **SHARP)
    assert not calibrated.vignetted
    np.testing.assert_allclose(np.asarray(expected_dn(radiance, calibrated, intr)), 250.0 * radiance + 90.0, rtol=1e-6)
    on = Sensor(**{**calibrated.to_dict(), "vignetting": True})
    tan2 = 2 * (10 * 0.02) ** 2
    dn = np.asarray(expected_dn(np.ones((21, 21, 1)), on, intr))
    assert dn[10, 10, 0] == pytest.approx(340.0, rel=1e-6) and dn[0, 0, 0] == pytest.approx(90.0 + 250.0 / (1 + tan2) ** 2, rel=1e-3)
    # an exposure-model sensor with vignetting off: every pixel collects what the axis pixel does
    flat = np.asarray(expected_electrons(np.ones((21, 21, 1)), Sensor(vignetting=False, **SHARP), intr))
    assert np.allclose(flat, flat[10, 10]) and Sensor(**SHARP).vignetted
    with pytest.raises(InputError, match="radiometric_scale_dn_per_w_m2_sr"):
        Sensor(radiometric_scale_dn_per_w_m2_sr=-1.0)


def test_psf_conserves_the_flux_of_a_spot():
    intr = Intrinsics(7.0, 4e-3, 41, 41)
    spot = np.zeros((41, 41, 1))
    spot[20, 20] = 1.0
    sharp = np.asarray(expected_electrons(spot, Sensor(**SHARP), intr))
    blurred = np.asarray(expected_electrons(spot, Sensor(psf_sigma_px=2.0, diffraction=False), intr))  # the Airy rings reach past the image
    assert blurred.sum() == pytest.approx(sharp.sum(), rel=1e-6)  # float32, as a caller without x64 gets it
    assert blurred[20, 20, 0] < 0.1 * sharp[20, 20, 0]


def test_shot_and_read_noise_over_many_draws():
    intr = Intrinsics(7.0, 4e-3, 128, 128)
    sensor = Sensor(gain_dn_per_electron=2.0, read_noise_electrons=3.0, bias_dn=200.0, quantum_efficiency=1.0, **SHARP)
    per_unit = float(np.asarray(expected_electrons(np.ones((128, 128, 1)), sensor, intr))[64, 64, 0])
    radiance = np.full((128, 128, 3), 40.0 / per_unit)  # 40 electrons on the axis
    mean = np.asarray(expected_dn(radiance, sensor, intr))
    draws = observe(radiance, sensor, intr, seed=1).astype(float)
    n = draws.size
    resid = draws - mean
    var = np.asarray(noise_variance_dn(mean, sensor))
    assert abs(resid.mean()) < 5 * np.sqrt(var.mean() / n)
    assert (resid**2).mean() == pytest.approx(var.mean(), abs=5 * var.mean() * np.sqrt(2 / n))
    assert np.array_equal(observe(radiance, sensor, intr, seed=1), observe(radiance, sensor, intr, seed=1))
    # without read noise and at gain 1 the counts are Poisson: P(0) = exp(-mean)
    poisson = Sensor(gain_dn_per_electron=1.0, read_noise_electrons=0.0, bias_dn=0.0, quantum_efficiency=1.0, **SHARP)
    counts = observe(np.full((128, 128, 3), 2.0 / per_unit), poisson, intr, seed=2).astype(float)
    lam = np.asarray(expected_electrons(np.full((128, 128, 3), 2.0 / per_unit), poisson, intr), dtype=float)
    p0 = np.exp(-lam).mean()
    assert (counts == 0).mean() == pytest.approx(p0, abs=5 * np.sqrt(p0 * (1 - p0) / counts.size))
    assert ((counts - lam) ** 2).mean() == pytest.approx(lam.mean(), rel=0.05)


def test_quantisation_and_saturation():
    s8 = Sensor(bit_depth=8, bias_dn=10.0, full_well_electrons=None)
    q = quantise(np.array([0.4, 0.6, 2.5, 3.5, -3.0, 254.6, 1e9]), s8)
    assert q.dtype == np.uint16 and q.tolist() == [0, 1, 2, 4, 0, 255, 255]
    assert quantise(np.array([70000.2]), Sensor(bit_depth=20, bias_dn=0.0)).dtype == np.uint32
    intr = Intrinsics(7.0, 4e-3, 16, 16)
    with pytest.warns(UserWarning, match="256 of the target's 256 pixels"):
        bright = observe(np.full((16, 16, 3), 1e6), s8, intr, seed=0)
    assert np.all(bright == 255) and np.all(saturated_mask(bright, s8))
    # a full well below the ADC's range: saturated pixels read the well's DN plus read noise
    well = Sensor(full_well_electrons=1000.0, gain_dn_per_electron=1.0, read_noise_electrons=2.0, bias_dn=100.0, **SHARP)
    with pytest.warns(UserWarning, match="saturate at 1094 DN"):
        img = observe(np.full((16, 16, 3), 1e3), well, intr, seed=0)
    assert abs(img.astype(float).mean() - 1100.0) < 1.0 and np.all(saturated_mask(img, well))
    dim = observe(np.full((16, 16, 3), 1e-6), well, intr, seed=0)
    assert not saturated_mask(dim, well).any()
    assert well.saturation_dn == pytest.approx(1100.0 - 3 * 2.0)


def test_distortion_round_trip_and_known_displacement():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.3, 0.3, size=(500, 2))
    c = Distortion(k1=-0.2, k2=0.05, k3=0.01, p1=1e-3, p2=-2e-3)
    assert np.allclose(undistort(distort(pts, c), c), pts, atol=1e-11)
    # pure radial: r_d = r (1 + k1 r^2 + k2 r^4), along any direction
    r = 0.2
    d = distort(np.array([r * np.cos(0.7), r * np.sin(0.7)]), Distortion(k1=0.1, k2=-0.05))
    assert np.hypot(*d) == pytest.approx(r * (1 + 0.1 * r**2 - 0.05 * r**4), rel=1e-12)
    assert np.arctan2(d[1], d[0]) == pytest.approx(0.7)
    # tangential p1 alone moves a point on the x axis along y by p1 x^2
    assert np.allclose(distort(np.array([0.1, 0.0]), Distortion(p1=0.01)), [0.1, 0.01 * 0.1**2])
    # a fold: k1 < 0 makes r_d = r (1 + k1 r^2) peak at r = 1 / sqrt(-3 k1); beyond its height there is no inverse
    assert np.isnan(undistort(np.array([[0.5, 0.0]]), Distortion(k1=-1.0))).all()


def test_distort_image_resamples_a_ramp():
    intr = Intrinsics(7.0, 4e-3, 41, 31)
    v, u = np.mgrid[0:31, 0:41] + 0.5
    ramp = np.stack([u, v], axis=-1)  # an image whose values are its own pixel coordinates
    c = Distortion(k1=2.0)
    out = np.asarray(distort_image(ramp, intr, c))
    assert np.allclose(np.asarray(distort_image(ramp, intr, Distortion()))[1:-1, 1:-1], ramp[1:-1, 1:-1])
    # along the central row (y = 0): x_d = x + k1 x^3, so the pinhole u is the cubic's real root
    f_px, (u0, v0) = intr.focal_px, intr.principal_point
    for col in (5, 12, 30):
        xd = (col + 0.5 - u0) / f_px
        x = [r.real for r in np.roots([2.0, 0.0, 1.0, -xd]) if abs(r.imag) < 1e-12][0]
        assert out[15, col, 0] == pytest.approx(u0 + f_px * x, abs=1e-5)  # float32 resampling
    assert out[15, 20, 1] == pytest.approx(v0) and v0 == 15.5  # the centre stays put


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"exposure_time_s": 0.0}, ["Sensor.exposure_time_s", "(0, 86400] s", "got 0"]),
        ({"quantum_efficiency": 1.2}, ["Sensor.quantum_efficiency", "(0, 1]", "1.2"]),
        ({"wavelength_m": (550.0,)}, ["Sensor.wavelength_m[0]", "550"]),
        ({"bit_depth": 40}, ["Sensor.bit_depth", "[1, 32]", "40"]),
        ({"bias_dn": 5000.0, "bit_depth": 12}, ["Sensor.bias_dn", "4095", "5000"]),
        ({"read_noise_electrons": float("nan")}, ["Sensor.read_noise_electrons"]),
        ({"full_well_electrons": -1.0}, ["Sensor.full_well_electrons"]),
        ({"psf_sigma_px": 1e300}, ["Sensor.psf_sigma_px", "[0, 100] px", "1e+300"]),  # aborted in XLA (the slow fuzz test's find)
    ],
)
def test_bad_sensor_values_are_refused(kwargs, words):
    with pytest.raises(InputError) as err:
        Sensor(**kwargs)
    for w in words:
        assert w in str(err.value)


def test_bad_radiance_is_refused_before_any_work():
    intr = Intrinsics(7.0, 4e-3, 8, 8)
    bad = np.ones((8, 8, 3))
    bad[0, 0, 0], bad[1, 1, 1] = -1.0, np.nan
    with pytest.raises(InputError, match="2 values"):
        expected_dn(bad, Sensor(), intr)
    with pytest.raises(InputError, match=r"\(8, 8, c\)"):
        expected_dn(np.ones((8, 9, 3)), Sensor(), intr)
    with pytest.raises(InputError, match="2 wavelengths for an image of 3 channels"):
        expected_dn(np.ones((8, 8, 3)), Sensor(wavelength_m=(5e-7, 6e-7)), intr)
    with pytest.raises(InputError, match="Distortion.k1"):
        Distortion(k1=float("inf"))


def test_expected_dn_and_distortion_differentiate_in_jax():
    import jax

    intr = Intrinsics(7.0, 4e-3, 12, 10)
    sensor = Sensor(psf_sigma_px=1.0)
    radiance = np.random.default_rng(0).uniform(0.0, 0.1, size=(10, 12, 3))
    tangent = np.random.default_rng(1).uniform(0.0, 1.0, size=(10, 12, 3))
    _, jvp = jax.jvp(lambda r: expected_dn(r, sensor, intr), (radiance,), (tangent,))
    # linear in the radiance: the derivative along a tangent is the tangent's own DN less the bias
    assert np.allclose(jvp, np.asarray(expected_dn(tangent, sensor, intr)) - sensor.bias_dn, rtol=1e-6)  # float32 round-off
    c = Distortion(k1=0.5)
    grad = jax.grad(lambda r: distort_image(r, intr, c).sum())(radiance)
    assert grad.shape == radiance.shape and np.isfinite(grad).all() and grad.sum() > 0


def test_flat_field_multiplies_the_signal_above_the_bias():
    intr = Intrinsics(1.0, 0.02, 6, 5)
    radiance = np.random.default_rng(1).uniform(0.0, 2.0, (5, 6, 3))
    flat = np.random.default_rng(2).uniform(0.8, 1.2, (5, 6))
    sensor = Sensor(radiometric_scale_dn_per_w_m2_sr=100.0, bias_dn=20.0, **SHARP)
    np.testing.assert_allclose(np.asarray(expected_dn(radiance, sensor, intr, flat)), 100.0 * radiance * flat[..., None] + 20.0, rtol=1e-6)
    with pytest.raises(InputError, match="`flat` must be finite and > 0 .*; 1 values are not"):
        expected_dn(radiance, sensor, intr, np.where(np.arange(30).reshape(5, 6) == 7, 0.0, flat))
    with pytest.raises(InputError, match=r"`flat` has shape \(6, 5\); the image is \(5, 6, 3\)"):
        expected_dn(radiance, sensor, intr, flat.T)


def test_the_chosen_exposure_puts_the_targets_percentile_at_its_fraction_and_saturation_warns():
    """sf.choose_exposure on a render: the target's 99.9th percentile lands at 80 % of full scale
    (within 2 %, noise-free and in one noisy observation) and sf.observe stays quiet; 1.5x that
    exposure saturates more than 0.1 % of the target's pixels, and sf.observe says so."""
    import warnings

    from spacefit.cases import load_case
    from spacefit.rendering.exr import read_exr

    radiance = read_exr(Path(__file__).resolve().parents[1] / "data/synthetic/panels/reference.exr")
    intr = Intrinsics.from_scene(load_case("panels").scene())
    for sensor in (Sensor(psf_sigma_px=0.7), Sensor(bit_depth=16, full_well_electrons=None, gain_dn_per_electron=1.0)):
        chosen = choose_exposure(radiance, sensor, intr)
        target = radiance.max(axis=-1) > 0
        full = chosen.saturation_dn - chosen.bias_dn
        expected = (np.asarray(expected_dn(radiance, chosen, intr)) - chosen.bias_dn).max(axis=-1)[target]
        assert np.percentile(expected, 99.9) == pytest.approx(0.8 * full, rel=1e-6)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            dn = observe(radiance, chosen, intr, seed=3).astype(float)
        assert np.percentile((dn - chosen.bias_dn).max(axis=-1)[target], 99.9) == pytest.approx(0.8 * full, rel=0.02)
        longer = Sensor(**{**chosen.to_dict(), "exposure_time_s": 1.5 * chosen.exposure_time_s})
        with pytest.warns(UserWarning, match=r"pixels \([0-9.]+ %, more than 0.1 %\) saturate"):
            observe(radiance, longer, intr, seed=3)
    half = choose_exposure(radiance, Sensor(), intr, fraction=0.5, percentile=50.0)
    assert np.median((np.asarray(expected_dn(radiance, half, intr)) - half.bias_dn).max(axis=-1)[radiance.max(axis=-1) > 0]) == \
        pytest.approx(0.5 * (half.saturation_dn - half.bias_dn), rel=1e-6)


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"fraction": 0.0}, "`fraction` must be in (0, 1]"),
    ({"percentile": 101.0}, "`percentile` must be in (0, 100]"),
    ({"target": np.zeros((4, 4), bool)}, "no target pixels"),
    ({"target": np.ones((3, 4), bool)}, "`target` must be a boolean (height, width) = (4, 4)"),
    ({"sensor": Sensor(radiometric_scale_dn_per_w_m2_sr=100.0)}, "`sensor` is calibrated"),
])
def test_choose_exposure_refuses_bad_input(kwargs, words):
    args = {"radiance": np.ones((4, 4, 3)), "sensor": Sensor(), "intrinsics": Intrinsics(7.0, 4e-3, 4, 4), **kwargs}
    with pytest.raises(InputError) as err:
        choose_exposure(**args)
    assert words in str(err.value)


def test_the_airy_radius_and_rms_width_solve_their_equations():
    """The radius holding PSF_ENERGY of the Airy pattern's energy, 1 - J0^2 - J1^2 = PSF_ENERGY (Rayleigh), and the
    rms width within it, X sqrt((J1^2 - J0 J2) / (2 (1 - J0^2 - J1^2))) (Watson 5.11), as psf.py writes them out."""
    x = optimize.brentq(lambda x: 1.0 - special.j0(x) ** 2 - special.j1(x) ** 2 - PSF_ENERGY, 1e-6, 1e6)
    j0, j1, j2 = (special.jv(n, x) for n in (0, 1, 2))
    assert AIRY_RADIUS_X == pytest.approx(x, rel=1e-12)
    assert AIRY_RMS_X == pytest.approx(x * np.sqrt((j1**2 - j0 * j2) / (2.0 * (1.0 - j0**2 - j1**2))), rel=1e-12)


def test_the_psf_reaches_five_sigma_and_its_widths_add_in_quadrature():
    """A 2 px Gaussian reaches ceil(5 x 2) = 10 px; with diffraction, the rms width is the Gaussian's and the
    Airy pattern's in quadrature (independent blurs' variances add)."""
    intrinsics = Intrinsics(7.0, 4e-3, 64, 64)
    gaussian = Sensor(psf_sigma_px=2.0, diffraction=False)
    assert psf_reach_px(gaussian, intrinsics, 550e-9) == 10
    airy = psf_rms_px(Sensor(psf_sigma_px=0.0, diffraction=True, aperture_diameter_m=2e-3), intrinsics, 1)
    both = psf_rms_px(Sensor(psf_sigma_px=2.0, diffraction=True, aperture_diameter_m=2e-3), intrinsics, 1)
    assert airy > 0.5 and both == pytest.approx(np.hypot(2.0, airy), rel=1e-12)


def test_a_sensor_s_integer_values_past_int32_are_held_as_floats_and_model_the_dn():
    """A gain of 2**31 DN per electron given as an integer: held as a float, the expected DN its hand formula (JAX
    refused the integer past int32's range with an OverflowError; found by test_fuzz_long's sensor)."""
    camera = Intrinsics(focal_length=0.05, pixel_pitch=5e-5, width=8, height=8)
    big = Sensor(gain_dn_per_electron=2**31, bias_dn=100, psf_sigma_px=0, diffraction=False)
    assert all(type(getattr(big, f)) is float for f in ("gain_dn_per_electron", "bias_dn", "psf_sigma_px"))
    radiance = np.full((8, 8, 3), 0.1)
    np.testing.assert_allclose(expected_dn(radiance, big, camera), 100.0 + 2.0**31 * expected_electrons(radiance, big, camera), rtol=1e-12)
