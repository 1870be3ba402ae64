"""Where things are seen from a site: the sun, a satellite from its orbit (TLE or OMM), the Earth's shadow.

Everything runs offline. The satellite is propagated by SGP4 (Vallado et al. 2006, "Revisiting
Spacetrack Report #3", AIAA 2006-6753; the ``sgp4`` package) to its TEME position, turned into the
Earth-fixed ITRS frame by astropy (GMST 1982 and polar motion from astropy's bundled IERS tables),
and seen from the site (WGS84 geodetic latitude, longitude, height) in the site's east-north-up
frame: altitude and azimuth are geometric (no refraction, no light time; as SatChecker gives them).
The sun is astropy's ``get_sun`` (no ephemeris download). No IERS table is ever downloaded
(``astropy.utils.iers.conf.auto_download`` is off while the geometry is computed): past the bundled
tables' end UT1 - UTC is taken as 0 with astropy's warning (a satellite then lands up to 0.03 deg off).

The Earth's shadow is a cylinder (the sun's rays parallel, no penumbra; the penumbra's width at
550 km is about 60 km, 0.5 deg of the terminator): the target is in shadow where its position r
from the Earth's centre has r . s < 0 and |r - (r . s) s| < R, R = :data:`EARTH_RADIUS_M`.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_range, check_type, quote
from spacefit.timescales import quiet_future_utc

# The Earth's (equatorial) radius, m, as lumos-sat takes it (a sphere).
EARTH_RADIUS_M = 6378.0e3


@dataclass(frozen=True)
class Site:
    """An observer on the Earth: geodetic latitude and longitude (deg, east positive), height (m).

    Args:
        latitude_deg: geodetic latitude (deg), in [-90, 90].
        longitude_deg: longitude (deg, east positive), in [-180, 360].
        height_m: height above the WGS84 ellipsoid (m).

    Raises:
        InputError: a value out of range, naming it.

    Example:
        >>> import spacefit as sf
        >>> sf.Site(latitude_deg=52.0, longitude_deg=4.4)
        Site(latitude_deg=52.0, longitude_deg=4.4, height_m=0.0)
    """

    latitude_deg: float
    longitude_deg: float
    height_m: float = 0.0

    def __post_init__(self) -> None:
        check_range("site.latitude_deg", self.latitude_deg, -90.0, 90.0, unit="deg")
        check_range("site.longitude_deg", self.longitude_deg, -360.0, 360.0, unit="deg")
        check_range("site.height_m", self.height_m, -500.0, 1e4, unit="m")


@contextmanager
def offline_iers() -> Iterator[None]:
    """astropy's IERS tables without any download: the bundled ones, and UT1 - UTC = 0 past their
    end (astropy warns)."""
    from astropy.utils import iers  # astropy: heavy, loaded when geometry is computed

    with (iers.conf.set_temp("auto_download", False), iers.conf.set_temp("iers_degraded_accuracy", "warn"),
          iers.conf.set_temp("auto_max_age", None)):
        yield


@quiet_future_utc
def utc_times(times_utc: Sequence[str], name: str = "time_utc") -> Any:
    """astropy ``Time`` (UTC) of ISO 8601 texts (``2020-03-01T04:00:00``, a space for the ``T`` and a
    trailing ``Z`` allowed).

    Raises:
        InputError: a text that is not such a time, quoted.
    """
    from astropy.time import Time  # astropy: heavy, loaded when times are read

    iso = [iso_text(t) for t in times_utc]
    try:
        return Time(iso, format="isot", scale="utc")
    except ValueError:
        bad = next(t for t, text in zip(times_utc, iso) if not is_time(text))
        raise InputError(f"`{name}` must be ISO 8601 times (UTC, 2020-03-01T04:00:00), got {quote(str(bad))}.") from None


def iso_text(text: str) -> str:
    """``text`` with a space for the ``T`` and a trailing ``Z`` read as ISO 8601's (UTC)."""
    text = str(text).strip().replace(" ", "T", 1)
    return text[:-1] if text.endswith(("Z", "z")) else text


