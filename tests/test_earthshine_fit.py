"""Earthshine in the plate light curve (spacefit/studies/plates.py): the Earth's position the readers
give, the prediction with and without an Earth (unchanged without, the closed form with), each
magnitude's Earthshine share, a fit of a light curve with Earthshine recovering the plate's albedo
that a fit without it misses, and the report's line."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import spacefit as sf
from spacefit.errors import InputError
from spacefit.studies.lightcurve_observations import LightCurveObservations, irradiance_of, magnitude_of
from spacefit.studies.earthshine import VEGETATION
from spacefit.studies.orbit import EARTH_RADIUS_M, in_earth_shadow
from spacefit.studies.plates import plates_irradiance

R = EARTH_RADIUS_M
HEIGHT_M = 550e3
NADIR = (0.0, 0.0, -1.0)


def observations(sun: np.ndarray, observer: np.ndarray, range_m: np.ndarray, magnitude: np.ndarray | None = None,
                 sigma: float | None = None, earth: bool = True) -> LightCurveObservations:
    """Observations of a target at HEIGHT_M in its nadir-sun frame (z up), the Earth's centre below it."""
    n = len(sun)
    earth_m = np.tile([0.0, 0.0, -(R + HEIGHT_M)], (n, 1)) if earth else None
    return LightCurveObservations(np.zeros(n) if magnitude is None else magnitude, None if sigma is None else np.full(n, sigma),
                                  "AB532", sun, observer, range_m, np.zeros(n, bool), None, "simulated", earth_m=earth_m)


def elevated(elevation_deg: np.ndarray) -> np.ndarray:
    """(n, 3) the sun at ``elevation_deg`` above the target's horizontal plane, towards +y."""
    e = np.radians(np.atleast_1d(elevation_deg))
    return np.stack([np.zeros_like(e), np.cos(e), np.sin(e)], axis=1)


