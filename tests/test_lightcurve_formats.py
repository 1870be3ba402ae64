"""MMT-9 track downloads and CCSDS TDMs with MAG, and the rules every light-curve format keeps:
impossible rows reported (never silently dropped or used), magnitudes in a named band, a target in
the Earth's shadow flagged.

The hand-made files hold the ISS's pass over northern France of tests/test_lightcurve_files.py, their
geometry columns from its independent formulation of SatChecker's (not from spacefit's)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import test_lightcurve_files as iss
from hypothesis import given, settings
from hypothesis import strategies as st

import spacefit as sf
from spacefit.errors import InputError

ORBIT = sf.Orbit.from_tle(iss.TLE)
TIMES = iss.PASS_TIMES[:6]
MMT_HEADER = ("# satellite: 25544 ISS (ZARYA) / ISS\n# catalogue: 1 NORAD\n# track: 101\n# variability: 0 Not variable\n"
              "# variability_period: 0.0\n# npoints: {n}\n#\n# Date Time StdMag Mag Filter Penumbra Distance Phase Channel\n")


def mmt_line(iso: str, mag: object = 2.0, filt: str = "V", penumbra: object = 0, **changes: object) -> str:
    """An MMT-9 track line at ``iso`` with the independent formulation's distance and phase angle."""
    geometry = iss.satchecker(iso, iss.SITE)
    values = {"time": iso.rstrip("Z").replace("T", " ") + "000", "stdmag": 0.5, "mag": mag, "filter": filt, "penumbra": penumbra,
              "distance": f"{geometry['range_to_sat_km_satchecker']:.3f}", "phase": f"{geometry['phase_angle_deg_satchecker']:.4f}",
              "channel": 3} | changes
    return " ".join(str(v) for v in values.values())


def write_mmt(path: Path, lines: list[str]) -> Path:
    path.write_text(MMT_HEADER.format(n=len(lines)) + "\n".join(lines) + "\n")
    return path


def phase_of(obs: sf.LightCurveObservations) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(obs.sun * obs.observer, axis=1), -1, 1)))


def test_mmt9_track_with_its_orbit(tmp_path):
    """Found from the file; the geometry the orbit's, agreeing with the file's Distance and Phase (no
    warning); band V, no errors stated; Penumbra 1 and the orbit's Earth shadow both flagged."""
    lines = [mmt_line(t, 2.0 + 0.1 * k) for k, t in enumerate(TIMES)] + [mmt_line(iss.PASS_TIMES[6], penumbra=1),
                                                                          mmt_line(iss.SHADOW_TIME)]
    path = write_mmt(tmp_path / "track_101.txt", lines)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obs = sf.read_light_curve(path, orbit=ORBIT, site=iss.SITE)
    assert len(obs) == 8 and obs.band == "V" and obs.magnitude_sigma is None and obs.refused == ()
    np.testing.assert_allclose(obs.magnitude[:6], 2.0 + 0.1 * np.arange(6))
    expected = [iss.satchecker(t, iss.SITE) for t in [*TIMES, iss.PASS_TIMES[6]]]
    np.testing.assert_allclose(phase_of(obs)[:7], [e["phase_angle_deg_satchecker"] for e in expected], atol=0.05)
    np.testing.assert_allclose(obs.range_m[:7], [e["range_to_sat_km_satchecker"] * 1e3 for e in expected], atol=100.0)
    assert obs.in_shadow.tolist() == [False] * 6 + [True, True]
    # a Distance 5 km off: warned of by name, the orbit's used
    write_mmt(path, [lines[0], mmt_line(TIMES[1], distance=float(mmt_line(TIMES[1]).split()[6]) + 5.0)])
    with pytest.warns(UserWarning, match=r"the orbit's range differs from the file's Distance by up to 5 km \(row 2"):
        sf.read_light_curve(path, orbit=ORBIT, site=iss.SITE)
    # MMT-9's own site by default: the ISS is then seen elsewhere, so the file's Distance disagrees
    with pytest.warns(UserWarning, match="the orbit's phase differs from the file's Phase"), \
            pytest.warns(UserWarning, match="the orbit's range differs from the file's Distance by up to 2.94e"):
        assert sf.read_light_curve(path, orbit=ORBIT, format="mmt9").range_m[0] > 2000e3


