"""A light-curve file and its target's scene file, read into the rendered light curve that
``spacefit fit-light-curve`` fits (:class:`~spacefit.studies.lightcurve_fit.RenderedLightCurve`).

Two kinds of file give the points' geometry:

* a point table (CSV, ECSV or a FITS table, read by ``astropy.table``): a ``magnitude`` column,
  optionally ``magnitude_sigma`` (mag) and ``time`` (kept as written, not used), and the geometry as
  any scene values of a point (:data:`~spacefit.studies.lightcurve_fit.POINT_KEYS`), in the scene's
  own vocabulary and units as a pass's frame table gives them (:mod:`spacefit.fitting.passes`):
  ``target.attitude_z_deg``, ``sun.elevation_deg``, a vector key (``camera.position_m``,
  ``sun.direction``) as one column of 3 numbers per row (ECSV, FITS) or as ``KEY.x``, ``KEY.y``,
  ``KEY.z``. A table is a point table when a column names a point's geometry.
* any other light-curve file :func:`~spacefit.studies.observing.read_light_curve` reads (the
  directions of the sun and the observer in the target's frame, or seen from a ``site``, ...): each
  lit observation at its geometry with the scene's camera and its magnitude carried to the median
  range (:func:`~spacefit.studies.target_plates.rendered_light_curve`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_path, check_range, check_type
from spacefit.fitting.passes import COMPONENTS, VECTOR_KEYS, cell, scene_columns, table_column
from spacefit.rendering.derivatives import check_seed
from spacefit.scene.toml import load_scene
from spacefit.studies.lightcurve_fit import POINT_KEYS, RenderedLightCurve
from spacefit.studies.lightcurve_observations import LightCurveObservations
from spacefit.studies.observing import read_light_curve
from spacefit.studies.orbit import Site
from spacefit.studies.target_plates import rendered_light_curve

MAGNITUDE, SIGMA, TIME = "magnitude", "magnitude_sigma", "time"
# The extensions of the tables astropy reads as point tables, and their astropy formats.
TABLE_FORMATS = {".csv": "ascii.csv", ".ecsv": "ascii.ecsv", ".fits": "fits", ".fit": "fits", ".fts": "fits"}


def is_point_column(name: str) -> bool:
    """Whether a table column names a point's geometry (a point key, or a vector key's component)."""
    key, _, component = name.rpartition(".")
    return name in POINT_KEYS or (key in VECTOR_KEYS and component in COMPONENTS)


@dataclass(frozen=True)
class LightCurveFiles:
    """A light-curve file and the scene file of its target, what ``spacefit fit-light-curve`` fits.

    The file is a point table (CSV, ECSV or a FITS table: a ``magnitude`` column, optionally
    ``magnitude_sigma`` (mag), and each point's geometry as scene values in the scene's vocabulary
    and units, ``sun.elevation_deg``, ``target.attitude_z_deg``, ...), or any light-curve file
    :func:`read_light_curve` reads, each lit observation then rendered at its geometry with the
    scene's camera.

    Attributes:
        curve: the light-curve file.
        scene: the target's scene file (TOML); its values are the fit's start.
        overrides: ``KEY=VALUE`` scene values applied to the scene (as ``--set`` takes them).
        band: the magnitudes' band (default: the file's, else V).
        site: the observer, for a file whose geometry is seen from a site.
        sigma_mag: the magnitudes' error (mag) where the file gives none (None: unknown).
        seed: the renders' seed, in [0, 2^31 - 1].

    Raises:
        InputError: a bad option value (the files themselves are read when the fit runs).

    Example:
        >>> import spacefit as sf
        >>> files = sf.LightCurveFiles(curve="curve.csv", scene="lander.toml", sigma_mag=0.05)
        >>> files.band is None  # the file's band, else V
        True
    """

    curve: str | Path
    scene: str | Path
    overrides: Sequence[str] = ()
    band: str | None = None
    site: Site | None = None
    sigma_mag: float | None = None
    seed: int = 1

    def __post_init__(self) -> None:
        check_path("curve", self.curve)
        check_path("scene", self.scene)
        check_type("site", self.site, (Site, type(None)), "an sf.Site or None")
        if self.sigma_mag is not None:
            check_range("sigma_mag", self.sigma_mag, 0.0, lo_open=True, unit="mag")
        check_seed("seed", self.seed)
        object.__setattr__(self, "overrides", tuple(self.overrides))

    @property
    def files(self) -> tuple[str | Path, ...]:
        """Every input file named (no output may write over one)."""
        return (self.curve, self.scene)

    def load(self) -> RenderedLightCurve:
        """Read the scene and the light curve.

        Raises:
            InputError: a scene or a light-curve file refused, naming the file, the row or the column;
                magnitude errors both in the file and ``sigma_mag``.
        """
        scene = load_scene(self.scene, list(self.overrides))
        path = Path(self.curve)
        if not path.is_file():
            raise InputError(f"light curve {str(path)!r} does not exist.")
        table = _point_table(path)
        if table is None:
            observations = read_light_curve(path, site=self.site, band=self.band)
            if observations.magnitude_sigma is None and self.sigma_mag is not None:
                observations = _with_sigma(observations, self.sigma_mag)
            elif self.sigma_mag is not None:
                raise InputError(f"light curve {str(path)!r} states its magnitude errors: leave `sigma_mag` out.")
            return rendered_light_curve(scene, observations, seed=self.seed)
        points, magnitude, sigma = table
        if sigma is not None and self.sigma_mag is not None:
            raise InputError(f"light curve {str(path)!r} has a `{SIGMA}` column: leave `sigma_mag` out.")
        try:
            return RenderedLightCurve(scene, points, magnitude, self.sigma_mag if sigma is None else sigma, self.band or "V",
                                      seed=self.seed)
        except InputError as err:
            raise type(err)(f"light curve {str(path)!r}: {err}") from None

    def record(self) -> dict[str, Any]:
        """What fit.json's ``inputs`` record of these files."""
        site = None if self.site is None else [self.site.latitude_deg, self.site.longitude_deg, self.site.height_m]
        return {"curve": str(self.curve), "scene_file": str(self.scene), "overrides": list(self.overrides), "band": self.band,
                "site": site, "sigma_mag": self.sigma_mag, "seed": self.seed}


