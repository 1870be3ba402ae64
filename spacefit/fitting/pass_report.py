"""A pass's fit frame by frame: each frame's own values, errors and goodness of fit against time, as a
table (a fit's ``frames.csv``) and a figure (``frames.png``). The pass itself is :mod:`spacefit.fitting.passes`."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import InputError, check_path
from spacefit.fitting.passes import Pass, elapsed_seconds
from spacefit.scene.names import Name

if TYPE_CHECKING:  # types only: matplotlib loads where a figure is drawn
    from spacefit.plotting import AxesArg, FigureArg


def frame_table(result: Any, frames: Pass | None = None, *, files: Sequence[str | Path] = (),
                times: Sequence[str] = (), entries: Sequence[int] | None = None) -> list[dict[str, Any]]:
    """Per frame of a pass's fit (:class:`FitResult`): its file, time and
    seconds since the first frame (from ``frames``, or ``files`` and ``times``), the goodness of
    fit of its own pixels (``chi2_dof``, NaN without a known noise, ``misfit``, ``render_noise``),
    and each per-frame parameter's value and standard error (``NAME``, ``NAME.stderr``: the name
    without ``@k``). ``entries``: the frames' observation indices in the fit (None: every observation
    of the fit is a frame, in order).

    Args:
        result: the pass's fit.
        frames: the :class:`Pass` (its files and times); or ``files`` and ``times``.
        entries: the frames' observation indices in the fit.

    Returns:
        One dict per frame.

    Example:
        Not run by the tests (an image fit takes minutes)::

            scene = sf.load_scene("lander.toml")
            observation = sf.PassObservation.read("pass/frames.csv", scene, per_frame=["target.attitude_x_deg"])
            result = sf.fit([observation], ["parts.legs.kd"])
            for row in sf.frame_table(result):
                print(row["frame"], row["chi2_dof"], row["target.attitude_x_deg"], row["target.attitude_x_deg.stderr"])
    """
    if frames is not None:
        files, times = frames.files, [f.time for f in frames.frames]
    entries = list(range(len(result.units))) if entries is None else list(entries)
    seconds = elapsed_seconds(times) if times else [math.nan] * len(entries)
    rows = []
    for i, k in enumerate(entries):
        row: dict[str, Any] = {"frame": i, "file": str(files[i]) if i < len(files) else "",
                               "time": times[i] if times else "", "time_s": seconds[i]}
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
    """The rows of :func:`frame_table` as CSV (a column per key; empty where a row has none; numbers
    as Python writes them, so that :func:`read_frame_table` reads them back exactly)."""

    keys = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)


# frames.csv's columns that are not numbers (:func:`frame_table`'s keys): text, whole numbers, flags.
TEXT_COLUMNS, INTEGER_COLUMNS, FLAG_COLUMNS = ("file", "time"), ("frame",), ("misfit",)


def read_frame_table(path: str | Path) -> list[dict[str, Any]]:
    """The rows of a fit's ``frames.csv`` (:func:`frame_table`'s, as the fit wrote them) back as
    :func:`frame_table` gives them: ``file`` and ``time`` text, ``frame`` an int, ``misfit`` a bool,
    the rest floats; a value a row did not have (empty) is left out of it. :func:`plot_frames` draws them.

    Raises:
        InputError: not a path, no such file, or a cell that is not what its column holds.

    Args:
        path: a ``frames.csv`` a pass's fit wrote.

    Returns:
        The rows, one dict per frame.

    Example:
        >>> import spacefit as sf
        >>> with open("frames.csv", "w") as f:
        ...     print("frame,file,time,time_s,chi2_dof,misfit,target.attitude_x_deg,target.attitude_x_deg.stderr", file=f)
        ...     print("0,frame0.exr,0,0,1.02,False,90.1,0.05", file=f)
        >>> row = sf.read_frame_table("frames.csv")[0]
        >>> row["frame"], row["misfit"], row["target.attitude_x_deg"]
        (0, False, 90.1)
    """
    path = check_path("path", path)
    if not path.is_file():
        raise InputError(f"`path` {str(path)!r}: no frame table there (a pass's fit writes frames.csv).")
    with open(path, newline="", encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    rows = []
    for line, cells in enumerate(table, start=2):  # line 1 is the header
        row: dict[str, Any] = {}
        for key, cell in cells.items():
            if key in TEXT_COLUMNS:
                row[key] = cell
            elif cell != "":
                row[key] = _cell(key, cell, f"{str(path)!r} line {line}")
        rows.append(row)
    return rows


def _cell(key: str, cell: str, where: str) -> int | bool | float:
    """A frames.csv cell of column ``key`` as :func:`frame_table` had it."""
    if key in FLAG_COLUMNS and cell in ("True", "False"):
        return cell == "True"
    try:
        if key in INTEGER_COLUMNS:
            return int(cell)
        if key not in FLAG_COLUMNS:
            return float(cell)
    except ValueError:
        pass
    what = "a whole number" if key in INTEGER_COLUMNS else "True or False" if key in FLAG_COLUMNS else "a number"
    raise InputError(f"{where}: {key} = {cell!r} is not {what}.")


def frame_panels(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The quantities :func:`plot_frames` draws of :func:`frame_table`'s ``rows``, one panel each: every
    per-frame parameter (a key with its ``.stderr``), then ``chi2_dof`` where a frame has a finite one
    (none without a known noise: chi^2 has no meaning there, and an empty panel is not drawn)."""
    own = [k for k in dict.fromkeys(key for row in rows for key in row) if any(f"{k}.stderr" in row for row in rows)]
    chi2 = np.array([row.get("chi2_dof", math.nan) for row in rows], dtype=float)
    return [*own, *(["chi2_dof"] if np.isfinite(chi2).any() else [])]


def plot_frames(rows: Sequence[Mapping[str, Any]], *, ax: AxesArg = None, fig: FigureArg = None) -> np.ndarray:
    """The per-frame parameters of :func:`frame_table`'s rows against time (one panel each, 1-sigma
    error bars) and each frame's chi^2 / dof, into ``ax`` (one Axes per panel) or ``fig`` (a
    matplotlib Figure or SubFigure; default a new one): the array of axes drawn. Without a known
    noise the frames have no chi^2 / dof and its panel is left out (the first panel's title says so).

    Args:
        rows: :func:`frame_table`'s rows (or :func:`read_frame_table`'s, of a saved frames.csv).
        ax: the axes to draw into, one per panel, or ``fig``: the Figure or SubFigure to lay them out in.

    Returns:
        The array of axes drawn.

    Raises:
        InputError: the rows have neither a per-frame parameter nor a chi^2 / dof: nothing to draw.

    Example:
        Not run by the tests (an image fit takes minutes)::

            scene = sf.load_scene("lander.toml")
            observation = sf.PassObservation.read("pass/frames.csv", scene, per_frame=["target.attitude_x_deg"])
            result = sf.fit([observation], ["parts.legs.kd"])
            axes = sf.plot_frames(sf.frame_table(result))
            axes.flat[0].figure.savefig("frames.png")
    """
    from spacefit.plotting import axis_label, panels  # deferred: plotting (0.5 s)

    names = frame_panels(rows)
    if not names:
        raise InputError("`rows` hold no per-frame parameter and no chi^2 / dof (the frames' noise is unknown): "
                         "plot_frames has nothing to draw.")
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
    if "chi2_dof" not in names:
        axes[0].set_title("no chi$^2$ / dof panel: the frames' noise is unknown", fontsize=8)
    axes[-1].set_xlabel("time since the first frame (s)" if known else "frame")
    return axes