def test_mmt9_rows_refused_by_row_column_and_value(tmp_path):
    lines = [mmt_line(TIMES[0]), mmt_line(TIMES[1], time="2019-13-45 99:00:00"), mmt_line(TIMES[2], mag="None"),
             mmt_line(TIMES[3], filt="B"), mmt_line(TIMES[4], time="2999-01-01 00:00:00"), mmt_line(TIMES[5], penumbra="None")]
    path = write_mmt(tmp_path / "track.txt", lines)
    with pytest.warns(UserWarning, match="5 rows refused"):
        obs = sf.read_light_curve(path, orbit=ORBIT, site=iss.SITE)
    assert len(obs) == 1
    assert [(r.row, r.column, r.value) for r in obs.refused] == [
        (2, "Date Time", "2019-13-45 99:00:00"), (3, "Mag", "None"), (4, "Filter", "B"), (5, "Date Time", "2999-01-01 00:00:00"),
        (6, "Penumbra", "None")]
    assert [r.reason.split(" (")[0] for r in obs.refused] == ["not an ISO 8601 time", "no magnitude", "another filter than the one read",
                                                              "in the future", "missing"]
    with pytest.raises(InputError, match=r"no usable rows: row 1: Date Time '2019-12-09 16:37:00.000000': before the launch"):
        sf.read_light_curve(path, orbit=ORBIT, site=iss.SITE, launch_utc="2019-12-09T16:37:10")


@pytest.mark.parametrize(("lines", "options", "message"), [
    ([mmt_line(TIMES[0])], {}, r"an MMT-9 track gives the distance and phase angle, not where the satellite was: give `orbit`"),
    ([mmt_line(TIMES[0]), mmt_line(TIMES[1], channel="3 7")], {"orbit": ORBIT}, r"row 2 has 10 values, the header 9"),
    ([mmt_line(TIMES[0], mag="bright")], {"orbit": ORBIT}, r"row 1's Mag must be a number \(or None\), got 'bright'"),
    ([mmt_line(TIMES[0], penumbra=2)], {"orbit": ORBIT}, r"row 1's Penumbra must be 0 or 1, got '2'"),
    ([mmt_line(TIMES[0], filt="Clear")], {"orbit": ORBIT}, r"the track's filters \(Clear\) have no spacefit band .* give `band`"),
    ([mmt_line(TIMES[0], filt="B"), mmt_line(TIMES[1], filt="R")], {"orbit": ORBIT, "band": "V"},
     r"the track's rows are in filters B, R, none of band V"),
])
def test_mmt9_malformed_tracks_are_named(tmp_path, lines, options, message):
    path = write_mmt(tmp_path / "track.txt", lines)
    with pytest.raises(InputError, match=rf"light curve .*track.txt: {message}"):
        sf.read_light_curve(path, site=iss.SITE, **options)


def test_mmt9_band_stated_for_an_unfiltered_track(tmp_path):
    path = write_mmt(tmp_path / "track.txt", [mmt_line(t, filt="Clear") for t in TIMES[:2]])
    assert sf.read_light_curve(path, orbit=ORBIT, site=iss.SITE, band="V").band == "V"


def tdm(data: str, meta: str = "TIME_SYSTEM = UTC\nPARTICIPANT_1 = ISS\nPARTICIPANT_2 = OBSERVER\nPATH = 1,2\nANGLE_TYPE = AZEL\n"
        "RANGE_UNITS = km\n") -> str:
    return ("CCSDS_TDM_VERS = 2.0\nCOMMENT hand-made\nCREATION_DATE = 2019-12-10T00:00:00\nORIGINATOR = SPACEFIT\n"
            f"META_START\n{meta}META_STOP\nDATA_START\n{data}DATA_STOP\n")


