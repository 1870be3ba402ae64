"""A pass: the frames a telescope records of one target as it follows it, each with its own time,
sun, observer and nominal target attitude, read from a table and fitted jointly.

A frame table has one row per frame (CSV, ECSV or a FITS table, read by ``astropy.table``; or
Python columns). Its columns, in the scene's own vocabulary and units (degrees at this edge):

- ``file``: the frame's observation (any image :meth:`Observation.from_file` reads), relative to the table's folder;
- ``time``: an ISO 8601 UTC time (``2026-03-04T05:06:07.5``) or seconds (any origin);
- any scene value by name, as ``--set`` takes it: a scene-file key or a parameter name
  (``sun.elevation_deg``, ``sun.azimuth_deg``, ``target.attitude_x_deg``, ``camera.roll_deg``); a
  vector key (``camera.position_m``, ``camera.look_at_m``, ``camera.attitude_deg``, ``camera.up``,
  ``sun.direction``, ``target.attitude_deg``, ``target.position_m``) as one column of 3 numbers
  per row (ECSV, FITS) or as three columns ``KEY.x``, ``KEY.y``, ``KEY.z`` (any table). A frame that
  gives the camera's ``attitude_deg`` and no ``look_at_m`` is posed by attitude;
- ``sensor.FIELD``: a per-frame :class:`Sensor` value (``sensor.exposure_time_s``);
- ``mask``: a per-frame mask image (optional).

Each frame's scene is the pass's scene with the frame's values set (:meth:`Pass.scenes`). A joint
fit frees the materials once and, per frame, the nuisances the user names
(:meth:`Pass.per_frame`: ``target.attitude_x_deg`` -> ``target.attitude_x_deg@k`` for each frame
k), or, the pass given whole as one observation (:class:`PassObservation`),
the fit frees them; :func:`frame_table` and :func:`plot_frames` give the per-frame values and goodness of fit
against time (a fit's report writes them as ``frames.csv`` and ``frames.png``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_path, quote
from spacefit.scene.names import Name
from spacefit.scene.parameters import PER_OBSERVATION
from spacefit.scene.schema import Scene
from spacefit.timescales import quiet_future_utc

# Scene-file keys that hold 3 numbers, given as one column of 3 or as KEY.x, KEY.y, KEY.z.
VECTOR_KEYS = ("camera.position_m", "camera.attitude_deg", "camera.look_at_m", "camera.up", "sun.direction",
               "target.position_m", "target.attitude_deg")
COMPONENTS = ("x", "y", "z")
SENSOR_PREFIX = "sensor."
# Columns that are not scene values.
FILE, TIME, MASK = "file", "time", "mask"


@dataclass(frozen=True)
class Frame:
    """One frame of a pass.

    Attributes:
        file: the observation's image file.
        time: as given: an ISO 8601 UTC time, or seconds as text.
        time_s: seconds since the pass's first frame (by ``time``).
        values: the frame's scene values by name (scene-file keys and parameter names), in the scene's units.
        sensor: the frame's own sensor values (:class:`Sensor` fields).
        mask: a mask image of the frame, or None.

    Example:
        >>> import spacefit as sf
        >>> frame = sf.Pass.from_columns({"file": ["f0.exr"], "time": ["2026-03-04T05:06:07"]}).frames[0]
        >>> frame.file.name, frame.time_s
        ('f0.exr', 0.0)
    """

    file: Path
    time: str
    time_s: float
    values: Mapping[str, Any] = field(default_factory=dict)
    sensor: Mapping[str, Any] = field(default_factory=dict)
    mask: Path | None = None


@dataclass(frozen=True)
class Pass:
    """The frames of a pass, in time order as given (:meth:`read` a table file, :meth:`from_columns`
    Python columns or an astropy table). Checked on construction; each frame's scene values are
    checked against a scene by :meth:`scenes`.

    Args:
        frames: the frames (:class:`Frame`).

    Raises:
        InputError: no frame, times of two kinds or not in order, a frame's bad value, naming the frame.

    Example:
        >>> import spacefit as sf
        >>> p = sf.Pass.from_columns({"file": ["f0.exr", "f1.exr"], "time": ["0", "10"], "sun.elevation_deg": [80.0, 78.0]})
        >>> p.frames[1].time_s, p.frames[1].values
        (10.0, {'sun.elevation_deg': 78.0})
    """

    frames: tuple[Frame, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "frames", tuple(self.frames))
        if not self.frames:
            raise InputError("a pass needs at least one frame; the frame table has no rows.")
        for i, frame in enumerate(self.frames):
            if not isinstance(frame, Frame):
                raise InputTypeError(f"`frames[{i}]` must be an sf.Frame, got {quote(frame)}.")

    def __len__(self) -> int:
        return len(self.frames)

    @classmethod
    def read(cls, path: str | Path) -> Pass:
        """The pass in a frame table file: CSV (``.csv``), ECSV (``.ecsv``) or a FITS table
        (``.fits``, ``.fit``, ``.fts``; the first table extension). Files in it are relative to its folder.

        Raises:
            InputError: a missing or unreadable file, another extension, a column refused by :meth:`from_columns`.
        """
        from astropy.table import Table  # deferred: astropy's table readers (0.3 s), which only a pass needs

        path = check_path("path", path)
        formats = {".csv": "ascii.csv", ".ecsv": "ascii.ecsv", ".fits": "fits", ".fit": "fits", ".fts": "fits"}
        if path.suffix.lower() not in formats:
            raise InputError(f"frame table {str(path)!r}: the extension must be one of {', '.join(formats)} (CSV, ECSV, FITS table).")
        if not path.is_file():
            raise InputError(f"frame table {str(path)!r} does not exist.")
        try:
            table = Table.read(path, format=formats[path.suffix.lower()])
        except (ValueError, OSError, KeyError, IndexError) as err:
            raise InputError(f"frame table {str(path)!r} cannot be read as {formats[path.suffix.lower()]}: {err}") from None
        return cls.from_columns(table, base_dir=path.parent)

    @classmethod
    def from_columns(cls, columns: Any, base_dir: str | Path = ".") -> Pass:
        """The pass in a table given by columns: a mapping of column name -> one value per frame
        (Python lists, NumPy arrays; a vector key's column holds 3 numbers per frame) or an
        ``astropy.table.Table``. Relative files are taken from ``base_dir``.

        Raises:
            InputError: no ``file`` or ``time`` column, columns of unequal lengths, a time that is
                neither ISO 8601 nor a number, a component column without its siblings, two frames
                with the same file or the same time.
        """
        names = list(columns.colnames if hasattr(columns, "colnames") else columns)
        for name in names:
            if not isinstance(name, str):
                raise InputTypeError(f"frame table column names must be strings, got {quote(name)}.")
        for required in (FILE, TIME):
            if required not in names:
                raise InputError(f"the frame table has no `{required}` column (columns: {', '.join(names) or 'none'}); "
                                 "every frame needs its observation file and its time.")
        cols = {name: table_column(columns[name]) for name in names}
        lengths = {name: len(col) for name, col in cols.items()}
        n = lengths[FILE]
        if any(length != n for length in lengths.values()):
            raise InputError(f"the frame table's columns must have one value per frame, got lengths {lengths}.")
        times = [_time_text(cols[TIME][i], i) for i in range(n)]
        seconds = elapsed_seconds(times)
        base = Path(base_dir)
        files = [base / str(cell(cols[FILE][i])).strip() for i in range(n)]
        for what, keys in (("file", [str(f) for f in files]), ("time", seconds)):
            first: dict[Any, int] = {}
            for i, key in enumerate(keys):
                if key in first:
                    raise InputError(f"frames {first[key]} and {i} of the frame table have the same {what} "
                                     f"{str(files[i]) if what == 'file' else times[i]!r}: a frame is one observation, listed once "
                                     "(a repeated frame would count its pixels twice); remove one of the rows.")
                first[key] = i
        values = scene_columns(cols, n)
        frames = []
        for i in range(n):
            sensor = {name[len(SENSOR_PREFIX):]: cell(cols[name][i]) for name in cols if name.startswith(SENSOR_PREFIX)}
            mask = base / str(cell(cols[MASK][i])).strip() if MASK in cols else None
            frames.append(Frame(files[i], times[i], seconds[i], values[i], sensor, mask))
        return cls(tuple(frames))

    @property
    def files(self) -> tuple[Path, ...]:
        """Each frame's observation file."""
        return tuple(f.file for f in self.frames)

    @property
    def times_s(self) -> np.ndarray:
        """Each frame's time, seconds since the first frame."""
        return np.array([f.time_s for f in self.frames])

    def scenes(self, scene: Scene) -> list[Scene]:
        """Each frame's scene: ``scene`` with the frame's values set (checked as ``--set`` checks them).

        Raises:
            InputError: a value refused, naming the frame and the column.
        """
        out = []
        for i, frame in enumerate(self.frames):
            try:
                out.append(scene.with_values(dict(frame.values)))
            except InputError as err:
                raise type(err)(f"frame {i} ({frame.file.name}): {err}") from None
        return out

    def per_frame(self, names: Sequence[str]) -> list[str]:
        """Each of ``names`` once per frame (``target.attitude_x_deg@0``, ``@1``, ...): the fit's
        per-frame nuisances. Refuses a name that cannot be one observation's own."""
        for name in names:
            if name not in PER_OBSERVATION:
                raise InputError(f"`per_frame` name {name!r} cannot be one frame's own; the per-frame parameters are "
                                 f"{', '.join(PER_OBSERVATION)}.")
        return [Name(name, k) for name in names for k in range(len(self.frames))]

    def observation_files(self, scene: str | Path, **options: Any) -> Any:
        """The frames as :class:`ObservationFiles` for
        :func:`fit_to_folder`: one scene file for all, each frame's values,
        sensor values, mask and time; ``options``: the other ``ObservationFiles`` fields
        (``overrides``, ``resolution``, ``sensor_values``, ``sensor_defaults``...)."""
        from spacefit.fitting.observation_files import ObservationFiles  # here: it loads the fitting stack (JAX); reading a pass does not

        masks = [f.mask for f in self.frames]
        if any(m is not None for m in masks) and "masks" in options:
            raise InputError("the frame table has a `mask` column: leave `masks` out.")
        if all(m is not None for m in masks):
            options["masks"] = masks
        elif any(m is not None for m in masks):
            raise InputError("the frame table's `mask` column must name a mask for every frame.")
        return ObservationFiles(self.files, (scene,), values=[dict(f.values) for f in self.frames],
                                frame_sensor_values=[dict(f.sensor) for f in self.frames],
                                times=[f.time for f in self.frames], **options)


def table_column(values: Any) -> list[Any]:
    """A table's column as a list of per-row values (a vector column: per-row lists of 3)."""
    if hasattr(values, "isot"):  # an astropy Time column (ECSV)
        return list(values.isot)
    if np.any(np.ma.getmaskarray(values)):
        raise InputError("the table has empty cells; give every row every column's value.")
    array = np.asarray(values)
    if array.ndim == 0:
        raise InputError(f"a table column must hold one value per row, got {quote(values)}.")
    return [v.tolist() if isinstance(v, np.ndarray) else v for v in array]


def cell(value: Any) -> Any:
    """A table cell as a plain Python value."""
    if isinstance(value, bytes):
        return value.decode()
    return value.item() if isinstance(value, np.generic) else value


def _time_text(value: Any, row: int) -> str:
    value = cell(value)
    if isinstance(value, bool):
        raise InputTypeError(f"frame {row}: `time` must be an ISO 8601 UTC time or seconds, got {value!r}.")
    return repr(float(value)) if isinstance(value, (int, float)) else str(value).strip()


@quiet_future_utc
def elapsed_seconds(times: Sequence[str]) -> list[float]:
    """Seconds since the first frame of ISO 8601 UTC times (rounded to the nanosecond: astropy's
    difference of two Julian dates is off by picoseconds, 9.999999999998 s for 10 s), or of numbers of
    seconds (all one kind)."""
    try:
        numbers = [float(t) for t in times]
    except ValueError:
        numbers = None
    if numbers is not None:
        if not all(math.isfinite(t) for t in numbers):
            raise InputError(f"`time` must be finite seconds, got {[t for t in times if not math.isfinite(float(t))][0]!r}.")
        return [t - numbers[0] for t in numbers]
    from astropy.time import Time  # deferred: astropy's time scales, which only a pass with ISO times needs

    out = []
    for i, t in enumerate(times):
        try:
            out.append(round(float((Time(t, format="isot", scale="utc") - Time(times[0], format="isot", scale="utc")).sec), 9))
        except ValueError:
            raise InputError(f"frame {i}: `time` must be an ISO 8601 UTC time (2026-03-04T05:06:07.5) or seconds, got {t!r} "
                             "(one kind for every frame).") from None
    return out


def scene_columns(cols: Mapping[str, list[Any]], n: int, other: Sequence[str] = (FILE, TIME, MASK)) -> list[dict[str, Any]]:
    """Per row, the scene values of a table's columns (those not in ``other`` nor ``sensor.FIELD``): scalar
    names as given, vector keys from one column of 3 or from their KEY.x, KEY.y, KEY.z columns."""
    names = [c for c in cols if c not in other and not c.startswith(SENSOR_PREFIX)]
    split: dict[str, dict[str, str]] = {}
    plain = []
    for name in names:
        key, _, comp = name.rpartition(".")
        if key in VECTOR_KEYS and comp in COMPONENTS:
            split.setdefault(key, {})[comp] = name
        else:
            plain.append(name)
    for key, parts in split.items():
        if set(parts) != set(COMPONENTS):
            missing = [f"{key}.{c}" for c in COMPONENTS if c not in parts]
            raise InputError(f"the table gives {', '.join(sorted(parts.values()))} but not {', '.join(missing)}: "
                             f"`{key}` needs all three components.")
        if key in plain:
            raise InputError(f"the table gives `{key}` both whole and by components; keep one.")
    rows = []
    for i in range(n):
        row = {name: cell(cols[name][i]) for name in plain}
        row.update({key: [cell(cols[parts[c]][i]) for c in COMPONENTS] for key, parts in split.items()})
        if "camera.attitude_deg" in row and "camera.look_at_m" not in row:
            row["camera.look_at_m"] = []  # an attitude given per frame poses the camera by attitude
        rows.append(row)
    return rows