@quiet_future_utc
def is_time(text: str) -> bool:
    """Whether astropy reads ``text`` (after :func:`iso_text`) as an ISO 8601 UTC time."""
    from astropy.time import Time  # astropy: heavy, loaded when times are read

    try:
        Time([iso_text(text)], format="isot", scale="utc")
    except ValueError:
        return False
    return True


@quiet_future_utc
def sun_directions_enu(times_utc: Sequence[str], site: Site) -> np.ndarray:
    """(n, 3) unit vectors towards the sun in the site's east-north-up frame, by astropy, offline."""
    from astropy import units as u  # astropy: heavy, loaded when geometry is computed
    from astropy.coordinates import AltAz, EarthLocation, get_sun

    times = utc_times(times_utc)
    location = EarthLocation(lat=site.latitude_deg * u.deg, lon=site.longitude_deg * u.deg, height=site.height_m * u.m)
    with offline_iers():
        altaz = get_sun(times).transform_to(AltAz(obstime=times, location=location))
    return altaz_to_enu(np.asarray(altaz.alt.deg), np.asarray(altaz.az.deg))


def altaz_to_enu(altitude_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """(n, 3) unit vectors (east, north, up) of altitudes and azimuths (deg, from north through east)."""
    alt, az = np.radians(altitude_deg), np.radians(azimuth_deg)
    return np.stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)], axis=-1)


