"""Track files of the Mini-MegaTORTORA (MMT-9) satellite database (Karpov et al. 2016, "Massive
photometry of low-altitude artificial satellites on Mini-MegaTORTORA", Revista Mexicana de Astronomia
y Astrofisica (Serie de Conferencias) 48, 112; the instrument: Beskin et al. 2017, "Wide-field
monitoring with Mini-MegaTORTORA multi-channel telescope with high temporal resolution",
Astrophysical Bulletin 72, 81).

The layout is the database's track download (``track_<id>.txt``), as its web application writes it
(``satellite_download`` in ``fweb/views_satellites.py`` of the MMT-9 software,
https://github.com/karpov-sv/favor2): ``#`` lines naming the satellite (``# satellite: <catalogue
number> <name> / <country>``), its catalogue, the track, its variability and the number of points,
then the header ``# Date Time StdMag Mag Filter Penumbra Distance Phase Channel`` and one line per
point, its values separated by spaces:

* ``Date Time``: UTC (``2019-12-09 16:37:00.250000``);
* ``StdMag``: the magnitude reduced to a standard distance (not used), ``Mag``: the apparent magnitude
  (no error is given);
* ``Filter``: ``Clear``, ``B``, ``V``, ``R``, ``Pol``, ``B+Pol``, ``V+Pol``, ``R+Pol`` (``Unknown``
  where none is recorded); ``V`` is spacefit's band ``V`` (:data:`MMT9_BANDS`), another filter's
  magnitudes are read only where ``band`` states their band;
* ``Penumbra``: 1 where the satellite is in the Earth's penumbra (flagged ``in_shadow``, as the
  database leaves such points out of its mean magnitudes);
* ``Distance`` (km) and ``Phase`` (the phase angle, deg), from the database's orbit;
* ``Channel``: the camera (not used); a satellite's whole download has a further column ``Track``.

An empty value is written ``None``. A track gives no direction to the satellite (the database keeps
its right ascension and declination but does not write them), so its geometry comes from an orbit
(a TLE or OMM of the satellite; the first line names its catalogue number), against which
``Distance`` and ``Phase`` are checked. The site is MMT-9's (:data:`MMT9_SITE`) unless another is given.
"""

from __future__ import annotations

import re

import numpy as np

from spacefit.errors import InputError
from spacefit.studies.lightcurve import SUN_MAGNITUDES
from spacefit.studies.observation_files import RefusedRow, SiteRows, time_refusals
from spacefit.studies.orbit import Site

# MMT-9 at the Special Astrophysical Observatory, Nizhnij Arkhyz (the MMT-9 software's fweb/settings.py).
MMT9_SITE = Site(43.65722222, 41.43235417, 2065.0)
MMT9_COLUMNS = ("Date", "Time", "StdMag", "Mag", "Filter", "Penumbra", "Distance", "Phase", "Channel")
# An MMT-9 filter -> spacefit's band (the others have none: Clear is unfiltered, Pol polarised).
MMT9_BANDS = {"V": "V"}
# The header line of a track download.
MMT9_HEADER = re.compile(r"^#\s*Date\s+Time\s+StdMag\s+Mag\s+Filter\b")


def is_mmt9(lines: list[str]) -> bool:
    """Whether the text ``lines`` are an MMT-9 track download (its header line among the comments)."""
    return any(MMT9_HEADER.match(line.strip()) for line in lines if line.lstrip().startswith("#"))


