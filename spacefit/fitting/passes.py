"""A pass: the frames a telescope records of one target as it follows it, each with its own time,
sun, observer and nominal target attitude, read from a table and fitted jointly.

A frame table has one row per frame (CSV, ECSV or a FITS table, read by ``astropy.table``; or
Python columns). Its columns, in the scene's own vocabulary and units (degrees at this edge):

- ``file``: the frame's observation (any image :meth:`Observation.from_file
  <spacefit.fitting.problem.Observation.from_file>` reads), relative to the table's folder;
- ``time``: an ISO 8601 UTC time (``2026-03-04T05:06:07.5``) or seconds (any origin);
- any scene value by name, as ``--set`` takes it: a scene-file key or a parameter name
  (``sun.elevation_deg``, ``sun.azimuth_deg``, ``target.attitude_x_deg``, ``camera.roll_deg``); a
  vector key (``camera.position_m``, ``camera.look_at_m``, ``camera.attitude_deg``, ``camera.up``,
  ``sun.direction``, ``target.attitude_deg``, ``target.position_m``) as one column of 3 numbers
  per row (ECSV, FITS) or as three columns ``KEY.x``, ``KEY.y``, ``KEY.z`` (any table). A frame that
  gives the camera's ``attitude_deg`` and no ``look_at_m`` is posed by attitude;
- ``sensor.FIELD``: a per-frame :class:`~spacefit.sensor.Sensor` value (``sensor.exposure_time_s``);
- ``mask``: a per-frame mask image (optional).

Each frame's scene is the pass's scene with the frame's values set (:meth:`Pass.scenes`). A joint
fit frees the materials once and, per frame, the nuisances the user names
(:meth:`Pass.per_frame`: ``target.attitude_x_deg`` -> ``target.attitude_x_deg@k`` for each frame
k); :func:`frame_table` and :func:`plot_frames` give the per-frame values and goodness of fit
against time (a fit's report writes them as ``frames.csv`` and ``frames.png``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_count, quote
from spacefit.scene.names import Name
from spacefit.scene.parameters import PER_OBSERVATION
from spacefit.scene.schema import Scene

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
        sensor: the frame's own sensor values (:class:`~spacefit.sensor.Sensor` fields).
        mask: a mask image of the frame, or None.
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
    checked against a scene by :meth:`scenes`."""

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

        path = Path(path)
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
                neither ISO 8601 nor a number, a component column without its siblings.
        """
        names = list(columns.colnames if hasattr(columns, "colnames") else columns)
        for name in names:
            if not isinstance(name, str):
                raise InputTypeError(f"frame table column names must be strings, got {quote(name)}.")
        for required in (FILE, TIME):
            if required not in names:
                raise InputError(f"the frame table has no `{required}` column (columns: {', '.join(names) or 'none'}); "
                                 "every frame needs its observation file and its time.")
        cols = {name: _column(columns[name]) for name in names}
        lengths = {name: len(col) for name, col in cols.items()}
        n = lengths[FILE]
        if any(length != n for length in lengths.values()):
            raise InputError(f"the frame table's columns must have one value per frame, got lengths {lengths}.")
        times = [_time_text(cols[TIME][i], i) for i in range(n)]
        seconds = _seconds(times)
        base = Path(base_dir)
        values = _scene_columns(cols, n)
        frames = []
        for i in range(n):
            sensor = {name[len(SENSOR_PREFIX):]: _plain(cols[name][i]) for name in cols if name.startswith(SENSOR_PREFIX)}
            mask = base / str(_plain(cols[MASK][i])).strip() if MASK in cols else None
            frames.append(Frame(base / str(_plain(cols[FILE][i])).strip(), times[i], seconds[i], values[i], sensor, mask))
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
        """The frames as :class:`~spacefit.fitting.observation_files.ObservationFiles` for
        :func:`~spacefit.pipeline.fit_to_folder`: one scene file for all, each frame's values,
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


def _column(values: Any) -> list[Any]:
    """A column as a list of per-frame values (a vector column: per-frame lists of 3)."""
    if hasattr(values, "isot"):  # an astropy Time column (ECSV)
        return list(values.isot)
    if np.any(np.ma.getmaskarray(values)):
        raise InputError("the frame table has empty cells; give every frame every column's value.")
    array = np.asarray(values)
    if array.ndim == 0:
        raise InputError(f"a frame table column must hold one value per frame, got {quote(values)}.")
    return [v.tolist() if isinstance(v, np.ndarray) else v for v in array]


def _plain(value: Any) -> Any:
    """A table cell as a plain Python value."""
    if isinstance(value, bytes):
        return value.decode()
    return value.item() if isinstance(value, np.generic) else value


def _time_text(value: Any, row: int) -> str:
    value = _plain(value)
    if isinstance(value, bool):
        raise InputTypeError(f"frame {row}: `time` must be an ISO 8601 UTC time or seconds, got {value!r}.")
    return repr(float(value)) if isinstance(value, (int, float)) else str(value).strip()


