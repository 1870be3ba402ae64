"""Light curves as observations: reading measured magnitudes with their times and geometry, the sun
from astropy offline, the target's frame, and the Earth's shadow.

Two file formats, CSV with ``#`` comment lines and a header naming the columns:

* the general format: ``time_utc`` (ISO 8601), ``magnitude``, optionally ``magnitude_sigma`` (mag),
  and the geometry, either in the target's frame, ``sun_x, sun_y, sun_z`` and ``observer_x,
  observer_y, observer_z`` (directions from the target, normalised on reading) and ``range_m``, or
  seen from a site (the ``site`` argument), ``altitude_deg``, ``azimuth_deg`` (of the target,
  azimuth from north through east) and ``height_m`` (the target's height above the Earth's surface).
* the Pomenis format of the Starlink v1.5 observations (Fankhauser, Askari & Tyson 2023):
  ``observation_time, satellite_height`` (km), ``satellite_altitude, satellite_azimuth`` (deg),
  ``ab_magnitude`` (band ``AB532``, no stated errors).

From a site, the sun's direction comes from astropy (``get_sun`` in the site's AltAz frame) with
no attempt to download IERS tables (``astropy.utils.iers.conf.auto_download = False``; astropy's
bundled tables, or none past their end: the sun is then placed within 0.01 deg, the Earth turning
0.004 deg in UT1 - UTC's 0.9 s). The Earth is a sphere of radius :data:`EARTH_RADIUS_M` (as
lumos-sat takes it), the site on it; the sun's parallax over the target's distance (5e-5 rad) is
neglected. The target's frame (:func:`nadir_sun_frame`): z away from the Earth's centre, y towards
the sun's direction projected onto the plane normal to z, x = y cross z: the frame of a satellite
whose base faces nadir and whose solar array, turned about z, faces the sun (lumos-sat's
"brightness frame").

The Earth's shadow is a cylinder (the sun's rays parallel, no penumbra; the penumbra's width at
550 km is about 60 km, 0.5 deg of the terminator): the target is in shadow where its position r
from the Earth's centre has r . s < 0 and |r - (r . s) s| < R. Such a target is predicted dark, and
an observation of it is flagged (``in_shadow``) and left out of fits.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacefit.errors import InputError, check_array, check_choice, check_range, check_type, quote, read_text_rows, unit_rows
from spacefit.studies.lightcurve import SUN_MAGNITUDES

# The Earth's (equatorial) radius, m, as lumos-sat takes it (a sphere).
EARTH_RADIUS_M = 6378.0e3
POMENIS_COLUMNS = ("observation_time", "satellite_height", "satellite_altitude", "satellite_azimuth", "ab_magnitude")
TARGET_FRAME_COLUMNS = ("sun_x", "sun_y", "sun_z", "observer_x", "observer_y", "observer_z", "range_m")
SITE_COLUMNS = ("altitude_deg", "azimuth_deg", "height_m")
# The greatest height above the Earth a light curve may give (m): the Moon's distance, twice.
MAX_HEIGHT_M = 8e8


@dataclass(frozen=True)
class Site:
    """An observer on the Earth: geodetic latitude and longitude (deg, east positive), height (m)."""

    latitude_deg: float
    longitude_deg: float
    height_m: float = 0.0

    def __post_init__(self) -> None:
        check_range("site.latitude_deg", self.latitude_deg, -90.0, 90.0, unit="deg")
        check_range("site.longitude_deg", self.longitude_deg, -360.0, 360.0, unit="deg")
        check_range("site.height_m", self.height_m, -500.0, 1e4, unit="m")


@dataclass(frozen=True)
class LightCurveObservations:
    """Measured brightness at known geometry.

    Attributes:
        magnitude, magnitude_sigma: apparent magnitudes in ``band`` and their errors (None: not stated).
        sun, observer: (n, 3) unit directions from the target towards the sun and the observer, in
            the target's frame.
        range_m: the observer's distance (m).
        in_shadow: (n,) the target in the Earth's shadow (predicted dark; left out of fits).
        time_utc: ISO times, or None.
        source: where they came from.
    """

    magnitude: np.ndarray
    magnitude_sigma: np.ndarray | None
    band: str
    sun: np.ndarray
    observer: np.ndarray
    range_m: np.ndarray
    in_shadow: np.ndarray
    time_utc: np.ndarray | None
    source: str

    def __post_init__(self) -> None:
        check_type("source", self.source, str, "a string")
        check_choice("band", self.band, SUN_MAGNITUDES)
        magnitude = _finite("magnitude", self.magnitude, 1)
        n = len(magnitude)
        fields = {"magnitude": magnitude, "range_m": _finite("range_m", self.range_m, 1, n)}
        if np.any(fields["range_m"] <= 0):
            raise InputError(f"`range_m` must be positive, got {quote(self.range_m)}.")
        if self.magnitude_sigma is not None:
            fields["magnitude_sigma"] = _finite("magnitude_sigma", self.magnitude_sigma, 1, n)
            if np.any(fields["magnitude_sigma"] <= 0):
                raise InputError(f"`magnitude_sigma` must be None or positive, got {quote(self.magnitude_sigma)}.")
        for name in ("sun", "observer"):
            v = _finite(name, getattr(self, name), 2, n)
            unit = unit_rows(v)
            if v.shape[1:] != (3,) or not np.all(np.isfinite(unit)):
                raise InputError(f"`{name}` must be ({n}, 3) directions, none (0, 0, 0), got {quote(getattr(self, name))}.")
            fields[name] = unit
        shadow = check_array("in_shadow", self.in_shadow, "a bool array")
        if shadow.shape != (n,):
            raise InputError(f"`in_shadow` must be {n} booleans, got shape {shadow.shape}.")
        if self.time_utc is not None and np.shape(self.time_utc) != (n,):
            raise InputError(f"`time_utc` must be None or {n} times, got {quote(self.time_utc)}.")
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.magnitude)

    def subset(self, rows: np.ndarray) -> "LightCurveObservations":
        """These observations at ``rows`` (indices or a boolean mask)."""
        pick = (lambda a: None if a is None else a[rows])
        return LightCurveObservations(self.magnitude[rows], pick(self.magnitude_sigma), self.band, self.sun[rows], self.observer[rows],
                                      self.range_m[rows], self.in_shadow[rows], pick(self.time_utc), self.source)


def _finite(name: str, value: object, ndim: int, n: int | None = None) -> np.ndarray:
    """``value`` as a finite float array of ``ndim`` dimensions (the first of length ``n`` if given, else at least 1)."""
    arr = check_array(name, value).astype(float)
    if arr.ndim != ndim or len(arr) != (n if n is not None else max(len(arr), 1)) or not np.all(np.isfinite(arr)):
        count = f"{n}" if n is not None else "one or more"
        raise InputError(f"`{name}` must be {count} finite values{' (rows)' if ndim > 1 else ''}, got {quote(value)}.")
    return arr


def sun_directions_enu(times_utc: Sequence[str], site: Site) -> np.ndarray:
    """(n, 3) unit vectors towards the sun in the site's east-north-up frame, by astropy, offline."""
    from astropy import units as u
    from astropy.coordinates import AltAz, EarthLocation, get_sun
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    iso = [str(t).strip().replace(" ", "T", 1) for t in times_utc]  # 2020-03-01T04:00:00 or 2020-03-01 04:00:00
    try:
        times = Time(iso, format="isot", scale="utc")
    except ValueError:
        bad = next(t for t, text in zip(times_utc, iso) if not _is_time(text, Time))
        raise InputError(f"`time_utc` must be ISO 8601 times (UTC, 2020-03-01T04:00:00), got {quote(str(bad))}.") from None
    location = EarthLocation(lat=site.latitude_deg * u.deg, lon=site.longitude_deg * u.deg, height=site.height_m * u.m)
    # past the bundled tables, or with their predictions old: the module docstring's 0.01 deg, with astropy's warning
    with iers.conf.set_temp("iers_degraded_accuracy", "warn"), iers.conf.set_temp("auto_max_age", None):
        altaz = get_sun(times).transform_to(AltAz(obstime=times, location=location))
    return altaz_to_enu(np.asarray(altaz.alt.deg), np.asarray(altaz.az.deg))


