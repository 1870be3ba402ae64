"""Light curves as observers publish them: the SCORE CSV reader and its refusals, the ECSV round trip,
the geometry computed from a TLE or OMM against SatChecker-style columns, and the Earth's shadow.

The SatChecker-style columns of the hand-made SCORE files are computed here by a second, independent
formulation: SGP4's TEME position turned to the Earth-fixed frame by the GMST 1982 formula written
out (no polar motion), the site on the WGS84 ellipsoid written out, and the sun from the Astronomical
Almanac's low-precision formula (0.01 deg, 1950-2050); spacefit's reader uses astropy's frames and
ephemeris instead. Both share only the SGP4 propagator, as SatChecker (skyfield) does.
"""

from __future__ import annotations

import csv
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import spacefit as sf
from spacefit.errors import InputError
from spacefit.studies.orbit import offline_iers

# The ISS on 2019-12-09 (the sgp4 package's published example); a pass over northern France at dusk.
TLE = ("ISS (ZARYA)\n1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991\n"
       "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482\n")
OMM = {"OBJECT_NAME": "ISS (ZARYA)", "OBJECT_ID": "1998-067A", "EPOCH": "2019-12-09T16:38:29.363424", "MEAN_MOTION": 15.50103472,
       "ECCENTRICITY": 0.0007417, "INCLINATION": 51.6439, "RA_OF_ASC_NODE": 211.2001, "ARG_OF_PERICENTER": 17.6667,
       "MEAN_ANOMALY": 85.6398, "EPHEMERIS_TYPE": 0, "CLASSIFICATION_TYPE": "U", "NORAD_CAT_ID": 25544, "ELEMENT_SET_NO": 999,
       "REV_AT_EPOCH": 20248, "BSTAR": 3.8792e-5, "MEAN_MOTION_DOT": 1.764e-5, "MEAN_MOTION_DDOT": 0.0}
SITE = sf.Site(48.0, 2.0, 100.0)
PASS_TIMES = [f"2019-12-09T16:{m:02d}:{s:02d}.000Z" for m in range(37, 43) for s in (0, 30)]
SHADOW_TIME = "2019-12-09T17:00:00.000Z"  # the ISS in the Earth's shadow (16:46 to 17:14 UTC)
# UT1 - UTC on 2019-12-09 (s), IERS Bulletin A.
DUT1_S = -0.1724
AU_M = 1.495978707e11
# SatChecker's own values for one TLE, site and time (its test's expected values; BSD 3-Clause, data/satchecker/).
SATCHECKER_VALUES = Path(__file__).resolve().parents[1] / "data" / "satchecker" / "iss_2020-05-31.json"
SCORE_COLUMNS = ("satellite_name", "norad_cat_id", "observation_time_utc", "observation_time_uncertainty_sec", "apparent_magnitude",
                 "apparent_magnitude_uncertainty", "observer_latitude_deg", "observer_longitude_deg", "observer_altitude_m",
                 "limiting_magnitude", "instrument", "observing_mode", "observing_filter", "observer_email", "observer_orcid",
                 "comments", "phase_angle_deg_satchecker", "alt_deg_satchecker", "az_deg_satchecker", "range_to_sat_km_satchecker",
                 "sat_altitude_km_satchecker", "solar_elevation_deg_satchecker", "solar_azimuth_deg_satchecker", "illuminated")


def julian_date(iso: str) -> float:
    """The Julian date (UTC) of an ISO 8601 time, by the Fliegel-Van Flandern day count."""
    date, clock = iso.rstrip("Z").split("T")
    y, m, d = (int(v) for v in date.split("-"))
    hh, mm, ss = clock.split(":")
    a = (14 - m) // 12
    yy, mm_ = y + 4800 - a, m + 12 * a - 3
    jdn = d + (153 * mm_ + 2) // 5 + 365 * yy + yy // 4 - yy // 100 + yy // 400 - 32045
    return jdn - 0.5 + (int(hh) + int(mm) / 60 + float(ss) / 3600) / 24