def _seconds(times: Sequence[str]) -> list[float]:
    """Seconds since the first frame of ISO 8601 UTC times, or of numbers of seconds (all one kind)."""
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
            out.append(float((Time(t, format="isot", scale="utc") - Time(times[0], format="isot", scale="utc")).sec))
        except ValueError:
            raise InputError(f"frame {i}: `time` must be an ISO 8601 UTC time (2026-03-04T05:06:07.5) or seconds, got {t!r} "
                             "(one kind for every frame).") from None
    return out


def _scene_columns(cols: Mapping[str, list[Any]], n: int) -> list[dict[str, Any]]:
    """Per frame, the scene values of the table's columns: scalar names as given, vector keys from one
    column of 3 or from their KEY.x, KEY.y, KEY.z columns."""
    names = [c for c in cols if c not in (FILE, TIME, MASK) and not c.startswith(SENSOR_PREFIX)]
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
            raise InputError(f"the frame table gives {', '.join(sorted(parts.values()))} but not {', '.join(missing)}: "
                             f"`{key}` needs all three components.")
        if key in plain:
            raise InputError(f"the frame table gives `{key}` both whole and by components; keep one.")
    rows = []
    for i in range(n):
        row = {name: _plain(cols[name][i]) for name in plain}
        row.update({key: [_plain(cols[parts[c]][i]) for c in COMPONENTS] for key, parts in split.items()})
        if "camera.attitude_deg" in row and "camera.look_at_m" not in row:
            row["camera.look_at_m"] = []  # an attitude given per frame poses the camera by attitude
        rows.append(row)
    return rows