def tdm_lines(iso: str, mag: float = 2.0, geometry: bool = True, tag: str | None = None) -> str:
    """A TDM's MAG line at ``iso`` and, with ``geometry``, the AZEL angles and range by the independent formulation."""
    g, tag = iss.satchecker(iso, iss.SITE), tag or iso.rstrip("Z")
    out = f"MAG = {tag} {mag}\n"
    if geometry:
        out += (f"ANGLE_1 = {tag} {g['az_deg_satchecker']:.6f}\nANGLE_2 = {tag} {g['alt_deg_satchecker']:.6f}\n"
                f"RANGE = {tag} {g['range_to_sat_km_satchecker']:.5f}\n")
    return out


def test_tdm_mag_with_azel_and_range(tmp_path):
    """Found from the file; the geometry from its AZEL angles and range seen from the site gives the
    independent formulation's phase angle (0.05 deg); an orbit agrees with the angles (no warning);
    a day-of-year time is read; the magnitude correction is added where not applied."""
    data = "".join(tdm_lines(t, 2.0 + 0.1 * k) for k, t in enumerate(TIMES[:5]))
    data += tdm_lines(TIMES[5], 2.5, tag="2019-343T" + TIMES[5].split("T")[1].rstrip("Z"))
    path = tmp_path / "iss.tdm"
    path.write_text(tdm(data))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obs = sf.read_light_curve(path, site=iss.SITE)
        with_orbit = sf.read_light_curve(path, site=iss.SITE, orbit=ORBIT)
    assert len(obs) == 6 and obs.band == "V" and obs.magnitude_sigma is None and obs.refused == ()
    np.testing.assert_allclose(obs.magnitude, 2.0 + 0.1 * np.arange(6))
    expected = [iss.satchecker(t, iss.SITE) for t in TIMES]
    np.testing.assert_allclose(phase_of(obs), [e["phase_angle_deg_satchecker"] for e in expected], atol=0.05)
    np.testing.assert_allclose(obs.range_m, [e["range_to_sat_km_satchecker"] * 1e3 for e in expected], atol=0.01)
    np.testing.assert_allclose(phase_of(with_orbit), phase_of(obs), atol=0.05)
    assert obs.time_utc[5] == TIMES[5].rstrip("Z") and not obs.in_shadow.any()
    assert sf.read_light_curve(path, site=iss.SITE, band="AB532").band == "AB532"
    corrected = path.read_text().replace("ANGLE_TYPE = AZEL", "ANGLE_TYPE = AZEL\nCORRECTIONS_APPLIED = NO\nCORRECTION_MAG = -0.25")
    path.write_text(corrected)
    np.testing.assert_allclose(sf.read_light_curve(path, site=iss.SITE).magnitude, 1.75 + 0.1 * np.arange(6))
    path.write_text(corrected.replace("CORRECTIONS_APPLIED = NO", "CORRECTIONS_APPLIED = YES"))
    np.testing.assert_allclose(sf.read_light_curve(path, site=iss.SITE).magnitude, 2.0 + 0.1 * np.arange(6))


@pytest.mark.parametrize(("system", "offset_s"), [("TAI", 37.0), ("GPS", 18.0), ("TT", 69.184)])
def test_tdm_time_systems_are_converted_to_utc(tmp_path, system, offset_s):
    """2019-12-09: TAI - UTC = 37 s, GPS - UTC = 18 s, TT - UTC = 69.184 s."""
    from astropy.time import Time, TimeDelta

    shifted = (Time(TIMES[0].rstrip("Z"), scale="utc") + TimeDelta(offset_s, format="sec")).utc.isot
    path = tmp_path / "iss.tdm"
    path.write_text(tdm(tdm_lines(TIMES[0], tag=shifted), meta=f"TIME_SYSTEM = {system}\nPARTICIPANT_1 = ISS\n"))
    obs = sf.read_light_curve(path, site=iss.SITE, orbit=ORBIT)
    assert abs((Time(obs.time_utc[0], scale="utc") - Time(TIMES[0].rstrip("Z"), scale="utc")).sec) < 1e-3


