"""A fit's output folder: ``fit.json``, ``comparison.png`` and ``convergence.png``, and a text summary.

* ``fit.json``: :meth:`FitResult.to_dict` (values, standard errors, correlation, status, warnings,
  history) plus ``timings_s``, ``versions`` and, if given, the ``inputs``;
* ``comparison.png``: one row per observation: the reference, the fit's render at the same sRGB
  exposure (the reference's :func:`~spacefit.output.preview_scale`), and the residual fit - reference
  (mean of the RGB channels, W m^-2 sr^-1) on a diverging colour map centred at 0;
* ``convergence.png``: the loss per step (log axis) and each parameter's value per step divided by
  its fitted value.

Plots are drawn on matplotlib's Agg canvas without pyplot, so the global backend (a notebook's) is
left alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from spacefit.fitting.loop import FitResult
from spacefit.output import PREVIEW_PERCENTILE, preview_scale, staged_output, to_srgb8, versions, write_json

RADIANCE_UNIT = "W m$^{-2}$ sr$^{-1}$"


def write_fit_report(
    out_dir: str | Path,
    result: FitResult,
    references: Sequence[np.ndarray],
    *,
    inputs: Mapping[str, Any] | None = None,
    timings_s: Mapping[str, float] | None = None,
) -> Path:
    """Write fit.json, comparison.png and convergence.png into ``out_dir`` all at once.

    Args:
        out_dir: output folder (created; on any error nothing is left behind).
        result: the fit's outcome.
        references: the reference radiance images (h, w, 3), W m^-2 sr^-1, in observation order.
        inputs: what was fitted (reference files, scenes, options), recorded in fit.json.
        timings_s: timings (s) to record besides the solve's own ``result.wall_time_s``.
    """
    data = {
        **result.to_dict(),
        "success": bool(result.success),  # the solver's flag can be a JAX boolean
        "timings_s": {"solve": result.wall_time_s, **(timings_s or {})},
        "units": {"radiance": "W m^-2 sr^-1 per RGB channel", "lengths": "m"},
        "versions": versions(),
        **({"inputs": dict(inputs)} if inputs is not None else {}),
    }
    with staged_output(out_dir) as stage:
        write_json(stage / "fit.json", data)
        _save(_comparison(result, references), stage / "comparison.png")
        _save(_convergence(result), stage / "convergence.png")
    return Path(out_dir)


def format_result(result: FitResult) -> str:
    """The fitted values with standard errors, the status and the warnings, as lines of text."""
    derived = [name for name in result.extras if f"{name}.stderr" in result.extras]  # e.g. wrinkles.rms_m
    width = max(len(name) for name in (*result.names, *derived))
    lines = [
        f"{result.solver} on the {result.loss_name} loss: {result.status} after {result.steps} steps "
        f"({result.wall_time_s:.1f} s), loss {result.loss:.4g}"
    ]
    for name in result.names:
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


def _comparison(result: FitResult, references: Sequence[np.ndarray]) -> Figure:
    """Reference | fit | residual, one row per observation; the fit's render is missing if the solve failed."""
    n = len(references)
    fig = Figure(figsize=(10.5, 3.2 * n), layout="constrained")
    axes = fig.subplots(n, 3, squeeze=False)
    for i, (row, reference) in enumerate(zip(axes, references)):
        ref = np.asarray(reference, dtype=np.float32)[..., :3]
        scale = preview_scale(ref)
        row[0].imshow(to_srgb8(ref, scale))
        row[0].set_title(f"reference {i} (white = {1 / scale:.3g} {RADIANCE_UNIT})", fontsize=9)
        if i < len(result.renders):
            render = np.asarray(result.renders[i], dtype=np.float32)
            row[1].imshow(to_srgb8(render, scale))
            row[1].set_title(f"fit {i} (same exposure)", fontsize=9)
            residual = (render - ref).mean(axis=-1)
            limit = float(np.percentile(np.abs(residual), PREVIEW_PERCENTILE)) or float(np.abs(residual).max()) or 1.0
            image = row[2].imshow(residual, cmap="RdBu_r", vmin=-limit, vmax=limit)
            row[2].set_title(f"fit - reference {i}", fontsize=9)
            fig.colorbar(image, ax=row[2], extend="both", label=RADIANCE_UNIT)
        else:
            for ax in row[1:]:
                ax.text(0.5, 0.5, "no render: the solve failed", ha="center", va="center", transform=ax.transAxes)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(f"{result.solver}, {result.loss_name} loss: {result.status}", fontsize=10)
    return fig


def _convergence(result: FitResult) -> Figure:
    """Loss per step (log) and each parameter per step relative to its fitted value."""
    fig = Figure(figsize=(10.0, 3.6), layout="constrained")
    ax_loss, ax_values = fig.subplots(1, 2)
    steps = [h["step"] for h in result.history]
    ax_loss.semilogy(steps, [h["loss"] for h in result.history], "o-", ms=3)
    ax_loss.set_xlabel("step")
    ax_loss.set_ylabel("loss 0.5 sum r$^2$")
    ax_loss.set_title(f"{result.solver}, {result.loss_name} loss", fontsize=9)
    for name in result.names:
        final = result.values[name]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.array([h["values"][name] for h in result.history]) / final
        ax_values.plot(steps, ratio, "o-", ms=3, label=f"{name} (fit {final:.4g})")
    ax_values.axhline(1.0, color="0.5", lw=0.8)
    ax_values.set_xlabel("step")
    ax_values.set_ylabel("value / fitted value")
    ax_values.legend(fontsize=8)
    for ax in (ax_loss, ax_values):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    return fig