def frame_table(result: Any, frames: Pass | None = None, *, files: Sequence[str | Path] = (),
                times: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Per frame of a pass's fit (:class:`~spacefit.fitting.loop.FitResult`): its file, time and
    seconds since the first frame (from ``frames``, or ``files`` and ``times``), the goodness of
    fit of its own pixels (``chi2_dof``, NaN without a known noise, ``misfit``, ``render_noise``),
    and each per-frame parameter's value and standard error (``NAME``, ``NAME.stderr``: the name
    without ``@k``)."""
    if frames is not None:
        files, times = frames.files, [f.time for f in frames.frames]
    seconds = _seconds(times) if times else [math.nan] * len(result.units)
    rows = []
    for k in range(len(result.units)):
        row: dict[str, Any] = {"frame": k, "file": str(files[k]) if k < len(files) else "",
                               "time": times[k] if times else "", "time_s": seconds[k]}
        if k < len(result.observation_goodness):
            quality = result.observation_goodness[k]
            row.update({"chi2_dof": quality.chi2_dof, "misfit": quality.misfit, "render_noise": quality.render_noise})
        for name in result.names:
            ref = Name(name)
            if ref.observation == k:
                row[ref.parameter] = result.values[name]
                row[f"{ref.parameter}.stderr"] = result.stderr[name]
        rows.append(row)
    return rows


def write_frame_table(path: str | Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """The rows of :func:`frame_table` as CSV (a column per key; empty where a row has none)."""
    import csv

    keys = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)


def plot_frames(rows: Sequence[Mapping[str, Any]], *, ax: Any = None, fig: Any = None) -> Any:
    """The per-frame parameters of :func:`frame_table`'s rows against time (one panel each, 1-sigma
    error bars) and each frame's chi^2 / dof, into ``ax`` (one Axes per panel) or ``fig`` (a
    matplotlib Figure or SubFigure; default a new one): the array of axes drawn (:mod:`spacefit.plotting`)."""
    from spacefit.plotting import axis_label, panels  # deferred: plotting (0.5 s)

    own = [k for k in dict.fromkeys(key for row in rows for key in row) if f"{k}.stderr" in rows[0]]
    names = [*own, "chi2_dof"]
    axes = panels(ax, fig, len(names), (6.0, 1.6 * len(names) + 0.6), lambda f: f.subplots(len(names), 1, sharex=True, squeeze=False))
    t = np.array([r["time_s"] for r in rows], dtype=float)
    known = np.all(np.isfinite(t))
    t = t if known else np.arange(len(rows), dtype=float)
    for panel, name in zip(axes, names):
        y = np.array([r.get(name, np.nan) for r in rows], dtype=float)
        err = np.array([r.get(f"{name}.stderr", np.nan) for r in rows], dtype=float)
        panel.errorbar(t, y, yerr=np.where(np.isfinite(err), err, 0.0), fmt="o", ms=3, capsize=2)
        panel.set_ylabel(axis_label(name) if name != "chi2_dof" else "chi$^2$ / dof", fontsize=7)
        panel.grid(alpha=0.3)
    axes[-1].set_xlabel("time since the first frame (s)" if known else "frame")
    return axes


def arc_pass(n: int, *, range_m: float = 25.0, zenith_deg: tuple[float, float] = (4.0, 16.0),
             azimuth_deg: tuple[float, float] = (0.0, 40.0), sun_elevation_deg: tuple[float, float] = (82.0, 78.0),
             sun_azimuth_deg: float = 200.0) -> list[dict[str, Any]]:
    """The scene values of ``n`` frames of a synthetic pass: an observer at ``range_m`` from the
    origin, looking at it, moving evenly from (zenith angle, azimuth) = (``zenith_deg[0]``,
    ``azimuth_deg[0]``) to the second values, and the sun's elevation changing evenly between
    ``sun_elevation_deg``'s (azimuth fixed). By default the observer crosses the panels' glint
    (the sun's mirror direction, 10 deg from the zenith at azimuth 20 deg) half-way. Each frame: ``camera.position_m``, ``camera.look_at_m``
    (the origin), ``sun.elevation_deg``, ``sun.azimuth_deg``."""
    check_count("n", n)
    out = []
    for s in np.linspace(0.0, 1.0, n) if n > 1 else [0.0]:
        theta = math.radians(zenith_deg[0] + s * (zenith_deg[1] - zenith_deg[0]))
        phi = math.radians(azimuth_deg[0] + s * (azimuth_deg[1] - azimuth_deg[0]))
        position = [range_m * math.sin(theta) * math.cos(phi), range_m * math.sin(theta) * math.sin(phi), range_m * math.cos(theta)]
        out.append({"camera.position_m": [round(v, 9) for v in position], "camera.look_at_m": [0.0, 0.0, 0.0],
                    "sun.elevation_deg": round(sun_elevation_deg[0] + s * (sun_elevation_deg[1] - sun_elevation_deg[0]), 9),
                    "sun.azimuth_deg": sun_azimuth_deg})
    return out


def simulate_pass(scene: Scene, frames: Sequence[Mapping[str, Any]], out_dir: str | Path, *,
                  truth: Mapping[str, Any] | None = None, errors: Sequence[Mapping[str, float]] = (),
                  sensor: Any = None, spp: int = 256, seed: int = 7, interval_s: float = 10.0) -> Pass:
    """Simulate a pass and write it: per frame k an observation ``frame<k>.fits`` (DN through
    ``sensor``'s model, :func:`~spacefit.formation.observe`, the sensor in its header and
    sidecar) or, without a sensor, ``frame<k>.exr`` (radiance), rendered at ``spp`` from ``scene``
    with ``frames[k]``'s values (the FITS card or EXR attribute ``RENDSPP`` says ``spp``), ``truth`` (every frame) and ``errors[k]`` (the frame's own
    departures from its nominal values, e.g. ``{"target.attitude_x_deg": 0.2}``, added to the
    nominal); and ``frames.csv``, the frame table of the nominal values (without the errors), times
    ``interval_s`` apart. Returns the pass read back from that table.

    Raises:
        InputError: a value refused by the scene, ``errors`` not one per frame, an existing ``out_dir``.
    """
    # here: simulating renders (Mitsuba) and forms images (JAX); reading or plotting a pass needs neither
    from astropy.table import Table
    from spacefit.formation import observe
    from spacefit.imageio import RENDER_SPP_KEY, write_observation
    from spacefit.rendering.exr import write_exr
    from spacefit.rendering.renderer import render
    from spacefit.scene.assembly import assemble
    from spacefit.scene.parameters import scene_value

    errors = list(errors) or [{}] * len(frames)
    if len(errors) != len(frames):
        raise InputError(f"`errors` must give one mapping per frame ({len(frames)}), got {len(errors)}.")
    out = Path(out_dir)
    if out.exists():
        raise InputError(f"`out_dir` {str(out)!r} exists; simulate_pass writes a new folder.")
    nominal = [scene.with_values({**dict(truth or {}), **dict(f)}) for f in frames]
    true = [s.with_values({name: scene_value(s, name) + dx for name, dx in e.items()}) for s, e in zip(nominal, errors)]
    out.mkdir(parents=True)
    columns: dict[str, list[Any]] = {"file": [], "time": []}
    for k, s in enumerate(true):
        radiance = render(s.with_values({"render.spp": spp, "render.seed": seed + k}))
        if sensor is None:
            name = f"frame{k}.exr"
            write_exr(out / name, radiance, header={RENDER_SPP_KEY: spp})
        else:
            name = f"frame{k}.fits"
            write_observation(out / name, observe(radiance, sensor, assemble(s).intrinsics, seed=seed + k), sensor, render_spp=spp)
        columns["file"].append(name)
        columns["time"].append(k * interval_s)
    keys = list(dict.fromkeys(key for f in frames for key in f))
    for key in keys:
        cells = [f[key] for f in frames]
        if key in VECTOR_KEYS:
            for c, axis in enumerate(COMPONENTS):
                columns[f"{key}.{axis}"] = [float(v[c]) for v in cells]
        else:
            columns[key] = cells
    Table(columns).write(out / "frames.csv")
    return Pass.read(out / "frames.csv")
