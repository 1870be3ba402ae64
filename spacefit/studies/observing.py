"""Light curves as observers publish them: reading and writing measured magnitudes with their times and
geometry, and the target's frame (the observations themselves, checked:
:mod:`spacefit.studies.lightcurve_observations`).

:func:`read_light_curve` reads six formats, found from the file (or named by ``format``):

* ``general``: CSV with ``#`` comment lines and a header naming the columns ``time_utc`` (ISO 8601),
  ``magnitude``, optionally ``magnitude_sigma`` (mag), and the geometry, either in the target's frame,
  ``sun_x, sun_y, sun_z`` and ``observer_x, observer_y, observer_z`` (directions from the target,
  normalised on reading) and ``range_m`` (optionally ``earth_x, earth_y, earth_z``, the Earth's
  centre from the target, m, for Earthshine, and ``in_shadow``), or seen from a site (the ``site``
  argument), ``altitude_deg``, ``azimuth_deg`` (of the target, azimuth from north through east) and
  ``height_m`` (the target's height above the Earth's surface).
* ``pomenis``: the Starlink v1.5 observations (Fankhauser, Askari & Tyson 2023):
  ``observation_time, satellite_height`` (km), ``satellite_altitude, satellite_azimuth`` (deg),
  ``ab_magnitude`` (band ``AB532``, no stated errors).
* ``score``: the IAU CPS SatHub SCORE CSV (:mod:`spacefit.studies.observation_files`), each row with
  its own observer; the geometry from SatChecker's columns.
* ``ecsv``: an astropy ECSV table of the general format's columns (:func:`write_light_curve` writes one).
* ``mmt9``: a track download of the Mini-MegaTORTORA satellite database (:mod:`spacefit.studies.mmt9`),
  found by its header line ``# Date Time StdMag Mag Filter ...``; the geometry from an ``orbit``.
* ``tdm``: a CCSDS Tracking Data Message with ``MAG`` data (:mod:`spacefit.studies.tdm`), found by its
  first keyword ``CCSDS_TDM_VERS``; the geometry from its AZEL angles and range seen from ``site``, or
  from an ``orbit``.

Given an ``orbit`` (:class:`Orbit`, a TLE or OMM), the geometry is computed
from it, the site and the time instead, offline (:func:`pass_geometry`),
and checked against the file's where it gives any (SatChecker's columns, an MMT-9 track's distance
and phase angle, a TDM's angles and range: :data:`ORBIT_TOLERANCE`). Rows whose time cannot be right
(not ISO 8601, before ``launch_utc``, in the future), and SCORE rows, MMT-9 points and TDM ``MAG``
lines without a magnitude or geometry, are refused: listed in ``refused`` with their row, column,
value and reason, and warned of. A missing value in the general or Pomenis format is an error
naming its row and column.

From a site, the sun's direction comes from astropy offline (:mod:`spacefit.studies.orbit`). The
Earth is a sphere of radius :data:`EARTH_RADIUS_M` (as lumos-sat takes it), the site on it; the
sun's parallax over the target's distance (5e-5 rad) is neglected. The target's frame
(:func:`nadir_sun_frame`): z away from the Earth's centre, y towards the sun's direction projected
onto the plane normal to z, x = y cross z: the frame of a satellite whose base faces nadir and whose
solar array, turned about z, faces the sun (lumos-sat's "brightness frame"). A target in the Earth's
shadow (:func:`~spacefit.studies.orbit.in_earth_shadow`, a SCORE row not ``illuminated``, an MMT-9
point in the penumbra, a general row ``in_shadow``) is predicted dark, and its observation flagged
(``in_shadow``) and left out of fits.
"""

from __future__ import annotations

import csv
import warnings
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from spacefit.errors import InputError, check_choice, check_type, read_text_rows
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.lightcurve_observations import LightCurveObservations
from spacefit.studies.mmt9 import is_mmt9, read_mmt9
from spacefit.studies.observation_files import SiteRows, check_format, file_format, read_ecsv, read_score, time_refusals, write_ecsv
from spacefit.studies.tdm import is_tdm, read_tdm
from spacefit.studies.orbit import EARTH_RADIUS_M, Orbit, Site, altaz_to_enu, in_earth_shadow, pass_geometry, sun_directions_enu