def gmst_rad(jd_ut1: float) -> float:
    """Greenwich mean sidereal time, IAU 1982 (Vallado, Fundamentals of Astrodynamics, eq. 3-45)."""
    t = (jd_ut1 - 2451545.0) / 36525.0
    seconds = 67310.54841 + (876600.0 * 3600 + 8640184.812866) * t + 0.093104 * t**2 - 6.2e-6 * t**3
    return math.radians((seconds % 86400.0) / 240.0)


def to_earth_fixed(v: np.ndarray, theta: float) -> np.ndarray:
    """A vector of the true-equator, mean-equinox frame in the Earth-fixed frame (no polar motion)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


def wgs84(lat_deg: float, lon_deg: float, h_m: float) -> tuple[np.ndarray, np.ndarray]:
    """A site's Earth-fixed position (m) and its east-north-up rows."""
    a, f = 6378137.0, 1 / 298.257223563
    e2, lat, lon = f * (2 - f), math.radians(lat_deg), math.radians(lon_deg)
    n = a / math.sqrt(1 - e2 * math.sin(lat) ** 2)
    position = np.array([(n + h_m) * math.cos(lat) * math.cos(lon), (n + h_m) * math.cos(lat) * math.sin(lon),
                         (n * (1 - e2) + h_m) * math.sin(lat)])
    up = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    return position, np.stack([east, np.cross(up, east), up])


def almanac_sun(jd: float) -> np.ndarray:
    """The sun's geocentric equatorial position (m) by the Astronomical Almanac's low-precision formula."""
    n = jd - 2451545.0
    g = math.radians(357.528 + 0.9856003 * n)
    ecliptic = math.radians(280.460 + 0.9856474 * n + 1.915 * math.sin(g) + 0.020 * math.sin(2 * g))
    obliquity = math.radians(23.439 - 4e-7 * n)
    r = (1.00014 - 0.01671 * math.cos(g) - 0.00014 * math.cos(2 * g)) * AU_M
    return r * np.array([math.cos(ecliptic), math.cos(obliquity) * math.sin(ecliptic), math.sin(obliquity) * math.sin(ecliptic)])


def altaz(enu: np.ndarray) -> tuple[float, float]:
    return math.degrees(math.atan2(enu[2], math.hypot(enu[0], enu[1]))), math.degrees(math.atan2(enu[0], enu[1])) % 360.0


def satchecker(iso: str, site: sf.Site) -> dict[str, object]:
    """SatChecker's columns of the ISS seen from ``site`` at ``iso``, by the independent formulation."""
    from sgp4.api import Satrec

    jd = julian_date(iso)
    _, teme_km, _ = Satrec.twoline2rv(*TLE.splitlines()[1:]).sgp4(math.floor(jd), jd - math.floor(jd))
    theta = gmst_rad(jd + DUT1_S / 86400.0)
    satellite = to_earth_fixed(np.array(teme_km) * 1e3, theta)
    sun = to_earth_fixed(almanac_sun(jd), theta)
    site_position, enu = wgs84(site.latitude_deg, site.longitude_deg, site.height_m)
    seen = satellite - site_position
    alt, az = altaz(enu @ seen)
    sun_alt, sun_az = altaz(enu @ (sun - site_position))
    to_sun, to_site = sun - satellite, -seen
    phase = math.degrees(math.acos(to_sun @ to_site / np.linalg.norm(to_sun) / np.linalg.norm(to_site)))
    s = sun / np.linalg.norm(sun)
    dark = satellite @ s < 0 and np.linalg.norm(satellite - (satellite @ s) * s) < 6378.0e3
    return {"phase_angle_deg_satchecker": phase, "alt_deg_satchecker": alt, "az_deg_satchecker": az,
            "range_to_sat_km_satchecker": np.linalg.norm(seen) / 1e3, "sat_altitude_km_satchecker": (np.linalg.norm(satellite) - 6371e3) / 1e3,
            "solar_elevation_deg_satchecker": sun_alt, "solar_azimuth_deg_satchecker": sun_az, "illuminated": not dark}


