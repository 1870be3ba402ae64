"""CCSDS Tracking Data Messages with magnitudes (CCSDS 503.0-B-2, "Tracking Data Message", Blue Book
issue 2, 2020), in the keyword = value notation (KVN; the XML form is not read).

A message starts with ``CCSDS_TDM_VERS``, then header keywords (``CREATION_DATE``, ``ORIGINATOR``,
...), then one or more segments, each a metadata block ``META_START`` ... ``META_STOP`` and a data
block ``DATA_START`` ... ``DATA_STOP``; ``COMMENT`` lines may stand anywhere. Read from the metadata:

* ``TIME_SYSTEM`` (required): the data's time scale: ``UTC``, or ``TAI``, ``TT``, ``GPS`` (TAI - 19 s),
  ``TDB``, ``TCB``, ``TCG``, ``UT1``, converted to UTC by astropy (:data:`TIME_SYSTEMS`);
* ``PARTICIPANT_1`` (required) and the others, and ``PATH``: the data's path (``2,1``: from the
  satellite to the observer). The standard has no keyword for where a participant is, so the
  observer's site is an argument;
* ``ANGLE_TYPE``: with ``AZEL``, ``ANGLE_1`` is the azimuth and ``ANGLE_2`` the elevation (deg);
  ``RANGE_UNITS``: ``km`` (or absent) for ``RANGE`` to be a distance;
* ``CORRECTIONS_APPLIED`` and ``CORRECTION_MAG``, ``CORRECTION_ANGLE_1``, ``CORRECTION_ANGLE_2``,
  ``CORRECTION_RANGE``: where the corrections are not applied (``NO``), they are added to the data.

Each data line is ``KEYWORD = time value`` (the time ISO 8601, ``2023-01-01T00:00:00.000`` or by day
of year ``2023-001T00:00:00``). Every ``MAG`` line is an observation (an apparent visual magnitude,
spacefit's band ``V`` unless ``band`` states another; the standard gives no error per value). Its
geometry: ``ANGLE_1``, ``ANGLE_2`` (``AZEL``) and ``RANGE`` (one-way ``PATH`` of two participants)
of the same segment and time, seen from the site; or an orbit's. Other data keywords are not read.
A row is a line of the file (1: its first line); a ``MAG`` line is refused where its time is
unreadable, before the launch or in the future, or where it has no geometry and no orbit is given.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field

import numpy as np

from spacefit.errors import InputError
from spacefit.studies.observation_files import RefusedRow, SiteRows, time_refusals
from spacefit.studies.orbit import Site, offline_iers

# TDM's TIME_SYSTEM -> (astropy's scale, seconds to add to read the time in it).
TIME_SYSTEMS = {"UTC": ("utc", 0.0), "TAI": ("tai", 0.0), "TT": ("tt", 0.0), "GPS": ("tai", 19.0), "TDB": ("tdb", 0.0),
                "TCB": ("tcb", 0.0), "TCG": ("tcg", 0.0), "UT1": ("ut1", 0.0)}
GEOMETRY_KEYWORDS = ("ANGLE_1", "ANGLE_2", "RANGE")
# What each geometry keyword's value may be (AZEL angles, range in km).
GEOMETRY_LIMITS = {"ANGLE_1": (lambda v: -180.0 <= v < 360.0, "an azimuth in [-180, 360) deg"),
                   "ANGLE_2": (lambda v: -90.0 <= v <= 90.0, "an elevation in [-90, 90] deg"),
                   "RANGE": (lambda v: v > 0.0, "a positive distance (km)")}
DAY_OF_YEAR = re.compile(r"^(\d{4})-(\d{3})T(.*)$")


@dataclass
class _Segment:
    """One metadata block's keywords and its data lines: (line number, keyword, time, value text)."""

    meta: dict[str, str] = field(default_factory=dict)
    lines: list[tuple[int, str, str, str]] = field(default_factory=list)


def is_tdm(lines: list[str]) -> bool:
    """Whether the text ``lines`` begin (after blank and ``COMMENT`` lines) with ``CCSDS_TDM_VERS``."""
    return bool(lines) and lines[_first_line(lines) - 1].strip().startswith("CCSDS_TDM_VERS")


