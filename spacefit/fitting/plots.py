"""A fit's plots, public as ``sf.plot_comparison`` and ``sf.plot_convergence``.

Each takes ``fig=`` (a matplotlib Figure or SubFigure to draw into) and returns the axes it drew
(:mod:`spacefit.plotting`: without ``fig`` it makes a Figure without pyplot, saved with
``axes.flat[0].figure.savefig(path)``). Images are cropped to the target and a margin unless
``crop=False``. matplotlib is imported with this module, which ``import spacefit`` loads only on
first use of these names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure, SubFigure
from matplotlib.ticker import MaxNLocator

from spacefit.errors import check_choice, check_range
from spacefit.fitting.loop import FitResult
from spacefit.output import PREVIEW_PERCENTILE, preview_scale, to_srgb8
from spacefit.plotting import axis_label, cropped, image_box, new_figure, show_image, unit_label
from spacefit.sensor import RADIANCE_UNIT


def plot_comparison(result: FitResult, references: Sequence[np.ndarray], *, fig: Figure | SubFigure | None = None,
                    crop: bool = True) -> np.ndarray:
    """Reference | fit | residual fit - reference, one row per observation.

    Args:
        result: the fit's outcome (its renders; missing where the solve failed).
        references: the reference images (h, w, 3), in observation order, each in the unit of the
            fit's model image (``result.units``: radiance, or DN for an observation with a sensor).
        fig: the matplotlib Figure or SubFigure to draw into (default: a new one).
        crop: show the target and a margin (found in the fit's render, else the reference); False:
            the whole film.
    Returns:
        the (observations, 3) array of axes drawn: the fit at the reference's sRGB exposure, the
        residual's RGB mean in that unit on a diverging colour map centred at 0.
    """
    n = len(references)
    fig = new_figure(fig, (10.5, 3.2 * n))
    axes = fig.subplots(n, 3, squeeze=False)
    for i, (row, reference) in enumerate(zip(axes, references)):
        ref = _rgb(reference)
        unit = unit_label(_unit(result, i))
        box = image_box([result.renders[i] if i < len(result.renders) else ref], crop)
        scale = preview_scale(cropped(ref, box))
        show_image(row[0], to_srgb8(ref, scale), box)
        row[0].set_title(f"reference {i} (white = {1 / scale:.3g} {unit})", fontsize=9)
        if i < len(result.renders):
            render = _rgb(result.renders[i])
            show_image(row[1], to_srgb8(render, scale), box)
            row[1].set_title(f"fit {i} (same exposure)", fontsize=9)
            residual = (render - ref).mean(axis=-1)
            image = show_image(row[2], residual, box, cmap="RdBu_r", **_centred(cropped(residual, box)))
            row[2].set_title(f"fit - reference {i}", fontsize=9)
            fig.colorbar(image, ax=row[2], extend="both", label=f"fit - reference ({unit})")
        else:
            for ax in row[1:]:
                ax.text(0.5, 0.5, "no render: the solve failed", ha="center", va="center", transform=ax.transAxes)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(f"{result.solver}, {result.loss_name} loss: {result.status}", fontsize=10)
    return axes


def plot_residuals(result: FitResult, *, fig: Figure | SubFigure | None = None, crop: bool = True) -> np.ndarray:
    """Each observation's residual, reference - model (:attr:`FitResult.residuals`), the channels'
    mean in the observation's unit on a diverging colour map centred at 0 (grey where not fitted),
    cropped to the target (found in the fit's render) and a margin unless ``crop=False``.

    Returns:
        the array of axes drawn (one per observation; one that says so where the fit has no residuals).
    """
    n = max(len(result.residuals), 1)
    fig = new_figure(fig, (4.0 * n, 3.6))
    axes = fig.subplots(1, n, squeeze=False)[0]
    cmap = colormaps["RdBu_r"].with_extremes(bad="0.6")
    for k, (ax, residual) in enumerate(zip(axes, result.residuals)):
        mean = np.asarray(residual, dtype=float).mean(axis=-1)
        box = image_box([result.renders[k] if k < len(result.renders) else mean], crop)
        image = show_image(ax, np.ma.masked_invalid(mean), box, cmap=cmap, **_centred(cropped(mean, box)))
        ax.set_title(f"reference - fit, observation {k}", fontsize=9)
        fig.colorbar(image, ax=ax, extend="both", label=f"reference - fit ({unit_label(_unit(result, k))})")
        ax.set_xticks([])
        ax.set_yticks([])
    if not result.residuals:
        axes[0].text(0.5, 0.5, "no residuals: the fit has no render", ha="center", va="center", transform=axes[0].transAxes)
    fig.suptitle(f"{result.status}", fontsize=9)
    return axes


def _unit(result: FitResult, k: int) -> str:
    return result.units[k] if k < len(result.units) else RADIANCE_UNIT


def _centred(values: np.ndarray) -> dict[str, float]:
    """vmin and vmax of a diverging colour map centred at 0 over the finite ``values``."""
    finite = np.abs(values[np.isfinite(values)])
    limit = float(np.percentile(finite, PREVIEW_PERCENTILE)) if finite.size else 0.0
    limit = limit or float(finite.max(initial=0.0)) or 1.0
    return {"vmin": -limit, "vmax": limit}


def _rgb(image: np.ndarray) -> np.ndarray:
    """An (h, w) or (h, w, c) image as (h, w, 3) float32 for display (a grey image in all three;
    values that are not finite, which a mask may have left out of the fit, shown as 0)."""
    image = np.nan_to_num(np.asarray(image, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    image = image[..., None] if image.ndim == 2 else image
    return np.repeat(image, 3, axis=-1) if image.shape[-1] == 1 else image[..., :3]


def plot_convergence(result: FitResult, *, truths: Mapping[str, float] | None = None,
                     fig: Figure | SubFigure | None = None) -> np.ndarray:
    """The loss per step (log axis; accepted steps joined, rejected trials as crosses, the loss's
    Monte Carlo noise as a band above the best loss) and, one panel each, every parameter's value
    per step in its unit, with the fitted value's one-standard-error band and, where ``truths``
    gives it (parameter name -> value, in the parameter's unit), the true value as a dashed line.

    Returns:
        the array of axes drawn: the loss's, then one per parameter in ``result.names`` order.
    """
    truths = dict(truths or {})
    for name, value in truths.items():
        check_choice("truths", name, result.names)
        check_range(f"truths[{name!r}]", value)
    n = len(result.names)
    fig = new_figure(fig, (10.0, max(3.6, 1.4 * n)))
    grid = fig.add_gridspec(max(n, 1), 2)
    ax_loss = fig.add_subplot(grid[:, 0])
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
    ax_loss.set_ylabel("loss, 0.5 sum of squared residuals")
    ax_loss.set_title(f"{result.solver}, {result.loss_name} loss: {result.status.name.lower()}", fontsize=9)
    ax_loss.legend(fontsize=8)
    axes = [ax_loss]
    for i, name in enumerate(result.names):
        ax = fig.add_subplot(grid[i, 1], sharex=ax_loss)
        final, stderr = result.values[name], result.stderr[name]
        ax.plot(steps, [h["values"][name] for h in history], "o-", ms=3, color=f"C{i}")
        if np.isfinite(stderr):
            ax.axhspan(final - stderr, final + stderr, color=f"C{i}", alpha=0.2, label="fit +- 1 standard error")
        ax.axhline(final, color=f"C{i}", lw=0.8)
        if name in truths:
            ax.axhline(truths[name], color="k", ls="--", lw=1.0, label="truth")
        ax.set_ylabel(axis_label(name), fontsize=7)
        if name in truths or np.isfinite(stderr):
            ax.legend(fontsize=6, loc="best")
        axes.append(ax)
    axes[-1].set_xlabel("step")
    for ax in axes:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    return np.array(axes, dtype=object)
