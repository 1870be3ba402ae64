"""A fit's output folder: ``fit.json``, ``comparison.png`` and ``convergence.png``, and a text summary.

* ``fit.json``: :meth:`FitResult.to_dict` (values, standard errors, correlation, status, warnings,
  history) plus ``timings_s``, ``versions`` and, if given, the ``inputs``;
* ``fit.toml``: the fitted scene (:attr:`FitResult.scene`), which renders the fit again;
* ``uncertainty.json``: :meth:`FitResult.uncertainty`, values, standard errors, units and the
  correlation matrix (strict JSON: a non-finite error is null);
* ``comparison.png``, ``convergence.png``: :func:`~spacefit.fitting.plots.plot_comparison` and
  :func:`~spacefit.fitting.plots.plot_convergence`, saved through matplotlib's Agg canvas.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from spacefit.fitting.loop import FitResult
from spacefit.fitting.plots import plot_comparison, plot_convergence
from spacefit.output import staged_output, versions, write_json


def write_fit_report(
    out_dir: str | Path,
    result: FitResult,
    references: Sequence[np.ndarray],
    *,
    inputs: Mapping[str, Any] | None = None,
    timings_s: Mapping[str, float] | None = None,
) -> Path:
    """Write fit.json, fit.toml, uncertainty.json, comparison.png and convergence.png into ``out_dir`` all at once.

    Args:
        out_dir: output folder (created; on any error nothing is left behind).
        result: the fit's outcome.
        references: the reference images (h, w, 3), in observation order, in the units of the fit (``result.units``).
        inputs: what was fitted (reference files, scenes, options), recorded in fit.json.
        timings_s: timings (s) to record besides the solve's own ``result.wall_time_s``.
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
    with staged_output(out_dir) as stage:
        write_json(stage / "fit.json", data)
        write_json(stage / "uncertainty.json", result.uncertainty())
        if result.scene is not None:
            (stage / "fit.toml").write_text(result.scene.to_toml(), encoding="utf-8")
        _save(plot_comparison(result, references), stage / "comparison.png")
        _save(plot_convergence(result), stage / "convergence.png")
    return Path(out_dir)


def format_result(result: FitResult) -> str:
    """The fitted values with standard errors, the status and the warnings, as lines of text."""
    derived = [name for name in result.extras if f"{name}.stderr" in result.extras]  # e.g. wrinkles.rms_m
    width = max(len(name) for name in (*result.names, *derived))
    lines = [
        f"{result.solver} on the {result.loss_name} loss: {result.status} after {result.steps} steps "
        f"({result.wall_time_s:.1f} s), loss {result.loss:.4g}"
    ]
    for heading, group in (("", result.estimates), ("nuisance parameters:", result.nuisances)):
        if heading and group:
            lines.append(f"  {heading}")
        for name in group:
            value, stderr, start = result.values[name], result.stderr[name], result.start[name]
            lines.append(f"  {name:<{width}} = {value:.6g} +/- {stderr:.3g}  (start {start:.6g})")
    for name in derived:
        value, stderr = result.extras[name], result.extras[f"{name}.stderr"]
        lines.append(f"  {name:<{width}} = {value:.6g} +/- {stderr:.3g}  (derived)")
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def _save(fig: Figure, path: Path) -> None:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