def read_mmt9(lines: list[str], *, band: str | None, site: Site | None, with_orbit: bool, launch_utc: str | None = None,
              now_utc: str | None = None) -> SiteRows:
    """The usable points of an MMT-9 track's text ``lines`` (module docstring), seen from ``site``
    (default :data:`MMT9_SITE`).

    Raises:
        InputError: no orbit, no header, a line with another count of values, a value that is not
            a number, a Penumbra flag other than 0 or 1, or filters without a band, each naming the row,
            the column and the value.
    """
    if not with_orbit:
        raise InputError("an MMT-9 track gives the distance and phase angle, not where the satellite was: give `orbit` "
                         "(sf.Orbit.from_tle or from_omm of the satellite its first line names).")
    header = next((line.strip().lstrip("#").split() for line in lines if MMT9_HEADER.match(line.strip())), None)
    if header is None or any(c not in header for c in MMT9_COLUMNS):
        raise InputError(f"an MMT-9 track needs the header '# {' '.join(MMT9_COLUMNS)}', got {header}.")
    data = [line.split() for line in lines if line.strip() and not line.lstrip().startswith("#")]
    if not data:
        raise InputError("no data rows.")
    at = {name: header.index(name) for name in MMT9_COLUMNS}
    for i, values in enumerate(data):
        if len(values) != len(header):
            raise InputError(f"row {i + 1} has {len(values)} values, the header {len(header)} ({' '.join(header)}): {' '.join(values)!r}.")
    times = [f"{v[at['Date']]} {v[at['Time']]}" for v in data]
    refused = time_refusals(times, "Date Time", launch_utc, now_utc)
    numbers = {name: np.array([_number(i, name, v[at[name]]) for i, v in enumerate(data)])
               for name in ("Mag", "Penumbra", "Distance", "Phase")}
    filters = [v[at["Filter"]] for v in data]
    read, band = _filter_read([f for i, f in enumerate(filters) if i not in refused] or filters, band)
    for i, values in enumerate(data):
        penumbra = numbers["Penumbra"][i]
        if not (np.isnan(penumbra) or penumbra in (0.0, 1.0)):
            raise InputError(f"row {i + 1}'s Penumbra must be 0 or 1, got {values[at['Penumbra']]!r}.")
        if i in refused:
            continue
        if filters[i] != read:
            refused[i] = RefusedRow(i + 1, "Filter", filters[i], f"another filter than the one read ({read}, band {band})")
        elif np.isnan(numbers["Mag"][i]):
            refused[i] = RefusedRow(i + 1, "Mag", values[at["Mag"]], "no magnitude")
        elif np.isnan(penumbra):
            refused[i] = RefusedRow(i + 1, "Penumbra", values[at["Penumbra"]], "missing (the Earth's penumbra unknown)")
    kept = np.array([i for i in range(len(data)) if i not in refused], dtype=int)
    if not len(kept):
        raise InputError(f"no usable rows: {'; '.join(str(r) for r in refused.values())}.")
    n = len(kept)
    site = site or MMT9_SITE
    return SiteRows(kept + 1, np.array(times)[kept], numbers["Mag"][kept], None, band, (site,) * n, np.full(n, np.nan),
                    np.full(n, np.nan), numbers["Distance"][kept] * 1e3, numbers["Phase"][kept], numbers["Penumbra"][kept] == 1.0,
                    tuple(refused[k] for k in sorted(refused)), {"range_m": "Distance", "phase_deg": "Phase"})


def _number(i: int, column: str, text: str) -> float:
    """Row ``i``'s (0-based) ``column`` ``text`` as a finite float, NaN where ``None``."""
    if text == "None":
        return float("nan")
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise InputError(f"row {i + 1}'s {column} must be a number (or None), got {text!r}.")
    return value


def _filter_read(filters: list[str], band: str | None) -> tuple[str, str]:
    """The filter whose rows are read, and their band: the one of ``band`` (else of a known band), or
    the file's only filter where ``band`` states its band."""
    present = list(dict.fromkeys(filters))
    if band is None:
        known = [f for f in present if f in MMT9_BANDS]
        if not known:
            raise InputError(f"the track's filters ({', '.join(present)}) have no spacefit band (known: {', '.join(MMT9_BANDS)}); "
                             f"give `band` (one of {', '.join(SUN_MAGNITUDES)}) to state the band of its magnitudes.")
        return known[0], MMT9_BANDS[known[0]]
    matching = [f for f in present if MMT9_BANDS.get(f) == band]
    if matching or len(present) == 1:
        return (matching or present)[0], band
    raise InputError(f"the track's rows are in filters {', '.join(present)}, none of band {band}: `band` states the band "
                     f"of a track in one filter only.")
