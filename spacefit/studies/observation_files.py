"""Light-curve files as observers publish them: which format a file is, the IAU CPS SatHub SCORE CSV,
astropy ECSV tables, and the rows a reader refuses (:class:`RefusedRow`, never silently dropped).

The SCORE CSV (the SatHub's "Satellite Observation Data Format"; every column present, optional
ones blank) is read from these columns:

* ``observation_time_utc`` (ISO 8601, UTC, a trailing ``Z`` allowed), ``apparent_magnitude`` and
  ``apparent_magnitude_uncertainty`` (mag), ``observing_filter`` (mapped to a spacefit band by
  :data:`SCORE_BANDS`; another filter is refused by name unless ``band`` states the band),
  ``observer_latitude_deg``, ``observer_longitude_deg`` (WGS84) and ``observer_altitude_m``;
  ``instrument`` and ``observing_mode`` are required to be there and otherwise not used;
* SatChecker's geometry, where present: ``alt_deg_satchecker``, ``az_deg_satchecker``,
  ``range_to_sat_km_satchecker`` (the target seen from the site), ``illuminated`` (``False``: the
  target in the Earth's shadow) and, for checking an orbit against them, ``phase_angle_deg_satchecker``.

A row is refused, with its number (1 for the first data row), column, value and reason, where its
time is not ISO 8601, before the launch (``launch_utc``) or in the future, where it has no magnitude
(a non-detection) or no uncertainty, or where it has no geometry and no orbit is given.

An ECSV file (astropy's ``Table.write(format="ascii.ecsv")``; an astropy ``TimeSeries`` writes one)
holds the general format's columns (:mod:`spacefit.studies.observing`), the time as ``time`` (an
astropy Time column, as a TimeSeries has it) or ``time_utc``, and in its metadata ``band`` and,
where the geometry is seen from a site, ``site`` (``latitude_deg``, ``longitude_deg``, ``height_m``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_choice
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.orbit import Site, is_time, iso_text
from spacefit.timescales import quiet_future_utc

FORMATS = ("general", "pomenis", "score", "ecsv", "mmt9", "tdm")
SCORE_REQUIRED = ("observation_time_utc", "apparent_magnitude", "apparent_magnitude_uncertainty", "observer_latitude_deg",
                  "observer_longitude_deg", "observer_altitude_m", "instrument", "observing_mode", "observing_filter")
SCORE_GEOMETRY = ("alt_deg_satchecker", "az_deg_satchecker", "range_to_sat_km_satchecker")
# SiteRows' quantities -> SatChecker's columns of them.
SCORE_CHECKED = {"altitude_deg": "alt_deg_satchecker", "azimuth_deg": "az_deg_satchecker", "range_m": "range_to_sat_km_satchecker",
                 "phase_deg": "phase_angle_deg_satchecker"}
# SCORE's observing_filter (lower case, spaces for - and _) -> spacefit's band. Only Johnson V has one:
# spacefit's other band is the Pomenis AB magnitude at 532 nm.
SCORE_BANDS = {"v": "V", "johnson v": "V", "bessel v": "V", "johnson cousins v": "V"}


@dataclass(frozen=True)
class RefusedRow:
    """A row a light-curve reader did not use: its number (1: the first data row), the column and the
    value that refused it, and why.

    Example:
        >>> import spacefit as sf
        >>> print(sf.RefusedRow(row=3, column="mag", value="x", reason="not a number"))
        row 3: mag 'x': not a number
    """

    row: int
    column: str
    value: str
    reason: str

    def __str__(self) -> str:
        return f"row {self.row}: {self.column} {self.value!r}: {self.reason}"


@dataclass(frozen=True)
class SiteRows:
    """The usable rows of a file whose observations are each seen from a site (SCORE, MMT-9, TDM),
    with the geometry the file gives (NaN where it has none).

    Attributes:
        rows: their numbers in the file (1: the first data row).
        times_utc, magnitude, band: as the file gives them; magnitude_sigma: None where it states no errors.
        sites: each row's observer.
        altitude_deg, azimuth_deg, range_m, phase_deg: the target seen from the site, by the file.
        dark: the file says the target was not illuminated (in the Earth's shadow or penumbra).
        refused: the rows not used.
        columns: the file's name of each of ``altitude_deg``, ``azimuth_deg``, ``range_m`` and
            ``phase_deg`` it gives, for the messages of a check against an orbit.
    """

    rows: np.ndarray
    times_utc: np.ndarray
    magnitude: np.ndarray
    magnitude_sigma: np.ndarray | None
    band: str
    sites: tuple[Site, ...]
    altitude_deg: np.ndarray
    azimuth_deg: np.ndarray
    range_m: np.ndarray
    phase_deg: np.ndarray
    dark: np.ndarray
    refused: tuple[RefusedRow, ...]
    columns: dict[str, str]


def file_format(path: Path, header: Sequence[str] | None) -> str:
    """The format of a light-curve file: ``ecsv`` (its first line ``# %ECSV``), ``score``, ``pomenis``
    or ``general`` from the CSV ``header``'s columns."""
    with path.open(encoding="utf-8", errors="replace") as f:
        if f.readline().startswith("# %ECSV"):
            return "ecsv"
    columns = set(header or ())
    if {"observation_time_utc", "apparent_magnitude"} <= columns:
        return "score"
    if {"observation_time", "ab_magnitude"} <= columns:
        return "pomenis"
    return "general"


def check_format(value: str | None) -> str | None:
    """``value`` if None or one of :data:`FORMATS`."""
    return None if value is None else check_choice("format", value, FORMATS)


@quiet_future_utc
def time_refusals(times: Sequence[str], column: str, launch_utc: str | None, now_utc: str | None) -> dict[int, RefusedRow]:
    """The rows (0-based) whose times cannot be right: not ISO 8601, before ``launch_utc``, after
    ``now_utc`` (default: now)."""
    from astropy.time import Time  # astropy: heavy, loaded when times are read

    bounds = {}
    for name, value in (("launch_utc", launch_utc), ("now_utc", now_utc)):
        if value is not None and not is_time(value):
            raise InputError(f"`{name}` must be an ISO 8601 time (UTC), got {value!r}.")
        bounds[name] = Time(iso_text(value), scale="utc") if value is not None else None
    now = bounds["now_utc"] if bounds["now_utc"] is not None else Time.now()
    try:
        readable = np.ones(len(times), dtype=bool)
        parsed = Time([iso_text(t) for t in times], format="isot", scale="utc")
    except ValueError:
        readable = np.array([is_time(t) for t in times], dtype=bool)
        parsed = Time([iso_text(t) if ok else "2000-01-01T00:00:00" for t, ok in zip(times, readable)], format="isot", scale="utc")
    early = parsed < bounds["launch_utc"] if bounds["launch_utc"] is not None else np.zeros(len(times), dtype=bool)
    late = parsed > now
    out = {}
    for i, text in enumerate(times):
        if not readable[i]:
            out[i] = RefusedRow(i + 1, column, str(text), "not an ISO 8601 time (UTC)")
        elif early[i]:
            out[i] = RefusedRow(i + 1, column, str(text), f"before the launch ({launch_utc})")
        elif late[i]:
            out[i] = RefusedRow(i + 1, column, str(text), f"in the future (after {now.isot})")
    return out


def score_band(row: int, value: str) -> str:
    """spacefit's band of SCORE's ``observing_filter`` ``value`` in data row ``row``."""
    key = re.sub(r"[\s_-]+", " ", value.strip().lower())
    if key not in SCORE_BANDS:
        raise InputError(f"row {row}'s observing_filter {value!r} has no spacefit band (known: {', '.join(sorted(SCORE_BANDS))}); "
                         f"give `band` (one of {', '.join(SUN_MAGNITUDES)}) to state the band of these magnitudes.")
    return SCORE_BANDS[key]


def _number(text: str | None) -> float:
    """``text`` as a float: NaN where blank; ValueError where not a finite number."""
    if text is None or not text.strip():
        return float("nan")
    value = float(text)
    if not np.isfinite(value):
        raise ValueError(text)
    return value


def read_score(rows: list[dict[str, str]], *, band: str | None, with_orbit: bool, launch_utc: str | None = None,
               now_utc: str | None = None) -> SiteRows:
    """The usable rows of a SCORE CSV's ``rows`` (module docstring); ``band`` states the magnitudes'
    band (else from each row's filter); ``with_orbit``: geometry will come from an orbit, so rows
    without SatChecker's are kept.

    Raises:
        InputError: a required column missing, an unknown filter, or a value that is not a number,
            each naming the row, the column and the value.
    """
    header = list(rows[0])
    missing = [c for c in SCORE_REQUIRED if c not in header]
    if missing:
        raise InputError(f"the SCORE header lacks {', '.join(missing)} (it has {', '.join(header)}).")
    times = [r["observation_time_utc"] or "" for r in rows]
    refused = time_refusals(times, "observation_time_utc", launch_utc, now_utc)
    bands = {band} if band is not None else set()
    numbers: dict[str, list[float]] = {}
    sites: list[Site] = []
    kept: list[int] = []
    for i, row in enumerate(rows):
        values = {}
        for column in (*SCORE_REQUIRED[1:6], *SCORE_GEOMETRY, "phase_angle_deg_satchecker"):
            try:
                values[column] = _number(row.get(column))
            except ValueError:
                raise InputError(f"row {i + 1}'s {column} must be a number, got {row.get(column)!r}.") from None
        if band is None:
            bands.add(score_band(i + 1, row["observing_filter"] or ""))
        if i in refused:
            continue
        blank = [c for c in SCORE_REQUIRED[1:6] if np.isnan(values[c])]
        if not with_orbit:
            blank += [c for c in SCORE_GEOMETRY if np.isnan(values[c])]
        if blank:
            why = "no magnitude (a non-detection)" if blank[0] == "apparent_magnitude" else "missing"
            refused[i] = RefusedRow(i + 1, blank[0], row.get(blank[0]) or "", why if blank[0] not in SCORE_GEOMETRY else "missing geometry")
            continue
        if values["apparent_magnitude_uncertainty"] <= 0:
            raise InputError(f"row {i + 1}'s apparent_magnitude_uncertainty must be positive, got {row['apparent_magnitude_uncertainty']!r}.")
        try:
            sites.append(Site(values["observer_latitude_deg"], values["observer_longitude_deg"], values["observer_altitude_m"]))
        except InputError as err:
            raise InputError(f"row {i + 1}: {err}") from None
        kept.append(i)
        for column, value in values.items():
            numbers.setdefault(column, []).append(value)
    if len(bands) > 1:
        raise InputError(f"the rows' filters are in several bands ({', '.join(sorted(bands))}): give `band`, or read one band per file.")
    if not kept:
        raise InputError(f"no usable rows: {'; '.join(str(r) for r in refused.values())}.")
    array = (lambda name: np.array(numbers[name]))
    dark = np.array([(rows[i].get("illuminated") or "").strip().lower() in ("false", "0", "no") for i in kept])
    return SiteRows(np.array(kept) + 1, np.array([times[i] for i in kept]), array("apparent_magnitude"),
                    array("apparent_magnitude_uncertainty"), bands.pop(), tuple(sites), array("alt_deg_satchecker"),
                    array("az_deg_satchecker"), array("range_to_sat_km_satchecker") * 1e3, array("phase_angle_deg_satchecker"),
                    dark, tuple(refused[k] for k in sorted(refused)), SCORE_CHECKED)


def read_ecsv(path: Path) -> tuple[list[dict[str, str]], str | None, Site | None]:
    """An ECSV light curve's rows as text (the time as ``time_utc``), and its metadata's band and site.

    Raises:
        InputError: not an ECSV table astropy reads, or a site that is not one.
    """
    from astropy.table import Table  # astropy: heavy, loaded when an ECSV file is read
    from astropy.time import Time

    try:
        table = Table.read(path, format="ascii.ecsv")
    except Exception as err:  # astropy raises many kinds for a malformed table
        raise InputError(f"light curve {path}: not an ECSV table astropy reads ({type(err).__name__}: {err}).") from None
    columns: dict[str, Any] = {name: table[name] for name in table.colnames}
    if "time" in columns and "time_utc" not in columns:
        time = columns.pop("time")
        columns["time_utc"] = (time.utc.isot if isinstance(time, Time) else time)
    rows = [{name: str(values[i]) for name, values in columns.items()} for i in range(len(table))]
    site = table.meta.get("site")
    if site is not None:
        try:
            site = Site(**site)
        except TypeError:
            raise InputError(f"light curve {path}: the metadata's site must have latitude_deg, longitude_deg, height_m, got {site!r}.") from None
    return rows, table.meta.get("band"), site


@quiet_future_utc
def write_ecsv(path: str | Path, columns: dict[str, np.ndarray], meta: dict[str, Any]) -> Path:
    """Write ``columns`` (``time_utc`` as an astropy Time column ``time``) with ``meta`` as an ECSV table."""
    from astropy.table import Table  # astropy: heavy, loaded when an ECSV file is written
    from astropy.time import Time

    table = Table(meta=meta)
    for name, values in columns.items():
        if name == "time_utc":
            table["time"] = Time([iso_text(t) for t in values], format="isot", scale="utc")
        else:
            table[name] = values
    table.write(path, format="ascii.ecsv", overwrite=True)
    return Path(path)