def score_row(iso: str, magnitude: float = 2.0, site: sf.Site = SITE, **changes: object) -> dict[str, object]:
    """A SCORE row of the ISS at ``iso`` with its SatChecker columns, then ``changes``."""
    row = {"satellite_name": "ISS (ZARYA)", "norad_cat_id": 25544, "observation_time_utc": iso, "observation_time_uncertainty_sec": 0.02,
           "apparent_magnitude": magnitude, "apparent_magnitude_uncertainty": 0.1, "observer_latitude_deg": site.latitude_deg,
           "observer_longitude_deg": site.longitude_deg, "observer_altitude_m": site.height_m, "limiting_magnitude": 8.0,
           "instrument": "50 mm f/1.4 lens, CMOS camera", "observing_mode": "CMOS", "observing_filter": "Johnson V",
           "observer_email": "observer@example.org", "observer_orcid": "0000-0002-1825-0097", "comments": ""}
    return row | satchecker(iso, site) | changes


def write_score(path: Path, rows: list[dict[str, object]], columns: tuple[str, ...] = SCORE_COLUMNS) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def phase_of(obs: sf.LightCurveObservations) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(obs.sun * obs.observer, axis=1), -1, 1)))


@pytest.fixture(scope="module")
def pass_rows() -> list[dict[str, object]]:
    return [score_row(t, magnitude=1.5 + 0.1 * k) for k, t in enumerate(PASS_TIMES)]


def test_score_reader_takes_the_documented_columns(tmp_path, pass_rows):
    """Magnitudes, errors and band from the file; the target's range and the phase angle from
    SatChecker's columns (the sun by astropy: within 0.05 deg of the file's phase angle)."""
    path = write_score(tmp_path / "score.csv", pass_rows)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obs = sf.read_light_curve(path)
    assert len(obs) == len(PASS_TIMES) and obs.band == "V" and obs.refused == ()
    np.testing.assert_allclose(obs.magnitude, [r["apparent_magnitude"] for r in pass_rows])
    np.testing.assert_allclose(obs.magnitude_sigma, 0.1)
    np.testing.assert_allclose(obs.range_m, [r["range_to_sat_km_satchecker"] * 1e3 for r in pass_rows], rtol=1e-12)
    np.testing.assert_allclose(phase_of(obs), [r["phase_angle_deg_satchecker"] for r in pass_rows], atol=0.05)
    assert not obs.in_shadow.any()
    assert sf.read_light_curve(path, band="AB532").band == "AB532"  # the band stated overrides the filter


def test_score_reader_names_row_column_and_value_of_what_it_refuses(tmp_path, pass_rows):
    rows = [dict(r) for r in pass_rows[:6]]
    rows[1]["observation_time_utc"] = "2019-13-45T99:00:00Z"
    rows[2]["alt_deg_satchecker"] = ""
    rows[3]["apparent_magnitude"] = ""
    rows[4]["observation_time_utc"] = "2999-01-01T00:00:00Z"
    path = write_score(tmp_path / "score.csv", rows)
    with pytest.warns(UserWarning, match=r"4 rows refused .*row 2: observation_time_utc '2019-13-45T99:00:00Z': not an ISO 8601"):
        obs = sf.read_light_curve(path)
    assert len(obs) == 2 and obs.time_utc.tolist() == [rows[0]["observation_time_utc"], rows[5]["observation_time_utc"]]
    assert [(r.row, r.column, r.value) for r in obs.refused] == [
        (2, "observation_time_utc", "2019-13-45T99:00:00Z"), (3, "alt_deg_satchecker", ""), (4, "apparent_magnitude", ""),
        (5, "observation_time_utc", "2999-01-01T00:00:00Z")]
    assert [r.reason.split(" (")[0] for r in obs.refused] == ["not an ISO 8601 time", "missing geometry", "no magnitude",
                                                              "in the future"]
    with pytest.warns(UserWarning, match="before the launch"):
        early = sf.read_light_curve(path, launch_utc="2019-12-09T16:38:00")
    assert {r.row for r in early.refused} == {1, 2, 3, 4, 5} and len(early) == 1
    # a missing geometry is computed from the orbit instead
    with pytest.warns(UserWarning, match="3 rows refused"):
        assert len(sf.read_light_curve(path, orbit=sf.Orbit.from_tle(TLE))) == 3