POMENIS_COLUMNS = ("observation_time", "satellite_height", "satellite_altitude", "satellite_azimuth", "ab_magnitude")
TARGET_FRAME_COLUMNS = ("sun_x", "sun_y", "sun_z", "observer_x", "observer_y", "observer_z", "range_m")
SITE_COLUMNS = ("altitude_deg", "azimuth_deg", "height_m")
# The Earth's centre from the target in its frame (m), optional beside TARGET_FRAME_COLUMNS.
EARTH_COLUMNS = ("earth_x", "earth_y", "earth_z")
# The greatest height above the Earth a light curve may give (m): the Moon's distance, twice.
MAX_HEIGHT_M = 8e8


def target_positions(altitude_deg: np.ndarray, azimuth_deg: np.ndarray, height_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The target's position from the Earth's centre (n, 3; the site's east-north-up axes, the site at
    (0, 0, R)) and its distance from the site (m), seen at altitude / azimuth at ``height_m``."""
    u = altaz_to_enu(altitude_deg, azimuth_deg)
    R, r = EARTH_RADIUS_M, EARTH_RADIUS_M + np.asarray(height_m, dtype=float)
    distance = -R * u[:, 2] + np.sqrt((R * u[:, 2]) ** 2 + r**2 - R**2)
    return np.array([0.0, 0.0, R]) + distance[:, None] * u, distance


def nadir_sun_frame(position_m: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rows x, y, z of the target's frame (module docstring) in the site's frame."""
    z = position_m / np.linalg.norm(position_m, axis=-1, keepdims=True)
    y = sun - np.sum(sun * z, axis=-1, keepdims=True) * z
    norm = np.linalg.norm(y, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        raise InputError("the sun is at the target's zenith or nadir: the nadir-sun frame's y axis is undefined there.")
    y = y / norm
    return np.stack([np.cross(y, z), y, z], axis=1)


def read_light_curve(path: str | Path, *, site: Site | None = None, band: str | None = None, format: str | None = None,
                     orbit: Orbit | None = None, launch_utc: str | None = None, now_utc: str | None = None) -> LightCurveObservations:
    """Read measured magnitudes from a file in one of the formats the guide "BRDF tables and light curves as observations" describes (found from
    the file, or ``format``: ``general``, ``pomenis``, ``score``, ``ecsv``, ``mmt9``, ``tdm``). ``site``
    is the observer where the geometry is seen from one (a SCORE file gives each row's; an MMT-9
    track's default is MMT-9's); ``band`` names the magnitudes' band (``V`` or ``AB532``; a SCORE file's or MMT-9 track's from its
    filters, a TDM's ``V``). ``orbit`` computes the geometry from a TLE or OMM instead (an MMT-9
    track needs one); rows before ``launch_utc`` or after ``now_utc`` (default: now) are refused,
    with a warning.

    Raises:
        InputError: one line naming the file and, where one is to blame, the row (a TDM's line), the
            column (keyword) and the value: missing columns or metadata, unreadable values, an unknown
            filter or time system, a missing site, band or orbit.
        OSError: the file cannot be read.

    Args:
        path: the file.
        site: the observer (:class:`Site`), where the geometry is computed.
        band: the magnitudes' band where the file does not say.
        format: the file's format; None: found from the file.
        orbit: the satellite's :class:`Orbit`, for geometry from its elements.
        launch_utc, now_utc: rows outside these times are refused.

    Returns:
        The :class:`LightCurveObservations`; rows refused are in its ``refused``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=np.array(['2024-01-01T00:00:00', '2024-01-01T00:00:10', '2024-01-01T00:00:20']), source="example")
        >>> back = sf.read_light_curve(sf.write_light_curve(curve, "curve.ecsv"))
        >>> back.band, back.refused
        ('V', ())
    """
    read_text_rows("path", path, "light curve")  # a text file, else a one-line error
    path = Path(path)
    text = path.read_text(encoding="utf-8").splitlines()
    check_type("site", site, (Site, type(None)), "an sf.Site or None")
    check_type("orbit", orbit, (Orbit, type(None)), "an sf.Orbit (Orbit.from_tle or Orbit.from_omm) or None")
    if band is not None:
        check_choice("band", band, SUN_MAGNITUDES)
    rows = list(csv.DictReader(line for line in text if line.strip() and not line.lstrip().startswith("#")))
    kind = check_format(format) or ("tdm" if is_tdm(text) else "mmt9" if is_mmt9(text) else file_format(path, list(rows[0]) if rows else None))
    if kind == "ecsv":
        rows, table_band, table_site = read_ecsv(path)
        band, site, kind = band or table_band, site or table_site, "general"
    if not rows and kind not in ("tdm", "mmt9"):
        raise InputError(f"light curve {path}: no data rows.")
    with_orbit = orbit is not None
    try:
        if kind in ("score", "mmt9", "tdm"):
            given = (read_score(rows, band=band, with_orbit=with_orbit, launch_utc=launch_utc, now_utc=now_utc) if kind == "score" else
                     (read_mmt9 if kind == "mmt9" else read_tdm)(text, band=band, site=site, with_orbit=with_orbit,
                                                                 launch_utc=launch_utc, now_utc=now_utc))
            observations = _from_site_rows(given, orbit, str(path))
        else:
            observations = _from_table(rows, kind, band, site, orbit, (launch_utc, now_utc), str(path))
    except InputError as err:
        raise type(err)(f"light curve {path}: {err}") from None
    if observations.refused:
        reasons = Counter(r.reason.split(" (")[0] for r in observations.refused)
        warnings.warn(f"light curve {path}: {len(observations.refused)} rows refused ({', '.join(f'{n} {why}' for why, n in reasons.items())}): "
                      f"{'; '.join(str(r) for r in observations.refused[:5])}{' ...' if len(observations.refused) > 5 else ''}",
                      stacklevel=2)
    return observations


def _from_table(rows: list[dict[str, str]], kind: str, band: str | None, site: Site | None, orbit: Orbit | None,
                bounds: tuple[str | None, str | None], source: str) -> LightCurveObservations:
    """The general or Pomenis format's observations (:func:`read_light_curve`)."""
    header = list(rows[0])
    if kind == "pomenis":
        missing = [c for c in POMENIS_COLUMNS if c not in header]
        if missing:
            raise InputError(f"the header {header} lacks {missing}.")
        band, time_column = "AB532", "observation_time"
        numbers = _columns(rows, POMENIS_COLUMNS[1:])
        magnitude, sigma = numbers[:, 3], None
        geometry = ("site", numbers[:, 1], numbers[:, 2], numbers[:, 0] * 1e3)
    else:
        if band is None:
            raise InputError(f"give `band` (one of {', '.join(SUN_MAGNITUDES)}) for the general format.")
        missing = [c for c in ("time_utc", "magnitude") if c not in header]
        if missing:
            raise InputError(f"the header {header} lacks {missing}.")
        time_column = "time_utc"
        magnitude = _columns(rows, ("magnitude",))[:, 0]
        sigma = _columns(rows, ("magnitude_sigma",))[:, 0] if "magnitude_sigma" in header else None
        if all(c in header for c in TARGET_FRAME_COLUMNS):
            numbers = _columns(rows, TARGET_FRAME_COLUMNS)
            shadow = np.array([r.get("in_shadow", "False").strip().lower() == "true" for r in rows])
            earth = _columns(rows, EARTH_COLUMNS) if all(c in header for c in EARTH_COLUMNS) else np.full((len(rows), 3), np.nan)
            geometry = ("frame", numbers[:, 0:3], numbers[:, 3:6], numbers[:, 6], shadow, earth)
        elif all(c in header for c in SITE_COLUMNS):
            numbers = _columns(rows, SITE_COLUMNS)
            geometry = ("site", numbers[:, 0], numbers[:, 1], numbers[:, 2])
        elif orbit is not None:
            geometry = ("orbit",)
        else:
            raise InputError(f"the header {header} has no geometry: give {', '.join(TARGET_FRAME_COLUMNS)} "
                             f"(the target's frame) or {', '.join(SITE_COLUMNS)} (seen from a `site`), or an `orbit`.")
    times = np.array([r[time_column] for r in rows])
    refused = time_refusals(times, time_column, *bounds)
    keep = np.array([i not in refused for i in range(len(rows))])
    if not keep.any():
        raise InputError(f"no usable rows: {'; '.join(str(r) for r in refused.values())}.")
    times, magnitude = times[keep], magnitude[keep]
    sigma = None if sigma is None else sigma[keep]
    geometry = (geometry[0], *(g[keep] for g in geometry[1:]))
    if geometry[0] == "frame":
        sun, observer, range_m, in_shadow, earth_m = geometry[1:]
        earth_m = None if np.isnan(earth_m).any() else earth_m
    else:
        if site is None:
            raise InputError("the geometry is seen from a site: give the observer's `site` (sf.Site(latitude_deg, longitude_deg, height_m)).")
        if orbit is not None:
            sun, observer, range_m, in_shadow, earth_m = _in_target_frame(*_orbit_geometry(orbit, site, times)[:4])
        else:
            altitude, azimuth, height = geometry[1:]
            if np.any((altitude < -90) | (altitude > 90)) or np.any((height <= 0) | (height > MAX_HEIGHT_M)):
                raise InputError(f"altitudes must lie in [-90, 90] deg and heights in (0, {MAX_HEIGHT_M:g}] m.")
            position, range_m = target_positions(altitude, azimuth, height)
            sun, observer, range_m, in_shadow, earth_m = _in_target_frame(*_site_geometry(site, times, position, range_m))
    return LightCurveObservations(magnitude, sigma, band, sun, observer, range_m, in_shadow, times, source,
                                  tuple(refused[k] for k in sorted(refused)), earth_m)


def _site_geometry(site: Site, times: np.ndarray, position: np.ndarray,
                   range_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Targets at ``position`` (the site's east-north-up axes, the site at (0, 0, R)): their position,
    the sun's and the observer's directions from them, and the range."""
    sun = sun_directions_enu(times, site)
    towards_observer = -(position - np.array([0.0, 0.0, EARTH_RADIUS_M])) / range_m[:, None]
    return position, sun, towards_observer, range_m


def _orbit_geometry(orbit: Orbit, site: Site, times: np.ndarray) -> tuple[np.ndarray, ...]:
    """:func:`_site_geometry`'s values from ``orbit`` (the Earth-fixed frame), and the altitude,
    azimuth and phase angle (deg) for checking."""
    g = pass_geometry(orbit, site, list(times))
    return g.position_m, g.sun, g.towards_observer, g.range_m, g.altitude_deg, g.azimuth_deg, g.phase_deg


def _in_target_frame(position: np.ndarray, sun: np.ndarray, towards_observer: np.ndarray,
                     range_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The sun's and the observer's directions in the target's frame, the range, the Earth's shadow,
    and the Earth's centre from the target in its frame (``position`` is the target's from it)."""
    frame = nadir_sun_frame(position, sun)
    in_shadow = in_earth_shadow(position, sun)
    to_frame = (lambda v: np.einsum("nij,nj->ni", frame, v))
    return to_frame(sun), to_frame(towards_observer), range_m, in_shadow, to_frame(-position)


# How far an orbit's geometry may stray from a file's (SatChecker's columns, an MMT-9 track's, a TDM's
# angles and range) without a warning: deg, and m for the range.
ORBIT_TOLERANCE = {"altitude_deg": 0.01, "azimuth_deg": 0.01, "phase_deg": 0.05, "range_m": 1000.0}


def _from_site_rows(given: SiteRows, orbit: Orbit | None, source: str) -> LightCurveObservations:
    """The observations of a file whose rows are each seen from a site (:func:`read_light_curve`):
    the geometry the orbit's where one is given (checked against the file's), else the file's."""
    n = len(given.magnitude)
    values = [np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty(n)]
    computed = {name: np.full(n, np.nan) for name in ORBIT_TOLERANCE}
    for site in dict.fromkeys(given.sites):
        rows = np.array([s == site for s in given.sites])
        if orbit is not None:
            *parts, altitude, azimuth, phase = _orbit_geometry(orbit, site, given.times_utc[rows])
            for name, value in zip(ORBIT_TOLERANCE, (altitude, azimuth, phase, parts[3])):
                computed[name][rows] = value
        else:
            u = altaz_to_enu(given.altitude_deg[rows], given.azimuth_deg[rows])
            position = np.array([0.0, 0.0, EARTH_RADIUS_M]) + given.range_m[rows, None] * u
            parts = _site_geometry(site, given.times_utc[rows], position, given.range_m[rows])
        for whole, part in zip(values, parts):
            whole[rows] = part
    for name, column in given.columns.items() if orbit is not None else ():
        off = computed[name] - getattr(given, name)
        off = np.abs((off + 180.0) % 360.0 - 180.0 if name.endswith("_deg") else off)
        if np.nanmax(off, initial=0.0) > ORBIT_TOLERANCE[name]:
            k, unit, scale = int(np.nanargmax(off)), *(("deg", 1.0) if name.endswith("_deg") else ("km", 1e-3))
            warnings.warn(f"{source}: the orbit's {name.rsplit('_', 1)[0]} differs from the file's {column} by up to {off[k] * scale:.3g} "
                          f"{unit} (row {given.rows[k]}: {computed[name][k] * scale:.4f} against {getattr(given, name)[k] * scale:.4f}); "
                          f"the geometry used is the orbit's.", stacklevel=3)
    sun, observer, range_m, in_shadow, earth_m = _in_target_frame(*values)
    return LightCurveObservations(given.magnitude, given.magnitude_sigma, given.band, sun, observer, range_m,
                                  in_shadow | given.dark, given.times_utc, source, given.refused, earth_m)


def write_light_curve(observations: LightCurveObservations, path: str | Path) -> Path:
    """Write ``observations`` as an ECSV table (the general format's columns in the target's frame,
    ``in_shadow``, ``earth_x, earth_y, earth_z`` where the Earth's position is known, the time as an
    astropy Time column ``time``; ``band`` and ``source`` in its
    metadata) that :func:`read_light_curve` reads back and astropy's ``TimeSeries.read`` reads.

    Raises:
        InputError: observations without times.

    Args:
        observations: the observations (with times).
        path: the ``.ecsv`` file to write.

    Returns:
        The file's path.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> phase = np.radians([20.0, 40.0, 60.0])  # the sun overhead, the observer tilted away
        >>> curve = sf.LightCurveObservations(
        ...     magnitude=np.array([5.0, 5.2, 5.5]), magnitude_sigma=np.full(3, 0.05), band="V",
        ...     sun=np.tile([0.0, 0.0, 1.0], (3, 1)), observer=np.stack([np.sin(phase), 0 * phase, np.cos(phase)], axis=1),
        ...     range_m=np.full(3, 1.0e6), in_shadow=np.zeros(3, bool), time_utc=np.array(['2024-01-01T00:00:00', '2024-01-01T00:00:10', '2024-01-01T00:00:20']), source="example")
        >>> path = sf.write_light_curve(curve, "curve.ecsv")
        >>> sf.read_light_curve(path).magnitude
        array([5. , 5.2, 5.5])
    """
    check_type("observations", observations, LightCurveObservations, "sf.LightCurveObservations")
    if observations.time_utc is None:
        raise InputError("`observations` have no times (time_utc is None): an ECSV light curve needs them.")
    o = observations
    columns = {"time_utc": o.time_utc, "magnitude": o.magnitude}
    if o.magnitude_sigma is not None:
        columns["magnitude_sigma"] = o.magnitude_sigma
    columns |= {f"{name}_{axis}": v[:, k] for name, v in (("sun", o.sun), ("observer", o.observer)) for k, axis in enumerate("xyz")}
    columns |= {"range_m": o.range_m, "in_shadow": o.in_shadow}
    if o.earth_m is not None:
        columns |= {name: o.earth_m[:, k] for k, name in enumerate(EARTH_COLUMNS)}
    return write_ecsv(path, columns, {"band": o.band, "source": o.source})


def _columns(rows: list[dict[str, str]], names: Sequence[str]) -> np.ndarray:
    """The columns ``names`` of ``rows`` as finite numbers."""
    out = np.empty((len(rows), len(names)))
    for i, row in enumerate(rows):
        for j, name in enumerate(names):
            try:
                out[i, j] = float(row[name])
            except (TypeError, ValueError):
                raise InputError(f"row {i + 1}'s {name} must be a number, got {row[name]!r}.") from None
    if not np.all(np.isfinite(out)):
        raise InputError(f"every value of {', '.join(names)} must be finite.")
    return out
