"""Times past the leap-second table (spacefit.timescales): a pass or a light curve in 2035 is read and
converted with no ERFA "dubious year" warning, and its frames' seconds are exact."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import spacefit as sf
from spacefit.fitting.passes import elapsed_seconds
from spacefit.studies.orbit import Site, sun_directions_enu, utc_times
from spacefit.timescales import quiet_future_utc

FUTURE = ["2035-06-01T00:00:00", "2035-06-01T00:00:10", "2035-06-01T00:00:20.25"]


@pytest.fixture
def warnings_are_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def test_a_pass_in_2035_reads_without_warnings_and_its_seconds_are_exact(warnings_are_errors):
    assert elapsed_seconds(FUTURE) == [0.0, 10.0, 20.25]
    frames = sf.Pass.from_columns({"file": ["a.exr", "b.exr", "c.exr"], "time": FUTURE,
                                   "sun.elevation_deg": [30.0] * 3, "sun.azimuth_deg": [0.0] * 3})
    assert [f.time_s for f in frames.frames] == [0.0, 10.0, 20.25]


def test_sun_directions_in_2035_without_warnings(warnings_are_errors):
    enu = sun_directions_enu(FUTURE, Site(latitude_deg=52.0, longitude_deg=5.0, height_m=0.0))
    assert enu.shape == (3, 3) and np.allclose(np.linalg.norm(enu, axis=1), 1.0)
    assert enu[0, 2] < 0  # midnight UT in the Netherlands: the sun below the horizon
    assert len(utc_times(FUTURE)) == 3


def test_only_the_dubious_year_is_silenced():
    from astropy.time import Time

    @quiet_future_utc
    def convert():
        Time(FUTURE, scale="utc").tai  # noqa: B018  (the conversion ERFA warns of)
        warnings.warn("another warning", UserWarning, stacklevel=1)

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        convert()
    assert [str(w.message) for w in seen] == ["another warning"]
    with pytest.warns(Warning, match="dubious year"):
        Time(FUTURE, scale="utc").tai  # noqa: B018  (astropy still warns outside spacefit)