def read_tdm(lines: list[str], *, band: str | None, site: Site | None, with_orbit: bool, launch_utc: str | None = None,
             now_utc: str | None = None) -> SiteRows:
    """The usable ``MAG`` observations of a TDM's text ``lines`` (module docstring), seen from ``site``.

    Raises:
        InputError: no site, a missing or misplaced block or keyword, an unknown TIME_SYSTEM, a value
            that is not a number, an angle or range out of range, each naming the line, the keyword and
            the value.
    """
    if site is None:
        raise InputError("a TDM names its participants but not where they are: give the observer's `site` "
                         "(sf.Site(latitude_deg, longitude_deg, height_m)).")
    segments = _segments(lines)
    rows: list[int] = []
    times: list[str] = []
    tags: list[str] = []
    magnitude: list[float] = []
    geometry: list[tuple[float, float, float]] = []
    refused: dict[int, RefusedRow] = {}
    for segment in segments:
        for row, tag, time_utc, value, angles in _observations(segment):
            if time_utc is None:
                refused[len(rows)] = RefusedRow(row, "MAG", tag, "its time is not ISO 8601 (nor a day of year)")
            rows.append(row)
            tags.append(tag)
            times.append(time_utc or "2000-01-01T00:00:00")
            magnitude.append(value)
            geometry.append(angles)
    if not rows:
        raise InputError("no MAG data lines.")
    readable = [i for i in range(len(rows)) if i not in refused]
    for k, why in time_refusals([times[i] for i in readable], "MAG", launch_utc, now_utc).items():
        refused[readable[k]] = RefusedRow(rows[readable[k]], why.column, tags[readable[k]], why.reason)
    geometry_array = np.array(geometry, dtype=float).reshape(-1, 3)
    for i in range(len(rows)):
        if i not in refused and not with_orbit and np.isnan(geometry_array[i]).any():
            missing = GEOMETRY_KEYWORDS[int(np.flatnonzero(np.isnan(geometry_array[i]))[0])]
            refused[i] = RefusedRow(rows[i], missing, "", "missing geometry (no AZEL angles and km range at this time, no orbit)")
    kept = np.array([i for i in range(len(rows)) if i not in refused], dtype=int)
    if not len(kept):
        raise InputError(f"no usable rows: {'; '.join(str(r) for r in refused.values())}.")
    n = len(kept)
    g = geometry_array[kept]
    return SiteRows(np.array(rows)[kept], np.array(times)[kept], np.array(magnitude, dtype=float)[kept], None, band or "V",
                    (site,) * n, g[:, 1], g[:, 0], g[:, 2] * 1e3, np.full(n, np.nan), np.zeros(n, dtype=bool),
                    tuple(refused[k] for k in sorted(refused)),
                    {"altitude_deg": "ANGLE_2", "azimuth_deg": "ANGLE_1", "range_m": "RANGE"})


def _segments(lines: list[str]) -> list[_Segment]:
    """The message's segments, its structure checked."""
    first = _first_line(lines)
    if not lines[first - 1].strip().startswith("CCSDS_TDM_VERS"):
        raise InputError(f"line {first}: a TDM starts with CCSDS_TDM_VERS, got {lines[first - 1].strip()!r}.")
    state, segments = "header", []
    for row, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("COMMENT"):
            continue
        if line in ("META_START", "META_STOP", "DATA_START", "DATA_STOP"):
            expected = {"header": "META_START", "data_done": "META_START", "meta": "META_STOP", "meta_done": "DATA_START",
                        "data": "DATA_STOP"}[state]
            if line != expected:
                raise InputError(f"line {row}: {line} where {expected} belongs.")
            state = {"META_START": "meta", "META_STOP": "meta_done", "DATA_START": "data", "DATA_STOP": "data_done"}[line]
            if line == "META_START":
                segments.append(_Segment())
            continue
        key, eq, value = line.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or not key:
            raise InputError(f"line {row}: {line!r} is not KEYWORD = value.")
        if state == "meta":
            segments[-1].meta[key] = value
        elif state == "data":
            time, _, number = value.partition(" ")
            if not number.strip():
                raise InputError(f"line {row}: {key}'s value must be a time and a number, got {value!r}.")
            segments[-1].lines.append((row, key, time, number.strip()))
        elif state in ("meta_done", "data_done"):
            raise InputError(f"line {row}: {key} outside a metadata or data block.")
    if not segments:
        raise InputError("no segment: a TDM's metadata stands between META_START and META_STOP.")
    if state != "data_done":
        raise InputError(f"the last segment is not closed (it ends in its {state.removesuffix('_done')} block).")
    for segment in segments:
        for key in ("TIME_SYSTEM", "PARTICIPANT_1"):
            if key not in segment.meta:
                raise InputError(f"a segment's metadata lacks {key} (it has {', '.join(segment.meta) or 'nothing'}).")
        if segment.meta["TIME_SYSTEM"] not in TIME_SYSTEMS:
            raise InputError(f"TIME_SYSTEM must be one of {', '.join(TIME_SYSTEMS)}, got {segment.meta['TIME_SYSTEM']!r}.")
    return segments