@pytest.mark.parametrize(("text", "message"), [
    (tdm(tdm_lines(TIMES[0]), meta="TIME_SYSTEM = MET\nPARTICIPANT_1 = ISS\n"), r"TIME_SYSTEM must be one of UTC, .*, got 'MET'"),
    (tdm(tdm_lines(TIMES[0]), meta="PARTICIPANT_1 = ISS\n"), r"a segment's metadata lacks TIME_SYSTEM \(it has PARTICIPANT_1\)"),
    (tdm(tdm_lines(TIMES[0])).replace("META_START\n", ""), r"line 11: META_STOP where META_START belongs"),
    ("CCSDS_TDM_VERS = 2.0\nDATA_START\nMAG = 2019-12-09T16:37:00 2.0\nDATA_STOP\n", r"line 2: DATA_START where META_START belongs"),
    (tdm("MAG = 2019-12-09T16:37:00 bright\n"), r"line 14: MAG's value must be a number, got 'bright'"),
    (tdm("MAG = 2019-12-09T16:37:00\n"), r"line 14: MAG's value must be a time and a number"),
    (tdm(tdm_lines(TIMES[0])).replace("DATA_STOP\n", ""), r"the last segment is not closed"),
    ("META_START\nTIME_SYSTEM = UTC\n", r"line 1: a TDM starts with CCSDS_TDM_VERS, got 'META_START'"),
    (tdm(tdm_lines(TIMES[0]).replace("ANGLE_2 = 2019-12-09T16:37:00.000 ", "ANGLE_2 = 2019-12-09T16:37:00.000 9")),
     r"line 16: ANGLE_2 at 2019-12-09T16:37:00.000 must be an elevation in \[-90, 90\] deg, got 913.207"),
])
def test_tdm_malformed_messages_are_named(tmp_path, text, message):
    path = tmp_path / "bad.tdm"
    path.write_text(text)
    with pytest.raises(InputError, match=rf"light curve .*bad.tdm: {message}"):
        sf.read_light_curve(path, site=iss.SITE, format="tdm")


def test_tdm_refusals_site_and_shadow(tmp_path):
    """A MAG without geometry refused (kept with an orbit), an unreadable or future time refused; the
    site required; a target in the Earth's shadow by the file's own angles and range flagged."""
    data = (tdm_lines(TIMES[0]) + tdm_lines(TIMES[1], geometry=False) + "MAG = 2019-12-09T25:61:00 2.0\n"
            + "MAG = 2999-01-01T00:00:00 2.0\n" + tdm_lines(iss.SHADOW_TIME))
    path = tmp_path / "iss.tdm"
    path.write_text(tdm(data))
    with pytest.warns(UserWarning, match="3 rows refused"):
        obs = sf.read_light_curve(path, site=iss.SITE)
    assert [(r.row, r.column, r.value) for r in obs.refused] == [(18, "ANGLE_1", ""), (19, "MAG", "2019-12-09T25:61:00"),
                                                                  (20, "MAG", "2999-01-01T00:00:00")]
    assert [r.reason.split(" (")[0] for r in obs.refused] == ["missing geometry", "its time is not ISO 8601", "in the future"]
    assert obs.in_shadow.tolist() == [False, True]
    with pytest.warns(UserWarning, match="2 rows refused"):
        assert sf.read_light_curve(path, site=iss.SITE, orbit=ORBIT).in_shadow.tolist() == [False, False, True]
    with pytest.raises(InputError, match="a TDM names its participants but not where they are: give the observer's `site`"):
        sf.read_light_curve(path)