@pytest.mark.parametrize(("change", "message"), [
    ({"observing_filter": "SDSS g"}, r"row 2's observing_filter 'SDSS g' has no spacefit band .* give `band`"),
    ({"range_to_sat_km_satchecker": "far"}, r"row 2's range_to_sat_km_satchecker must be a number, got 'far'"),
    ({"apparent_magnitude_uncertainty": "-0.1"}, r"row 2's apparent_magnitude_uncertainty must be positive, got '-0.1'"),
    ({"observer_latitude_deg": "91"}, r"row 2: `site.latitude_deg` must be in \[-90, 90\] deg, got 91"),
])
def test_score_reader_refuses_malformed_values_by_name(tmp_path, pass_rows, change, message):
    path = write_score(tmp_path / "score.csv", [pass_rows[0], pass_rows[1] | change])
    with pytest.raises(InputError, match=message):
        sf.read_light_curve(path)


def test_score_reader_names_a_missing_column(tmp_path, pass_rows):
    path = write_score(tmp_path / "score.csv", pass_rows[:2], tuple(c for c in SCORE_COLUMNS if c != "observing_filter"))
    with pytest.raises(InputError, match="the SCORE header lacks observing_filter"):
        sf.read_light_curve(path)
    with pytest.raises(InputError, match="`format` must be one of"):
        sf.read_light_curve(path, format="votable")


def test_geometry_from_a_tle_or_omm_matches_satchecker_columns(tmp_path, pass_rows):
    """Altitude and azimuth within 0.01 deg, the phase angle within 0.05 deg, the range within 100 m
    of the independent formulation's; the OMM of the same elements gives the same geometry."""
    orbit = sf.Orbit.from_tle(TLE)
    assert orbit.name == "ISS (ZARYA)"
    times = [r["observation_time_utc"] for r in pass_rows]
    g = sf.pass_geometry(orbit, SITE, times)
    column = (lambda name: np.array([r[name] for r in pass_rows], dtype=float))
    np.testing.assert_allclose(g.altitude_deg, column("alt_deg_satchecker"), atol=0.01)
    azimuth_off = (g.azimuth_deg - column("az_deg_satchecker") + 180) % 360 - 180
    np.testing.assert_allclose(azimuth_off * np.cos(np.radians(g.altitude_deg)), 0.0, atol=0.01)
    np.testing.assert_allclose(g.phase_deg, column("phase_angle_deg_satchecker"), atol=0.05)
    np.testing.assert_allclose(g.range_m, column("range_to_sat_km_satchecker") * 1e3, atol=100.0)
    np.testing.assert_allclose(g.sun_altitude_deg, column("solar_elevation_deg_satchecker"), atol=0.05)
    from_omm = sf.pass_geometry(sf.Orbit.from_omm(OMM), SITE, times)
    np.testing.assert_allclose(from_omm.position_m, g.position_m, atol=1.0)
    # the reader with the orbit: the SatChecker columns agree, so no warning; one altered, one warning naming it
    path = write_score(tmp_path / "score.csv", pass_rows)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obs = sf.read_light_curve(path, orbit=orbit)
    np.testing.assert_allclose(phase_of(obs), column("phase_angle_deg_satchecker"), atol=0.05)
    np.testing.assert_allclose(obs.range_m, g.range_m)
    write_score(path, [pass_rows[0], pass_rows[1] | {"alt_deg_satchecker": pass_rows[1]["alt_deg_satchecker"] + 0.1}])
    with pytest.warns(UserWarning, match=r"the orbit's altitude differs from the file's alt_deg_satchecker by up to 0.1 deg \(row 2"):
        sf.read_light_curve(path, orbit=orbit)
    with pytest.raises(InputError, match="`tle` must be two element lines"):
        sf.Orbit.from_tle("1 25544U")
    with pytest.raises(InputError, match="OMM .* cannot be read: KeyError 'EPOCH'"):
        sf.Orbit.from_omm({k: v for k, v in OMM.items() if k != "EPOCH"})