def enu_to_altaz(enu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Altitudes and azimuths (deg, azimuth from north through east in [0, 360)) of (n, 3) east-north-up vectors."""
    e, n, up = enu[:, 0], enu[:, 1], enu[:, 2]
    return np.degrees(np.arctan2(up, np.hypot(e, n))), np.degrees(np.arctan2(e, n)) % 360.0


def in_earth_shadow(position_m: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Whether targets at ``position_m`` (n, 3, from the Earth's centre) are in the cylindrical shadow
    of a sun in directions ``sun`` (n, 3, unit)."""
    along = np.sum(position_m * sun, axis=-1)
    across = np.linalg.norm(position_m - along[:, None] * sun, axis=-1)
    return (along < 0) & (across < EARTH_RADIUS_M)


@dataclass(frozen=True)
class Orbit:
    """A satellite's mean elements for SGP4, from a TLE (:meth:`from_tle`) or an OMM (:meth:`from_omm`).

    Example:
        >>> with open("iss.tle", "w") as f:  # illustrative elements
        ...     print("ISS (ZARYA)", file=f)
        ...     print("1 25544U 98067A   24001.50000000  .00016717  00000-0  10270-3 0  9993", file=f)
        ...     print("2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.49815308432561", file=f)
        >>> import spacefit as sf
        >>> tle = "iss.tle"
        >>> sf.Orbit.from_tle(tle).name
        'ISS (ZARYA)'
    """

    satrec: Any
    name: str = ""

    @classmethod
    def from_tle(cls, text: str | Path) -> "Orbit":
        """The orbit of a two-line element set (two lines, or three with the name first; or a file of them).

        Raises:
            InputError: not two TLE lines, or elements SGP4 refuses.
        """
        from sgp4.api import Satrec  # sgp4: loaded with the orbit

        if isinstance(text, Path) or (isinstance(text, str) and "\n" not in text.strip() and Path(text).is_file()):
            text = Path(text).read_text(encoding="utf-8")
        check_type("tle", text, str, "the TLE's text or a file of it")
        lines = [line.rstrip() for line in text.splitlines() if line.strip()]
        if len(lines) not in (2, 3) or not (lines[-2].startswith("1 ") and lines[-1].startswith("2 ")):
            raise InputError(f"`tle` must be two element lines starting '1 ' and '2 ' (a name line before them allowed), got {quote(text)}.")
        name = lines[0].strip().removeprefix("0 ") if len(lines) == 3 else ""
        try:
            satrec = Satrec.twoline2rv(lines[-2], lines[-1])
        except ValueError as err:
            raise InputError(f"`tle` {quote(text)} cannot be read: {err}") from None
        return cls(satrec, name)

    @classmethod
    def from_omm(cls, fields: Mapping[str, Any] | str | Path) -> "Orbit":
        """The orbit of an OMM (CCSDS Orbit Mean-Elements Message): its fields (``EPOCH``,
        ``MEAN_MOTION``, ``ECCENTRICITY``, ...), or a file of them (JSON as CelesTrak gives it, one
        object or a list of one; XML; CSV).

        Raises:
            InputError: not one OMM, or a field missing or unreadable.
        """
        from sgp4 import omm  # sgp4: loaded with the orbit
        from sgp4.api import Satrec

        if not isinstance(fields, Mapping):
            path = Path(fields)
            text = path.read_text(encoding="utf-8")
            if path.suffix.lower() == ".json" or text.lstrip().startswith(("{", "[")):
                loaded = json.loads(text)
                records = loaded if isinstance(loaded, list) else [loaded]
            else:
                with path.open(encoding="utf-8") as f:
                    records = list(omm.parse_xml(f) if text.lstrip().startswith("<") else omm.parse_csv(f))
            if len(records) != 1:
                raise InputError(f"OMM file {str(path)!r} must hold one satellite's elements, got {len(records)}.")
            fields = records[0]
        satrec = Satrec()
        try:
            omm.initialize(satrec, dict(fields))
        except (KeyError, ValueError) as err:
            raise InputError(f"OMM {quote(dict(fields))} cannot be read: {type(err).__name__} {err}.") from None
        return cls(satrec, str(fields.get("OBJECT_NAME", "")))


@dataclass(frozen=True)
class PassGeometry:
    """A satellite seen from a site at given times (:func:`pass_geometry`); angles in deg, lengths in m.

    Attributes:
        altitude_deg, azimuth_deg: the satellite's, geometric (azimuth from north through east).
        range_m: the site's distance to it; height_m: its height above the WGS84 ellipsoid.
        phase_deg: the angle at the satellite between the sun and the observer.
        sun_altitude_deg, sun_azimuth_deg: the sun's, from the site.
        in_shadow: the satellite in the Earth's shadow (the guide "BRDF tables and light curves as observations").
        position_m, sun, towards_observer: (n, 3) in the Earth-fixed ITRS frame: the satellite from the
            Earth's centre, and unit vectors from it towards the sun and towards the observer.

    Example:
        >>> import spacefit as sf
        >>> with open("iss.tle", "w") as f:  # illustrative elements
        ...     print("ISS (ZARYA)", file=f)
        ...     print("1 25544U 98067A   24001.50000000  .00016717  00000-0  10270-3 0  9993", file=f)
        ...     print("2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.49815308432561", file=f)
        >>> tle = "iss.tle"
        >>> geometry = sf.pass_geometry(sf.Orbit.from_tle(tle), sf.Site(52.0, 4.4), ["2024-01-01T18:00:00"])
        >>> geometry.phase_deg.shape
        (1,)
    """

    altitude_deg: np.ndarray
    azimuth_deg: np.ndarray
    range_m: np.ndarray
    height_m: np.ndarray
    phase_deg: np.ndarray
    sun_altitude_deg: np.ndarray
    sun_azimuth_deg: np.ndarray
    in_shadow: np.ndarray
    position_m: np.ndarray
    sun: np.ndarray
    towards_observer: np.ndarray


def enu_rows(site: Site) -> np.ndarray:
    """(3, 3) rows east, north, up of the site (geodetic latitude and longitude) in the Earth-fixed frame."""
    lat, lon = np.radians(site.latitude_deg), np.radians(site.longitude_deg)
    return np.array([[-np.sin(lon), np.cos(lon), 0.0],
                     [-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)],
                     [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]])


