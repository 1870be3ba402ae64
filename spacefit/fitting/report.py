"""A fit's output folder: ``fit.json``, ``comparison.png`` and ``convergence.png``, and a text summary.

* ``fit.json``: :meth:`FitResult.to_dict` (values, standard errors, correlation, status and its name, warnings,
  goodness of fit, per-part chi^2, history) plus ``timings_s``, ``versions`` and, if given, the ``inputs``;
* ``fit.toml``: the fitted scene (:attr:`FitResult.scene`), which renders the fit again;
* ``uncertainty.json``: :meth:`FitResult.uncertainty`, values, standard errors, units and the
  correlation matrix (strict JSON: a non-finite error is null);
* ``comparison.png`` (a fit of images), ``convergence.png``: :func:`plot_comparison` and
  :func:`plot_convergence`, saved through matplotlib's Agg canvas;
* ``frames.csv``, ``frames.png`` (a pass: a :class:`PassObservation`,
  or images whose ``inputs`` give each one's time): per frame its time, goodness of fit and own
  parameters, and their plot against time (:mod:`spacefit.fitting.pass_report`; ``frames<i>`` for the
  i-th observation where a fit has several passes; no plot where a frame has neither own parameters nor a known noise);
* ``observation<i>.png``: the figure of the i-th observation of another kind (a table, a light curve),
  its :meth:`~spacefit.fitting.observations.base.Reported.plot`;
* ``residuals.fits`` (a fit of images): :attr:`FitResult.residuals`, reference - model, one image extension per
  observation (``EXTNAME`` ``OBS<k>``, (channels, height, width) float32 in the unit ``BUNIT`` of the
  observation, NaN where not fitted; rows stored top row first, ``ROWORDER = 'TOP-DOWN'``), drawn as
  ``comparison.png``'s third column (:func:`~spacefit.fitting.plots.residual_panel`).

:func:`read_fit` reads the folder back into its :class:`FitResult` (without
the renders). The summary's (:func:`format_result`) first line is the verdict, :class:`~spacefit.fitting.status.Status`;
the second the goodness of fit (:mod:`spacefit.fitting.goodness`).
"""

from __future__ import annotations

import json
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg

from astropy.io import fits

from spacefit.errors import InputTypeError, check_flag, check_name_list, check_path, check_type, quote
from spacefit.fitting.observations.image import Observation
from spacefit.fitting.observations.passes import PassObservation
from spacefit.fitting.result import FitResult
from spacefit.fitting.status import Status
from spacefit.fitting.pass_report import frame_panels, frame_table, plot_frames, write_frame_table
from spacefit.fitting.plots import plot_comparison, plot_convergence
from spacefit.locks import holding_lock
from spacefit.output import prepare_output, staged_output, versions, write_json
from spacefit.units import DN_UNIT

# The residual images' units as FITS BUNIT.
FITS_UNITS = {DN_UNIT: "adu"}
# The figures' resolution, dots per inch.
FIGURE_DPI = 110
# zlib's level for the figures' PNG files: 3 encodes an image fit's three figures in half the time of Pillow's
# default, 6 (0.07 s of CPU in place of 0.14 s, load 14), for files 12 % larger (552 KiB in place of 493 KiB); the
# same pixels (docs/measurements/performance.md).
PNG_COMPRESS_LEVEL = 3