def below(n: int, seed: int = 0, widest_deg: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` observers below the target (directions within ``widest_deg`` of nadir) and their ranges (m)."""
    rng = np.random.default_rng(seed)
    tilt, turn = np.radians(rng.uniform(0, widest_deg, n)), rng.uniform(0, 2 * np.pi, n)
    towards = np.stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), -np.cos(tilt)], axis=1)
    return towards, HEIGHT_M / np.cos(tilt)


def test_without_an_earth_the_prediction_is_the_suns_alone_bit_for_bit():
    plates = [sf.Plate("base", 2.0, NADIR, sf.Lambert(0.4)), sf.Plate("array", 5.0, (0.0, 1.0, 0.0), sf.Conductor(1.5, 0.0, 0.2, 0.2))]
    towards, range_m = below(12)
    obs = observations(elevated(np.linspace(-20, 40, 12)), towards, range_m)
    irradiance = np.asarray(plates_irradiance(plates, obs.sun, obs.observer, obs.range_m, 1360.0))
    sun_alone = magnitude_of(irradiance, "AB532", 1360.0)
    np.testing.assert_array_equal(sf.predict_magnitudes(plates, obs), sun_alone)
    np.testing.assert_array_equal(sf.predict_magnitudes(plates, obs, earth=None), sun_alone)
    block = sf.PlateLightCurve(plates, obs).block(("parts.base.kd",))
    with jax.enable_x64(True):  # as the fit runs it
        np.testing.assert_allclose(np.asarray(block.model(np.array([0.4]), 0)), irradiance, rtol=1e-13, atol=0)


def test_a_nadir_plate_under_an_overhead_sun_reflects_the_closed_forms_earthshine():
    """The sun overhead lights only the plate's back (the observer is below): all its light is
    Earthshine, E_sun E_earth (rho / pi) A cos(theta_o) / d^2, E_earth the closed form of
    tests/test_earthshine.py for a Lambert Earth of albedo A on a nadir plate at x = R / r."""
    albedo, rho, area, d, tilt = 0.3, 0.5, 2.0, 900e3, math.radians(35.0)
    x = R / (R + HEIGHT_M)
    k, m, q = 1 - x**2, 1 + x**2, (1 - x) ** 2

    def F(y):
        return -m * k**2 / y - m * y - k**2 * math.log(y) + y**2 / 2

    earth_on_plate = 2 * albedo * x**2 * (F(k) - F(q)) / (16 * x**3)
    obs = observations(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, math.sin(tilt), -math.cos(tilt)]]), np.array([d]))
    plate = sf.Plate("base", area, NADIR, sf.Lambert(rho))
    magnitude, share = sf.predict_magnitudes([plate], obs, earth=sf.Earth(kd=albedo), shares=True)
    expected = 1360.0 * earth_on_plate * rho / math.pi * area * math.cos(tilt) / d**2
    assert irradiance_of(magnitude, "AB532", 1360.0)[0] == pytest.approx(expected, rel=1e-5)
    assert np.isinf(sf.predict_magnitudes([plate], obs)[0]) and share[0] == 1.0


def test_earthshines_share_is_below_one_and_largest_where_the_target_is_near_the_terminator():
    """A nadir plate lit from below by the sun: near the terminator (the sun 2 deg below the target's
    horizontal, grazing the plate) the lit part of the Earth's cap is wide and the sun's term small;
    with the sun 20 deg below it the plate is lit more steeply and the cap under the target is dark."""
    plate = sf.Plate("base", 2.0, NADIR, sf.Lambert(0.5))
    elevation = np.array([-2.0, -5.0, -10.0, -15.0, -20.0])
    obs = observations(elevated(elevation), np.tile([0.0, 0.5, -math.sqrt(0.75)], (5, 1)), np.full(5, 700e3))
    assert not in_earth_shadow(-obs.earth_m, obs.sun).any()
    _, share = sf.predict_magnitudes([plate], obs, earth=sf.Earth(), shares=True)
    assert np.all((share > 0) & (share < 1))
    assert np.all(np.diff(share) < 0) and share[0] > 100 * share[-1]
    _, none = sf.predict_magnitudes([plate], obs, shares=True)
    np.testing.assert_array_equal(none, 0.0)


TILTED = (0.0, math.sqrt(0.5), -math.sqrt(0.5))  # facing down and towards the sun's side


@pytest.fixture(scope="module")
def simulated():
    """A light curve of a plate facing down at 45 deg towards the sun's side (kd 0.4), the sun 0 to 35
    deg above the target's horizontal (lighting it and the Earth below), Earthshine's share 1 to 40 %;
    0.02 mag noise."""
    n = 40
    towards, range_m = below(n, seed=3, widest_deg=40.0)
    exact = observations(elevated(np.linspace(0, 35, n)), towards, range_m)
    magnitude = sf.predict_magnitudes([sf.Plate("base", 3.0, TILTED, sf.Lambert(0.4))], exact, earth=sf.Earth())
    noise = 0.02 * np.random.default_rng(4).standard_normal(n)
    return [sf.Plate("base", 3.0, TILTED, sf.Lambert(0.25))], observations(exact.sun, towards, range_m, magnitude + noise, sigma=0.02)


@pytest.fixture(scope="module")
def fits(simulated):
    """The simulated light curve's kd fitted with Earthshine and without, once for the tests that read them."""
    start, obs = simulated
    return sf.fit_plates(start, obs, ["parts.base.kd"], earth=sf.Earth()), sf.fit_plates(start, obs, ["parts.base.kd"])


def test_a_fit_with_earthshine_recovers_the_albedo_that_one_without_misses(fits):
    with_earth, without = fits
    kd, err = with_earth.values["parts.base.kd"], with_earth.stderr["parts.base.kd"]
    assert abs(kd - 0.4) < 3 * err and with_earth.status is not sf.Status.MISFIT
    # the Earth's light taken for the plate's: biased bright, and the phase curve's shape missed
    assert without.values["parts.base.kd"] - 0.4 > 10 * err and without.status is sf.Status.MISFIT


def test_the_report_says_whether_earthshine_was_included_and_its_share(simulated, fits):
    plates, obs = simulated
    result, plain = fits
    curve = result.observations[0]
    _, share = sf.predict_magnitudes(sf.fitted_plates(plates, result), obs, earth=sf.Earth(), shares=True)
    line = curve.report(result, result.entries[0])[-1]
    assert line == (f"    Earthshine: included (Lambert Earth, albedo 0.3), share median {100 * np.median(share):.3g} %, "
                    f"max {100 * np.max(share):.3g} %")
    assert line in sf.format_result(result)
    assert plain.observations[0].report(plain, plain.entries[0])[-1] == "    Earthshine: not included"
    assert VEGETATION.describe() == "Phong-type Earth, kd 0.53, ks 0.28, n 7.31"


def test_an_earth_is_refused_for_observations_without_the_earths_position():
    plate = sf.Plate("base", 2.0, NADIR, sf.Lambert(0.5))
    towards, range_m = below(3)
    obs = observations(elevated([10.0, 20.0, 30.0]), towards, range_m, earth=False)
    for attempt in (lambda: sf.predict_magnitudes([plate], obs, earth=sf.Earth()),
                    lambda: sf.PlateLightCurve([plate], obs, earth=sf.Earth())):
        with pytest.raises(InputError, match="no Earth position .*earth_x, earth_y, earth_z, or pass earth=None"):
            attempt()
    with pytest.raises(InputError, match="earth.radius_m"):
        sf.predict_magnitudes([plate], observations(obs.sun, towards, range_m), earth=sf.Earth(radius_m=6.0e6))
    with pytest.raises(InputError, match="earth_m"):  # the Earth's centre inside the Earth
        LightCurveObservations(np.zeros(3), None, "AB532", obs.sun, towards, range_m, np.zeros(3, bool), None, "x",
                               earth_m=np.zeros((3, 3)))


def test_observations_take_one_time_a_row_as_an_array():
    """A ragged or short `time_utc` is refused (a ragged one raised NumPy's ValueError: the slow fuzz
    test's find); a list of times is kept as an array, so that a subset picks its rows."""
    towards, range_m = below(3)
    sun, shadow, iso = elevated([10.0, 20.0, 30.0]), np.zeros(3, bool), "2024-01-01T00:00:00"
    for times in ([None, [], "t"], [iso] * 2):
        with pytest.raises(InputError, match=r"`time_utc` must be None or 3 times"):
            LightCurveObservations(np.zeros(3), None, "AB532", sun, towards, range_m, shadow, times, "x")
    listed = LightCurveObservations(np.zeros(3), None, "AB532", sun, towards, range_m, shadow, [iso] * 3, "x")
    assert listed.subset(np.array([0, 2])).time_utc.tolist() == [iso, iso]


def test_the_readers_give_the_earths_centre_below_the_target(tmp_path):
    """From a site's altitude, azimuth and height the Earth's centre is straight below the target (its
    frame's -z) at R + height; the ECSV round trip keeps it and a target-frame file without it has none."""
    path = tmp_path / "site.csv"
    heights = [550e3, 800e3]
    path.write_text("time_utc,magnitude,altitude_deg,azimuth_deg,height_m\n"
                    f"2019-12-09T16:40:00,5.0,40.0,120.0,{heights[0]}\n2019-12-09T16:41:00,5.5,25.0,200.0,{heights[1]}\n")
    read = sf.read_light_curve(path, site=sf.Site(48.0, 2.0, 100.0), band="AB532")
    np.testing.assert_allclose(read.earth_m, [[0.0, 0.0, -(R + h)] for h in heights], atol=1e-6 * R)
    again = sf.read_light_curve(sf.write_light_curve(read, tmp_path / "again.ecsv"))
    np.testing.assert_allclose(again.earth_m, read.earth_m, rtol=1e-15)
    np.testing.assert_array_equal(again.subset(np.array([1])).earth_m, read.earth_m[1:])
    frame = tmp_path / "frame.csv"
    frame.write_text("time_utc,magnitude,sun_x,sun_y,sun_z,observer_x,observer_y,observer_z,range_m\n"
                     "2019-12-09T16:40:00,5.0,0,1,0,0,0,-1,6e5\n")
    assert sf.read_light_curve(frame, band="AB532").earth_m is None