def pass_geometry(orbit: Orbit, site: Site, times_utc: Sequence[str]) -> PassGeometry:
    """``orbit``'s satellite seen from ``site`` at ``times_utc`` (ISO 8601), offline (the guide "BRDF tables and light curves as observations").

    Raises:
        InputError: a time that is not ISO 8601, or one SGP4 cannot propagate to (the orbit decayed, ...).

    Args:
        orbit: the satellite's :class:`Orbit`.
        site: the observer's :class:`Site`.
        times_utc: ISO 8601 UTC times.

    Returns:
        A :class:`PassGeometry`, one value per time.

    Example:
        >>> import spacefit as sf
        >>> with open("iss.tle", "w") as f:  # illustrative elements
        ...     print("ISS (ZARYA)", file=f)
        ...     print("1 25544U 98067A   24001.50000000  .00016717  00000-0  10270-3 0  9993", file=f)
        ...     print("2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.49815308432561", file=f)
        >>> tle = "iss.tle"
        >>> geometry = sf.pass_geometry(sf.Orbit.from_tle(tle), sf.Site(52.0, 4.4), ["2024-01-01T18:00:00", "2024-01-01T18:01:00"])
        >>> geometry.altitude_deg.shape, bool(geometry.range_m.min() > 4e5)
        ((2,), True)
    """
    from astropy import units as u  # astropy: heavy, loaded when geometry is computed
    from astropy.coordinates import ITRS, TEME, CartesianRepresentation, EarthLocation, get_sun
    from sgp4.api import SGP4_ERRORS

    check_type("orbit", orbit, Orbit, "an sf.Orbit (Orbit.from_tle or Orbit.from_omm)")
    check_type("site", site, Site, "an sf.Site")
    times = utc_times(times_utc)
    error, teme_km, _ = orbit.satrec.sgp4_array(np.atleast_1d(times.jd1), np.atleast_1d(times.jd2))
    if np.any(error):
        k = int(np.flatnonzero(error)[0])
        raise InputError(f"SGP4 cannot propagate {orbit.name or 'the orbit'} to {times_utc[k]!r}: {SGP4_ERRORS[int(error[k])]}.")
    location = EarthLocation.from_geodetic(site.longitude_deg * u.deg, site.latitude_deg * u.deg, site.height_m * u.m)
    with offline_iers():
        teme = TEME(CartesianRepresentation(teme_km.T * u.km), obstime=times)
        satellite = teme.transform_to(ITRS(obstime=times))
        position = satellite.cartesian.xyz.to_value(u.m).T
        sun_position = get_sun(times).transform_to(ITRS(obstime=times)).cartesian.xyz.to_value(u.m).T
        site_position = np.asarray(location.get_itrs(times).cartesian.xyz.to_value(u.m)).T
    site_position = np.broadcast_to(site_position, position.shape)
    rows = enu_rows(site)
    seen = position - site_position
    range_m = np.linalg.norm(seen, axis=1)
    altitude, azimuth = enu_to_altaz(seen @ rows.T)
    sun_altitude, sun_azimuth = enu_to_altaz((sun_position - site_position) @ rows.T)
    to_sun = (sun_position - position) / np.linalg.norm(sun_position - position, axis=1, keepdims=True)
    towards = -seen / range_m[:, None]
    phase = np.degrees(np.arccos(np.clip(np.sum(to_sun * towards, axis=1), -1.0, 1.0)))
    height = np.asarray(EarthLocation.from_geocentric(*position.T, unit=u.m).height.to_value(u.m))
    shadow = in_earth_shadow(position, sun_position / np.linalg.norm(sun_position, axis=1, keepdims=True))
    return PassGeometry(altitude, azimuth, range_m, height, phase, sun_altitude, sun_azimuth, shadow, position, to_sun, towards)