def write_fit_report(
    out_dir: str | Path,
    result: FitResult,
    references: Sequence[np.ndarray],
    *,
    inputs: Mapping[str, Any] | None = None,
    timings_s: Mapping[str, float] | None = None,
    replaces: Collection[str] = (),
) -> Path:
    """Write fit.json, fit.toml, uncertainty.json, convergence.png and, with images, comparison.png
    and residuals.fits into ``out_dir`` all at once.

    Args:
        out_dir: output folder (created; on any error nothing is left behind).
        result: the fit's outcome.
        references: the reference images (h, w, 3), in observation order, in the units of the fit (``result.units``).
        inputs: what was fitted (reference files, scenes, options), recorded in fit.json.
        timings_s: timings (s) to record besides the solve's own ``result.wall_time_s``.
        replaces: names of a previous report's files in ``out_dir`` (``spacefit fit --overwrite`` passes those its
            previous result held): those this one does not write are removed once its own are in place.

    Returns:
        The folder's path.

    Raises:
        InputError: a folder that cannot be written (files of other names in it are kept, the
            report's own replaced).

    Example:
        Not run by the tests (an image fit takes minutes)::

            scene = sf.load_scene("lander.toml")
            observation = sf.PassObservation.read("pass/frames.csv", scene, per_frame=["target.attitude_x_deg"])
            result = sf.fit([observation], ["parts.legs.kd"])
            references = [sf.read_exr(frame.file) for frame in sf.Pass.read("pass/frames.csv").frames]
            sf.write_fit_report("fit-out", result, references)
    """
    data = {
        **result.to_dict(),
        "success": bool(result.success),  # the solver's flag can be a JAX boolean
        "timings_s": {"solve": result.wall_time_s, **(timings_s or {})},
        # the observations' units (radiance, or DN with a sensor) are those of ``parts`` and the renders
        "units": {"radiance": "W m^-2 sr^-1 per RGB channel", "lengths": "m", "observations": list(result.units)},
        "versions": versions(),
        **({"inputs": dict(inputs)} if inputs is not None else {}),
    }
    with staged_output(out_dir, replaces) as stage:
        write_json(stage / "fit.json", data)
        write_json(stage / "uncertainty.json", result.uncertainty())
        if result.scene is not None:
            (stage / "fit.toml").write_text(result.scene.to_toml(), encoding="utf-8")
        _save(plot_convergence(result), stage / "convergence.png")
        if any(isinstance(o, Observation) for o in result.observations):  # images' figures (an interrupted fit's too,
            # its residuals not computed); a table's or a light curve's is its observation<i>.png
            _save(plot_comparison(result, references), stage / "comparison.png")
            write_residuals(stage / "residuals.fits", result)
        passes = [i for i, o in enumerate(result.observations) if isinstance(o, PassObservation)]
        for i, (observation, entries) in enumerate(zip(result.observations, result.entries)):
            if i in passes:  # its frames against time
                own = "" if len(passes) == 1 else str(i)
                rows = frame_table(result, observation.frames, entries=entries)
                write_frame_table(stage / f"frames{own}.csv", rows)
                if frame_panels(rows):
                    _save(plot_frames(rows), stage / f"frames{own}.png")
            elif not isinstance(observation, Observation):  # an image's figure is comparison.png
                _save(observation.plot(result, entries), stage / f"observation{i}.png")
        if not passes and inputs is not None and inputs.get("times"):  # a pass given as its frames' images
            rows = frame_table(result, files=inputs["references"], times=inputs["times"])
            write_frame_table(stage / "frames.csv", rows)
            if frame_panels(rows):
                _save(plot_frames(rows), stage / "frames.png")
    return Path(out_dir)


def write_residuals(path: Path, result: FitResult) -> None:
    """The residual images, reference - model, as FITS: one extension per image ``OBSk``, k the
    observation's index (none without renders; a table's or a light curve's are drawn in observation<k>.png)."""
    hdus: list[fits.PrimaryHDU | fits.ImageHDU] = [fits.PrimaryHDU()]
    for k in result.images:
        residual = result.residuals[k]
        header = fits.Header()
        header["BUNIT"] = FITS_UNITS.get(result.units[k], "W m-2 sr-1")
        header["ROWORDER"] = ("TOP-DOWN", "the first row stored is the top of the image")
        header["COMMENT"] = "reference - model of the fit; NaN where not fitted"
        hdus.append(fits.ImageHDU(np.moveaxis(np.asarray(residual, dtype=np.float32), -1, 0), header, name=f"OBS{k}"))
    fits.HDUList(hdus).writeto(path)