def test_general_and_pomenis_rows_that_cannot_be_right(tmp_path):
    """The general and Pomenis formats: a time before the launch refused and reported, a missing
    geometry value an error naming row and column, the file's in_shadow flag kept."""
    path = tmp_path / "lc.csv"
    path.write_text("time_utc,magnitude,sun_x,sun_y,sun_z,observer_x,observer_y,observer_z,range_m,in_shadow\n"
                    "2019-12-09T16:37:00,5.0,0,1,0,0,0,-1,1e6,False\n2019-12-09T16:38:00,5.0,0,1,0,0,0,-1,1e6,True\n"
                    "2018-01-01T00:00:00,5.0,0,1,0,0,0,-1,1e6,False\n")
    with pytest.warns(UserWarning, match=r"1 rows refused .*row 3: time_utc '2018-01-01T00:00:00': before the launch"):
        obs = sf.read_light_curve(path, band="V", launch_utc="2019-01-01T00:00:00")
    assert obs.in_shadow.tolist() == [False, True] and [r.row for r in obs.refused] == [3]
    path.write_text("observation_time,satellite_height,satellite_altitude,satellite_azimuth,ab_magnitude\n"
                    "2019-12-09T16:37:00,550,40,120,5.1\n2019-12-09T16:38:00,,40,120,5.1\n")
    with pytest.raises(InputError, match="row 2's satellite_height must be a number, got ''"):
        sf.read_light_curve(path, site=iss.SITE)


TOKENS = ["", "None", "nan", "inf", "-1", "0", "1e300", "V", "B", "Clear", "2", "META_START", "META_STOP", "DATA_START", "DATA_STOP",
          "MAG", "=", "2019-343T16:37:00", "2019-12-09T16:37:00", "TIME_SYSTEM = MET", "#", "x"]


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(data=st.data())
def test_mutated_mmt9_and_tdm_files_are_read_or_refused_by_name(tmp_path_factory, data):
    """A valid track or message with a few tokens replaced or lines dropped: read (finite magnitudes,
    unit directions, every row used or refused) or a one-line InputError naming the file."""
    kind = data.draw(st.sampled_from(["mmt9", "tdm"]))
    if kind == "mmt9":
        text = MMT_HEADER.format(n=3) + "\n".join(mmt_line(t) for t in TIMES[:3]) + "\n"
    else:
        text = tdm("".join(tdm_lines(t) for t in TIMES[:2]))
    lines = [line.split(" ") for line in text.splitlines()]
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(lines) - 1))
        if data.draw(st.booleans()) or len(lines[i]) == 0:
            del lines[i]
        else:
            lines[i][data.draw(st.integers(0, len(lines[i]) - 1))] = data.draw(st.sampled_from(TOKENS))
        if not lines:
            break
    path = tmp_path_factory.mktemp("mutated") / f"lc.{kind}"
    path.write_text("\n".join(" ".join(line) for line in lines) + "\n")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            obs = sf.read_light_curve(path, site=iss.SITE, orbit=ORBIT, format=kind)
    except InputError as err:
        assert str(err).startswith(f"light curve {path}: ") and "\n" not in str(err)
        return
    assert len(obs) > 0 and np.all(np.isfinite(obs.magnitude)) and np.all(obs.range_m > 0)
    np.testing.assert_allclose(np.linalg.norm(obs.sun, axis=1), 1.0)
    if kind == "mmt9":
        rows = [line for line in lines if line and line[0] and not line[0].startswith("#")]
    else:
        starts = [i for i, line in enumerate(lines) if line == ["DATA_START"]]
        rows = [line for line in lines[starts[0]:] if line[0] == "MAG"] if starts else []
    assert len(obs) + len(obs.refused) == len(rows)  # every row used or refused, none dropped