def _point_table(path: Path) -> tuple[list[dict[str, Any]], np.ndarray, np.ndarray | None] | None:
    """A point table's points, magnitudes and errors (None: none given), or None for a file that is no point table."""
    if path.suffix.lower() not in TABLE_FORMATS:
        return None
    from astropy.table import Table  # deferred: astropy's table readers (0.3 s), which only a light-curve file needs

    try:
        table = Table.read(path, format=TABLE_FORMATS[path.suffix.lower()])
    except (ValueError, OSError, KeyError, IndexError) as err:
        if path.suffix.lower() == ".csv":  # a light curve of another format in CSV (general, Pomenis, SCORE)
            return None
        raise InputError(f"light curve {str(path)!r} cannot be read as {TABLE_FORMATS[path.suffix.lower()]}: {err}") from None
    names = list(table.colnames)
    if not any(is_point_column(name) for name in names):
        return None
    other = [n for n in names if n not in (MAGNITUDE, SIGMA, TIME) and not is_point_column(n)]
    if MAGNITUDE not in names or other:
        raise InputError(f"light curve {str(path)!r}: a point table has a `{MAGNITUDE}` column, optionally `{SIGMA}` and `{TIME}`, and "
                         f"columns of the points' geometry ({', '.join(POINT_KEYS)}; a vector as KEY.x, KEY.y, KEY.z); "
                         f"got {'no magnitude' if MAGNITUDE not in names else 'also ' + ', '.join(other)}.")
    try:
        cols = {name: table_column(table[name]) for name in names}
        magnitude = np.array([_number(MAGNITUDE, cell(v), i) for i, v in enumerate(cols[MAGNITUDE])])
        sigma = np.array([_number(SIGMA, cell(v), i) for i, v in enumerate(cols[SIGMA])]) if SIGMA in cols else None
        return scene_columns(cols, len(magnitude), other=(MAGNITUDE, SIGMA, TIME)), magnitude, sigma
    except InputError as err:
        raise type(err)(f"light curve {str(path)!r}: {err}") from None


def _number(column: str, value: Any, row: int) -> float:
    """A table cell that must be a finite number (a column with a word in it is read as text)."""
    try:
        number = float(value) if isinstance(value, (int, float, str)) and not isinstance(value, bool) else None
    except ValueError:
        number = None
    if number is None or not np.isfinite(number):
        raise InputError(f"row {row}'s `{column}` must be a finite number, got {value!r}.")
    return number


def _with_sigma(observations: LightCurveObservations, sigma_mag: float) -> LightCurveObservations:
    """``observations`` with every magnitude's error ``sigma_mag``."""
    return dataclasses.replace(observations, magnitude_sigma=np.full(len(observations), sigma_mag))