def _first_line(lines: list[str]) -> int:
    """The number of the first line that is neither blank nor a comment (1 where none is)."""
    return next((i for i, line in enumerate(lines, start=1) if line.strip() and not line.strip().startswith("COMMENT")), 1)


def _observations(segment: _Segment) -> list[tuple[int, str, str | None, float, tuple[float, float, float]]]:
    """Each ``MAG`` line of ``segment``: its line, time as written and in UTC (None: unreadable),
    corrected magnitude and (azimuth, elevation, range km) at its time, NaN where the segment gives none."""
    meta = segment.meta
    corrected = meta.get("CORRECTIONS_APPLIED", "NO").upper() == "NO"
    use_angles = meta.get("ANGLE_TYPE", "").upper() == "AZEL"
    path = [p for p in meta.get("PATH", "").split(",") if p.strip()]
    use_range = meta.get("RANGE_UNITS", "km").lower() == "km" and len(path) == 2
    values: dict[tuple[str, str], float] = {}
    for row, key, time, text in segment.lines:
        if key == "MAG" or (key == "RANGE" and use_range) or (key.startswith("ANGLE_") and use_angles):
            value = _number(row, key, text) + (_number(row, f"CORRECTION_{key}", meta.get(f"CORRECTION_{key}", "0")) if corrected else 0.0)
            allowed, what = GEOMETRY_LIMITS.get(key, (lambda v: True, ""))
            if not allowed(value):
                raise InputError(f"line {row}: {key} at {time} must be {what}, got {value:g}.")
            values[(key, time)] = value
    utc = _utc(sorted({time for (key, time) in values if key == "MAG"}), meta["TIME_SYSTEM"])
    out = []
    for row, key, time, _ in segment.lines:
        if key != "MAG":
            continue
        azimuth, elevation, distance = (values.get((k, time), np.nan) for k in GEOMETRY_KEYWORDS)
        out.append((row, time, utc[time], values[("MAG", time)], (azimuth % 360.0, elevation, distance)))
    return out


def _number(row: int, key: str, text: str) -> float:
    """Line ``row``'s ``key`` value ``text`` as a finite float."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise InputError(f"line {row}: {key}'s value must be a number, got {text!r}.")
    return value


def _utc(times: list[str], system: str) -> dict[str, str | None]:
    """Each TDM time of the scale ``system`` as an ISO 8601 UTC text (None: not a time)."""
    scale, offset_s = TIME_SYSTEMS[system]
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*dubious year")  # a time far from now: refused later, not warned of twice
        return {text: _one_utc(text, scale, offset_s) for text in times}


def _one_utc(text: str, scale: str, offset_s: float) -> str | None:
    """A TDM time ``text`` of astropy's ``scale``, ``offset_s`` added, as ISO 8601 UTC (None: not a time)."""
    from astropy import units as u  # astropy: heavy, loaded when times are read
    from astropy.time import Time

    match = DAY_OF_YEAR.match(text)
    try:
        t = Time(f"{match[1]}:{match[2]}:{match[3]}" if match else text, format="yday" if match else "isot", scale=scale)
    except ValueError:
        return None
    with offline_iers():
        return (t + offset_s * u.s).utc.isot