def format_result(result: FitResult) -> str:
    """The verdict (first line), the goodness of fit, the fitted values with standard errors (marked
    where they are not valid: a misfit's are too small), each observation's own part
    (:meth:`Observation.report`: an image's chi^2 per part, a pass's
    frames, a table's or a light curve's goodness of fit), and the warnings, as lines of text.

    Args:
        result: the fit's result.

    Returns:
        The report, lines joined by newlines (what ``spacefit fit`` prints and report.txt holds).

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> text = sf.format_result(sf.fit_brdf_table(table, "lambert"))
        >>> text.splitlines()[0].startswith("converged")
        True
    """
    check_type("result", result, FitResult, "an sf.FitResult (what sf.fit returns)")
    derived = [name for name in result.extras if f"{name}.stderr" in result.extras]  # e.g. wrinkles.rms_m
    width = max(len(name) for name in (*result.names, *derived))
    lines = [result.headline]
    if result.goodness is not None:
        lines.append(result.goodness.line())
    mark = f"  [{result.stderr_note}]" if result.status is Status.MISFIT else ""
    for heading, group in (("", result.estimates), ("nuisance parameters:", result.nuisances)):
        if heading and group:
            lines.append(f"  {heading}")
        for name in group:
            value, stderr, start = result.values[name], result.stderr[name], result.start[name]
            lines.append(f"  {name:<{width}} = {value:.6g} +/- {stderr:.3g}  (start {start:.6g}){mark}")
    for name in derived:
        value, stderr = result.extras[name], result.extras[f"{name}.stderr"]
        lines.append(f"  {name:<{width}} = {value:.6g} +/- {stderr:.3g}  (derived)")
    for observation, entries in zip(result.observations, result.entries):  # each observation's own part
        lines += observation.report(result, entries)
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


@holding_lock("out_dir")
def write_table_fit(out_dir: str | Path, fit: FitResult, *, inputs: Mapping[str, Any] | None = None, overwrite: bool = False) -> Path:
    """Write the folder of a fit of value observations alone (a BRDF table, a light curve): ``fit.json``
    (:meth:`FitResult.to_dict`, the package versions and, if given, the ``inputs``: names and JSON
    values) and ``report.txt`` (:func:`format_result`) into ``out_dir`` all at once (on an error
    nothing is left behind). The folder must be new or empty, or hold an earlier table fit and
    ``overwrite`` be given ; it is written holding its lock
    (one writer per folder).

    Args:
        out_dir: the folder.
        fit: the :class:`FitResult`.
        inputs: what was fitted, by name (JSON values).
        overwrite: replace an earlier table fit in ``out_dir``.

    Returns:
        The folder's path.

    Raises:
        InputError: a folder that holds other files, or an earlier fit without ``overwrite``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> folder = sf.write_table_fit("paint-fit", sf.fit_brdf_table(table, "lambert"))
        >>> sorted(p.name for p in folder.iterdir())
        ['fit.json', 'report.txt']
    """
    check_type("fit", fit, FitResult, "an sf.FitResult")
    check_type("inputs", inputs, (Mapping, type(None)), "a dict of names and JSON values, or None")
    check_name_list("inputs", list(inputs or {}))
    try:
        json.dumps(dict(inputs or {}), allow_nan=False)
    except (TypeError, ValueError, RecursionError) as err:
        raise InputTypeError(f"`inputs` must hold JSON values (strings, finite numbers, lists, dicts): {err}; got {quote(inputs)}.") from None
    prepare_output(check_path("out_dir", out_dir), "table-fit", overwrite=check_flag("overwrite", overwrite))
    with staged_output(out_dir) as stage:
        write_json(stage / "fit.json", {**fit.to_dict(), "versions": versions(), **({"inputs": dict(inputs)} if inputs else {})})
        (stage / "report.txt").write_text(format_result(fit) + "\n", encoding="utf-8")
    return Path(out_dir)


def _save(axes: np.ndarray, path: Path) -> None:
    """Save the figure of a figure function's axes as PNG through its Agg canvas, laid out and drawn
    once: ``savefig`` draws a figure with a layout engine twice, the first time to lay it out (half of
    a report's figure time, which the fit process pays in full; docs/measurements/performance.md)."""
    fig = axes.flat[0].figure
    fig.dpi = FIGURE_DPI
    FigureCanvasAgg(fig).print_png(path, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