def test_geometry_matches_satcheckers_own_values():
    """SatChecker's values (its Skyfield propagation, data/satchecker) at Julian date 2459000.5, which
    SatChecker reads as UT1 (00:00:00.254 UTC): altitude and azimuth within 0.01 deg, the phase angle
    within 0.05 deg, the range within 100 m, the sun within 0.01 deg, in the Earth's shadow as
    SatChecker says. Read as UTC instead, the azimuth is more than 0.01 deg off: UT1 - UTC matters."""
    from astropy.time import Time

    given = json.loads(SATCHECKER_VALUES.read_text())
    orbit, site = sf.Orbit.from_tle("\n".join(given["tle"])), sf.Site(given["latitude_deg"], given["longitude_deg"], given["elevation_m"])
    with offline_iers():
        utc = Time(given["julian_date_ut1"], format="jd", scale="ut1").utc.isot
    g = sf.pass_geometry(orbit, site, [utc])
    assert abs(g.altitude_deg[0] - given["alt_deg"]) < 0.01 and abs(g.azimuth_deg[0] - given["az_deg"]) < 0.01
    assert abs(g.phase_deg[0] - given["phase_angle_deg"]) < 0.05 and abs(g.range_m[0] - given["distance_km"] * 1e3) < 100.0
    assert abs(g.sun_altitude_deg[0] - given["solar_elevation_deg"]) < 0.01 and abs(g.sun_azimuth_deg[0] - given["solar_azimuth_deg"]) < 0.01
    assert g.in_shadow.tolist() == [not given["illuminated"]]
    as_utc = sf.pass_geometry(orbit, site, [Time(given["julian_date_ut1"], format="jd", scale="utc").isot])
    assert abs(as_utc.azimuth_deg[0] - given["az_deg"]) > 0.01


def test_a_target_in_the_earths_shadow_is_flagged(tmp_path):
    """At 17:00 UTC the ISS is in the Earth's cylindrical shadow by the independent formulation and
    by the orbit's; a SCORE row the file calls not illuminated is flagged too."""
    assert satchecker(SHADOW_TIME, SITE)["illuminated"] is False
    g = sf.pass_geometry(sf.Orbit.from_tle(TLE), SITE, [PASS_TIMES[0], SHADOW_TIME])
    assert g.in_shadow.tolist() == [False, True]
    path = write_score(tmp_path / "score.csv", [score_row(PASS_TIMES[0]), score_row(PASS_TIMES[1], illuminated=False),
                                                score_row(SHADOW_TIME)])
    obs = sf.read_light_curve(path, orbit=sf.Orbit.from_tle(TLE))
    assert obs.in_shadow.tolist() == [False, True, True]
    assert sf.read_light_curve(path).in_shadow.tolist() == [False, True, True]


def test_ecsv_round_trip_and_timeseries(tmp_path, pass_rows):
    """Observations written as ECSV read back equal (through read_light_curve and astropy's TimeSeries)."""
    from astropy.timeseries import TimeSeries

    obs = sf.read_light_curve(write_score(tmp_path / "score.csv", pass_rows[:4] + [score_row(SHADOW_TIME)]))
    path = sf.write_light_curve(obs, tmp_path / "lc.ecsv")
    back = sf.read_light_curve(path)
    assert back.band == obs.band and len(back) == len(obs)
    for name in ("magnitude", "magnitude_sigma", "sun", "observer", "range_m"):
        np.testing.assert_allclose(getattr(back, name), getattr(obs, name), rtol=1e-12, err_msg=name)
    assert back.in_shadow.tolist() == obs.in_shadow.tolist() == [False] * 4 + [True]
    np.testing.assert_array_equal([t.rstrip("Z") for t in obs.time_utc], back.time_utc)
    series = TimeSeries.read(path, format="ascii.ecsv")
    np.testing.assert_allclose(series["magnitude"], obs.magnitude)
    assert series.meta["band"] == "V"