def _is_time(text: str, time_class: type) -> bool:
    """Whether astropy's ``time_class`` reads ``text`` as an ISO 8601 time."""
    try:
        time_class([text], format="isot", scale="utc")
    except ValueError:
        return False
    return True


def altaz_to_enu(altitude_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """(n, 3) unit vectors (east, north, up) of altitudes and azimuths (deg, from north through east)."""
    alt, az = np.radians(altitude_deg), np.radians(azimuth_deg)
    return np.stack([np.cos(alt) * np.sin(az), np.cos(alt) * np.cos(az), np.sin(alt)], axis=-1)


def target_positions(altitude_deg: np.ndarray, azimuth_deg: np.ndarray, height_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The target's position from the Earth's centre (n, 3; the site's east-north-up axes, the site at
    (0, 0, R)) and its distance from the site (m), seen at altitude / azimuth at ``height_m``."""
    u = altaz_to_enu(altitude_deg, azimuth_deg)
    R, r = EARTH_RADIUS_M, EARTH_RADIUS_M + np.asarray(height_m, dtype=float)
    distance = -R * u[:, 2] + np.sqrt((R * u[:, 2]) ** 2 + r**2 - R**2)
    return np.array([0.0, 0.0, R]) + distance[:, None] * u, distance


def in_earth_shadow(position_m: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Whether targets at ``position_m`` (n, 3, from the Earth's centre) are in the cylindrical shadow
    of a sun in directions ``sun`` (n, 3, unit)."""
    along = np.sum(position_m * sun, axis=-1)
    across = np.linalg.norm(position_m - along[:, None] * sun, axis=-1)
    return (along < 0) & (across < EARTH_RADIUS_M)


def nadir_sun_frame(position_m: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rows x, y, z of the target's frame (module docstring) in the site's frame."""
    z = position_m / np.linalg.norm(position_m, axis=-1, keepdims=True)
    y = sun - np.sum(sun * z, axis=-1, keepdims=True) * z
    norm = np.linalg.norm(y, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        raise InputError("the sun is at the target's zenith or nadir: the nadir-sun frame's y axis is undefined there.")
    y = y / norm
    return np.stack([np.cross(y, z), y, z], axis=1)


def read_light_curve(path: str | Path, *, site: Site | None = None, band: str | None = None) -> LightCurveObservations:
    """Read measured magnitudes in the general or the Pomenis format (module docstring); ``site`` is
    needed where the geometry is an altitude, azimuth and height; ``band`` names the general
    format's band (one of :data:`~spacefit.studies.lightcurve.SUN_MAGNITUDES`).

    Raises:
        InputError: missing columns, unreadable values, a missing site or band.
        OSError: the file cannot be read.
    """
    lines = read_text_rows("path", path, "light curve")
    path = Path(path)
    check_type("site", site, (Site, type(None)), "an sf.Site or None")
    if band is not None:
        check_choice("band", band, SUN_MAGNITUDES)
    rows = list(csv.DictReader(lines))
    if not rows:
        raise InputError(f"light curve {path}: no data rows.")
    header = list(rows[0])
    if all(c in header for c in POMENIS_COLUMNS):
        band = "AB532"
        times = np.array([r["observation_time"] for r in rows])
        numbers = _columns(path, rows, POMENIS_COLUMNS[1:])
        magnitude, sigma = numbers[:, 3], None
        geometry = ("site", numbers[:, 1], numbers[:, 2], numbers[:, 0] * 1e3)
    else:
        if band is None:
            raise InputError(f"light curve {path}: give `band` (one of {', '.join(SUN_MAGNITUDES)}) for the general format.")
        check_choice("band", band, SUN_MAGNITUDES)
        for needed in (("time_utc", "magnitude"),):
            missing = [c for c in needed if c not in header]
            if missing:
                raise InputError(f"light curve {path}: the header {header} lacks {missing}.")
        times = np.array([r["time_utc"] for r in rows])
        magnitude = _columns(path, rows, ("magnitude",))[:, 0]
        sigma = _columns(path, rows, ("magnitude_sigma",))[:, 0] if "magnitude_sigma" in header else None
        if all(c in header for c in TARGET_FRAME_COLUMNS):
            numbers = _columns(path, rows, TARGET_FRAME_COLUMNS)
            geometry = ("frame", numbers[:, 0:3], numbers[:, 3:6], numbers[:, 6])
        elif all(c in header for c in SITE_COLUMNS):
            numbers = _columns(path, rows, SITE_COLUMNS)
            geometry = ("site", numbers[:, 0], numbers[:, 1], numbers[:, 2])
        else:
            raise InputError(f"light curve {path}: the header {header} has no geometry: give {', '.join(TARGET_FRAME_COLUMNS)} "
                             f"(the target's frame) or {', '.join(SITE_COLUMNS)} (seen from a `site`).")
    if geometry[0] == "frame":
        sun, observer, range_m = geometry[1:]
        in_shadow = np.zeros(len(rows), dtype=bool)
    else:
        if site is None:
            raise InputError(f"light curve {path} gives the target's altitude and azimuth: give the observer's `site` "
                             f"(sf.Site(latitude_deg, longitude_deg, height_m)).")
        altitude, azimuth, height = geometry[1], geometry[2], geometry[3]
        if np.any((altitude < -90) | (altitude > 90)) or np.any((height <= 0) | (height > MAX_HEIGHT_M)):
            raise InputError(f"light curve {path}: altitudes must lie in [-90, 90] deg and heights in (0, {MAX_HEIGHT_M:g}] m.")
        sun_enu = sun_directions_enu(times, site)
        position, range_m = target_positions(altitude, azimuth, height)
        frame = nadir_sun_frame(position, sun_enu)
        towards_observer = -(position - np.array([0.0, 0.0, EARTH_RADIUS_M])) / range_m[:, None]
        sun = np.einsum("nij,nj->ni", frame, sun_enu)
        observer = np.einsum("nij,nj->ni", frame, towards_observer)
        in_shadow = in_earth_shadow(position, sun_enu)
    try:
        return LightCurveObservations(magnitude, sigma, band, sun, observer, range_m, in_shadow, times, str(path))
    except InputError as err:
        raise type(err)(f"light curve {path}: {err}") from None


def _columns(path: Path, rows: list[dict[str, str]], names: Sequence[str]) -> np.ndarray:
    out = np.empty((len(rows), len(names)))
    for i, row in enumerate(rows):
        for j, name in enumerate(names):
            try:
                out[i, j] = float(row[name])
            except (TypeError, ValueError):
                raise InputError(f"light curve {path}: row {i + 1}'s {name} must be a number, got {row[name]!r}.") from None
    if not np.all(np.isfinite(out)):
        raise InputError(f"light curve {path}: every value of {', '.join(names)} must be finite.")
    return out


def magnitude_of(irradiance_w_m2: np.ndarray, band: str, sun_irradiance_w_m2: float) -> np.ndarray:
    """Apparent magnitudes in ``band`` of irradiances at the observer (inf where dark)."""
    with np.errstate(divide="ignore"):
        return SUN_MAGNITUDES[check_choice("band", band, SUN_MAGNITUDES)] - 2.5 * np.log10(np.asarray(irradiance_w_m2) / sun_irradiance_w_m2)


def irradiance_of(magnitude: np.ndarray, band: str, sun_irradiance_w_m2: float) -> np.ndarray:
    """Irradiances at the observer (W m^-2) of apparent magnitudes in ``band``."""
    return sun_irradiance_w_m2 * 10.0 ** (-0.4 * (np.asarray(magnitude) - SUN_MAGNITUDES[check_choice("band", band, SUN_MAGNITUDES)]))


# d ln E / d m: a magnitude error's relative irradiance error.
LN_PER_MAGNITUDE = 0.4 * math.log(10.0)
