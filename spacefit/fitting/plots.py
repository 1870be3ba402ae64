"""A fit's plots, public as ``sf.plot_comparison`` and ``sf.plot_convergence``.

Each returns a matplotlib :class:`~matplotlib.figure.Figure` made without pyplot, so the global
backend (a notebook's) is left alone: show it in a notebook by evaluating it, or save it with
``fig.savefig(path)``. matplotlib is imported with this module, which ``import spacefit`` loads
only on first use of these names.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from spacefit.fitting.loop import FitResult
from spacefit.output import PREVIEW_PERCENTILE, preview_scale, to_srgb8
from spacefit.sensor import DN_UNIT, RADIANCE_UNIT

# The image units as axis labels.
PLOT_UNITS = {RADIANCE_UNIT: "W m$^{-2}$ sr$^{-1}$", DN_UNIT: "DN"}


def plot_comparison(result: FitResult, references: Sequence[np.ndarray]) -> Figure:
    """Reference | fit | residual fit - reference, one row per observation.

    Args:
        result: the fit's outcome (its renders; missing where the solve failed).
        references: the reference images (h, w, 3), in observation order, each in the unit of the
            fit's model image (``result.units``: radiance, or DN for an observation with a sensor).
    Returns:
        a matplotlib Figure (not attached to pyplot): the fit at the reference's sRGB exposure, the
        residual's RGB mean in that unit on a diverging colour map centred at 0.
    """
    n = len(references)
    fig = Figure(figsize=(10.5, 3.2 * n), layout="constrained")
    axes = fig.subplots(n, 3, squeeze=False)
    for i, (row, reference) in enumerate(zip(axes, references)):
        ref = _rgb(reference)
        unit = PLOT_UNITS[result.units[i] if i < len(result.units) else RADIANCE_UNIT]
        scale = preview_scale(ref)
        row[0].imshow(to_srgb8(ref, scale))
        row[0].set_title(f"reference {i} (white = {1 / scale:.3g} {unit})", fontsize=9)
        if i < len(result.renders):
            render = _rgb(result.renders[i])
            row[1].imshow(to_srgb8(render, scale))
            row[1].set_title(f"fit {i} (same exposure)", fontsize=9)
            residual = (render - ref).mean(axis=-1)
            limit = float(np.percentile(np.abs(residual), PREVIEW_PERCENTILE)) or float(np.abs(residual).max()) or 1.0
            image = row[2].imshow(residual, cmap="RdBu_r", vmin=-limit, vmax=limit)
            row[2].set_title(f"fit - reference {i}", fontsize=9)
            fig.colorbar(image, ax=row[2], extend="both", label=unit)
        else:
            for ax in row[1:]:
                ax.text(0.5, 0.5, "no render: the solve failed", ha="center", va="center", transform=ax.transAxes)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(f"{result.solver}, {result.loss_name} loss: {result.status}", fontsize=10)
    return fig


def plot_residuals(result: FitResult) -> Figure:
    """Each observation's residual, reference - model (:attr:`FitResult.residuals`), the channels'
    mean in the observation's unit on a diverging colour map centred at 0 (grey where not fitted).

    Returns:
        a matplotlib Figure (not attached to pyplot); one that says so where the fit has no residuals.
    """
    n = max(len(result.residuals), 1)
    fig = Figure(figsize=(4.0 * n, 3.6), layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    for k, (ax, residual) in enumerate(zip(axes, result.residuals)):
        mean = np.asarray(residual, dtype=float).mean(axis=-1)
        limit = float(np.nanpercentile(np.abs(mean), PREVIEW_PERCENTILE)) if np.isfinite(mean).any() else 0.0
        limit = limit or float(np.nanmax(np.abs(mean), initial=0.0)) or 1.0
        cmap = colormaps["RdBu_r"].with_extremes(bad="0.6")
        image = ax.imshow(np.ma.masked_invalid(mean), cmap=cmap, vmin=-limit, vmax=limit)
        ax.set_title(f"reference - fit, observation {k}", fontsize=9)
        fig.colorbar(image, ax=ax, extend="both", label=PLOT_UNITS[result.units[k] if k < len(result.units) else RADIANCE_UNIT])
        ax.set_xticks([])
        ax.set_yticks([])
    if not result.residuals:
        axes[0].text(0.5, 0.5, "no residuals: the fit has no render", ha="center", va="center", transform=axes[0].transAxes)
    fig.suptitle(f"{result.status}", fontsize=9)
    return fig


def _rgb(image: np.ndarray) -> np.ndarray:
    """An (h, w) or (h, w, c) image as (h, w, 3) float32 for display (a grey image in all three;
    values that are not finite, which a mask may have left out of the fit, shown as 0)."""
    image = np.nan_to_num(np.asarray(image, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    image = image[..., None] if image.ndim == 2 else image
    return np.repeat(image, 3, axis=-1) if image.shape[-1] == 1 else image[..., :3]


def plot_convergence(result: FitResult) -> Figure:
    """The loss per step (log axis; accepted steps joined, rejected trials as crosses, the loss's
    Monte Carlo noise as a band above the best loss) and each parameter per step divided by its
    fitted value.

    Returns:
        a matplotlib Figure (not attached to pyplot).
    """
    fig = Figure(figsize=(10.0, 3.6), layout="constrained")
    ax_loss, ax_values = fig.subplots(1, 2)
    history = result.history
    steps = np.array([h["step"] for h in history])
    losses = np.array([h["loss"] for h in history], dtype=float)
    accepted = np.array([h.get("accepted", True) for h in history], dtype=bool)
    ax_loss.semilogy(steps[accepted], losses[accepted], "o-", ms=3, label="accepted")
    if (~accepted).any():
        ax_loss.semilogy(steps[~accepted], losses[~accepted], "x", color="C3", ms=5, label="rejected")
    noise = np.array([h.get("loss_noise", np.nan) for h in history], dtype=float)
    if np.isfinite(noise).any():
        best = np.minimum.accumulate(np.where(np.isfinite(losses), losses, np.inf))
        ax_loss.fill_between(steps, best, best + noise, color="0.6", alpha=0.4, step="post", label="Monte Carlo noise")
    ax_loss.set_xlabel("step")
    ax_loss.set_ylabel("loss 0.5 sum r$^2$")
    ax_loss.set_title(f"{result.solver}, {result.loss_name} loss: {result.status.name.lower()}", fontsize=9)
    ax_loss.legend(fontsize=8)
    for name in result.names:
        final = result.values[name]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.array([h["values"][name] for h in history]) / final
        ax_values.plot(steps, ratio, "o-", ms=3, label=f"{name} (fit {final:.4g})")
    ax_values.axhline(1.0, color="0.5", lw=0.8)
    ax_values.set_xlabel("step")
    ax_values.set_ylabel("value / fitted value")
    ax_values.legend(fontsize=8)
    for ax in (ax_loss, ax_values):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    return fig
