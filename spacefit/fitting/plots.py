"""A fit's plots, public as ``sf.plot_comparison`` and ``sf.plot_convergence``.

Each takes ``ax=`` (the axes to draw into, one per panel) or ``fig=`` (a matplotlib Figure or
SubFigure to lay them out in) and returns the axes it drew (:mod:`spacefit.plotting`: without
either it makes a Figure without pyplot, saved with ``axes.flat[0].figure.savefig(path)``). Images are cropped to the target and a margin unless
``crop=False``. matplotlib is imported with this module, which ``import spacefit`` loads only on
first use of these names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib as mpl
import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.figure import Figure, SubFigure
from matplotlib.font_manager import FontProperties
from matplotlib.ticker import MaxNLocator

from spacefit.errors import check_choice, check_range
from spacefit.fitting.result import FitResult
from spacefit.output import PREVIEW_PERCENTILE, preview_scale, to_srgb8
from spacefit.plotting import (AxesArg, FigureArg, axis_label, cropped, image_box, left_decoration_pt, line_pt, log_scale, panels,
                               points_renderer, show_image, suptitle, tick_labels, unit_label, wrapped)
from spacefit.units import RADIANCE_UNIT

# The convergence figure's room beyond its labels' own, points: at its edges, and between its columns and its panels
# (what matplotlib's constrained layout leaves).
PAD_PT = 3.0
# matplotlib's gap between an axes and its y axis's offset text ("1e-5", "+1.5e-1", above it), points.
OFFSET_TEXT_PAD_PT = 3.0


def plot_comparison(result: FitResult, references: Sequence[np.ndarray], *, ax: AxesArg = None,
                    fig: FigureArg = None, crop: bool = True) -> np.ndarray:
    """Reference | fit | residual reference - fit (the sign of :attr:`FitResult.residuals`), one row per observation.

    Args:
        result: the fit's outcome (its renders; missing where the solve failed).
        references: the reference images (h, w, 3), in observation order, each in the unit of the
            fit's model image (``result.units``: radiance, or DN for an observation with a sensor).
        ax: the axes to draw into, 3 per observation (row by row); or ``fig``: the matplotlib Figure
            or SubFigure to lay them out in (default: a new one).
        crop: show the target and a margin (found in the fit's render, else the reference); False:
            the whole film.
    Returns:
        The axes drawn, an array of one row of 3 per image (the fit at the reference's sRGB exposure,
        the residual's RGB mean in that unit on a diverging colour map centred at 0, grey where not fitted:
        :func:`residual_panel`, the picture of residuals.fits).

    Example:
        Not run by the tests (an image fit takes minutes)::

            scene = sf.load_scene("lander.toml")
            observation = sf.PassObservation.read("pass/frames.csv", scene, per_frame=["target.attitude_x_deg"])
            result = sf.fit([observation], ["parts.legs.kd"])
            references = [sf.read_exr(frame.file) for frame in sf.Pass.read("pass/frames.csv").frames]
            axes = sf.plot_comparison(result, references)
    """
    n = len(references)
    axes = panels(ax, fig, 3 * n, (10.5, 3.2 * n), lambda f: f.subplots(n, 3, squeeze=False)).reshape(n, 3)
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
            residual_panel(row[2], result, i, crop, reference)
        else:
            for panel in row[1:]:
                panel.text(0.5, 0.5, "no render: the solve failed", ha="center", va="center", transform=panel.transAxes)
        for panel in row:
            panel.set_xticks([])
            panel.set_yticks([])
    if ax is None:
        suptitle(axes[0, 0].figure, f"{result.solver}, {result.loss_name} loss: {result.status}", 10)
    return axes


def residual_panel(panel: Axes, result: FitResult, k: int, crop: bool = True, reference: np.ndarray | None = None) -> None:
    """Image ``k``'s residual, reference - fit, into ``panel``: the channels' mean in its unit on a diverging colour
    map centred at 0 (its scale symmetric, a colour bar in the unit), grey where not fitted, titled "reference - fit,
    observation k". The fit's :attr:`FitResult.residuals` (what residuals.fits holds); for a fit without them (one
    interrupted), ``reference`` less the fit's render. Cropped to the target (in the fit's render) and a margin unless
    ``crop=False``."""
    fitted = k < len(result.residuals) and np.ndim(result.residuals[k]) == 3
    mean = (np.asarray(result.residuals[k], dtype=float) if fitted else _rgb(reference) - _rgb(result.renders[k])).mean(axis=-1)
    box = image_box([result.renders[k] if k < len(result.renders) else mean], crop)
    cmap = colormaps["RdBu_r"].with_extremes(bad="0.6")
    image = show_image(panel, np.ma.masked_invalid(mean), box, cmap=cmap, **_centred(cropped(mean, box)))
    panel.set_title(f"reference - fit, observation {k}", fontsize=9)
    panel.figure.colorbar(image, ax=panel, extend="both", label=f"reference - fit ({unit_label(_unit(result, k))})")
    panel.set_xticks([])
    panel.set_yticks([])


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


def plot_convergence(result: FitResult, *, truths: Mapping[str, float] | None = None, ax: AxesArg = None,
                     fig: FigureArg = None) -> np.ndarray:
    """The loss per step (log axis; accepted steps joined, rejected trials as crosses, the loss's
    Monte Carlo noise as a band above the best loss) and, one panel each, every parameter's value
    per step in its unit, with the fitted value's one-standard-error band and, where ``truths``
    gives it (parameter name -> value, in the parameter's unit), the true value as a dashed line
    (their legend once, in the first parameter's panel);
    into ``ax`` (the loss's, then one per parameter) or ``fig``.

    Returns:
        the array of axes drawn: the loss's, then one per parameter in ``result.names`` order.

    Args:
        result: the fit's result (its history).
        truths: known values by name, drawn as dashed lines.
        ax: the axes to draw into, or ``fig``: the Figure or SubFigure to lay them out in (default: a new one).

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> table = sf.BRDFTable(wi=wi, wo=np.tile([0.0, 0.0, 1.0], (4, 1)), value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="paint")
        >>> axes = sf.plot_convergence(sf.fit_brdf_table(table, "lambert"), truths={"parts.sample.kd": 0.3})
        >>> len(axes)  # the loss, then kd
        2
    """
    truths = dict(truths or {})
    for name, value in truths.items():
        check_choice("truths", name, result.names)
        check_range(f"truths[{name!r}]", value)
    n = len(result.names)

    def layout(f: Figure | SubFigure) -> list[Axes]:
        grid = f.add_gridspec(max(n, 1), 2, **_rows(f, n))
        loss = f.add_subplot(grid[:, 0])
        return [loss, *(f.add_subplot(grid[i, 1], sharex=loss) for i in range(n))]

    axes = panels(ax, fig, n + 1, (10.0, max(3.6, 1.4 * n)), layout, layout="none")
    ax_loss = axes[0]
    history = result.history
    steps = np.array([h["step"] for h in history])
    losses = np.array([h["loss"] for h in history], dtype=float)
    accepted = np.array([h.get("accepted", True) for h in history], dtype=bool)
    log_scale(ax_loss)
    ax_loss.plot(steps[accepted], losses[accepted], "o-", ms=3, label="accepted")
    if (~accepted).any():
        ax_loss.plot(steps[~accepted], losses[~accepted], "x", color="C3", ms=5, label="rejected")
    noise = np.array([h.get("loss_noise", np.nan) for h in history], dtype=float)
    if np.isfinite(noise).any():
        best = np.minimum.accumulate(np.where(np.isfinite(losses), losses, np.inf))
        ax_loss.fill_between(steps, best, best + noise, color="0.6", alpha=0.4, step="post", label="Monte Carlo noise")
    ax_loss.set_xlabel("step")
    ax_loss.set_ylabel("loss, 0.5 sum of squared residuals")
    ax_loss.set_title(f"{result.solver}, {result.loss_name} loss: {result.status.headline}", fontsize=9)
    ax_loss.legend(fontsize=8)
    for i, (name, panel) in enumerate(zip(result.names, axes[1:])):
        final, stderr = result.values[name], result.stderr[name]
        panel.plot(steps, [h["values"][name] for h in history], "o-", ms=3, color=f"C{i}")
        if np.isfinite(stderr):
            panel.axhspan(final - stderr, final + stderr, color=f"C{i}", alpha=0.2, label="fit +- 1 standard error")
        panel.axhline(final, color=f"C{i}", lw=0.8)
        if name in truths:
            panel.axhline(truths[name], color="k", ls="--", lw=1.0, label="truth")
        # in lines as long as the panel is high (its own figure's rows are laid out already): one line ran into its neighbours'
        panel.set_ylabel(wrapped(axis_label(name), panel.get_window_extent().height, panel.figure.dpi, 7), fontsize=7)
        if ax is None:  # its own column, sharing the steps: numbered once, under it
            panel.tick_params(labelbottom=panel is axes[-1])
    column = {label: handle for panel in axes[1:] for handle, label in zip(*panel.get_legend_handles_labels())}
    if column:  # the band's and the truth's meaning once, in the column's first panel: every panel's would say the same
        axes[1].legend(column.values(), column.keys(), fontsize=6, loc="best")
    axes[-1].set_xlabel("step")
    for panel in axes:
        panel.xaxis.set_major_locator(MaxNLocator(integer=True))
        panel.grid(alpha=0.3)
    if ax is None and fig is None:
        _columns(axes)
    return axes


def _rows(figure: Figure | SubFigure, n: int) -> dict[str, float]:
    """The convergence figure's rows (GridSpec's top, bottom and hspace) in ``figure``: room above for the loss's title
    (or the first panel's offset text), below for the steps' numbers and label, and between two of the ``n``
    parameters' panels for a tick label's line, which holds the lower one's offset text; from the fonts alone, so
    that the panels have their heights before anything is drawn in them."""
    renderer = points_renderer()
    tick = line_pt(renderer, FontProperties(size=mpl.rcParams["ytick.labelsize"]))
    label = line_pt(renderer, FontProperties(size=mpl.rcParams["axes.labelsize"]))
    title = line_pt(renderer, FontProperties(size=9)) + mpl.rcParams["axes.titlepad"]
    steps = mpl.rcParams["xtick.major.size"] + mpl.rcParams["xtick.major.pad"] + tick + mpl.rcParams["axes.labelpad"] + label
    top, bottom, gap = PAD_PT + max(title, OFFSET_TEXT_PAD_PT + tick), PAD_PT + steps, OFFSET_TEXT_PAD_PT + tick + PAD_PT
    height = figure.bbox.height / figure.dpi * 72
    rows = max(n, 1)
    return {"top": 1 - top / height, "bottom": bottom / height, "hspace": gap * rows / (height - top - bottom - gap * (rows - 1))}


def _columns(axes: np.ndarray) -> None:
    """Lay the convergence figure's two columns out once, from its labels' extents in points (its axes' positions set;
    it has no layout engine): the loss's y axis within the left edge, the parameters' (the widest) between the
    columns, the steps' last label within the right edge. matplotlib's constrained layout measured every axes twice
    at every draw, each time making and placing its ticks: 60 % of the figure's drawing."""
    renderer, figure = points_renderer(), axes[0].figure
    width = figure.bbox.width / figure.dpi * 72
    prop = axes[-1].xaxis.get_major_ticks(1)[0].label1.get_fontproperties()
    overhang = max((renderer.get_text_width_height_descent(text, prop, False)[0] / 2 for text in tick_labels(axes[-1].xaxis)),
                   default=0.0)  # a step's number centred at the right edge
    left = PAD_PT + left_decoration_pt(axes[0], renderer)
    right = PAD_PT + overhang
    gap = overhang + PAD_PT + max((left_decoration_pt(panel, renderer) for panel in axes[1:]), default=0.0)
    grid = axes[0].get_subplotspec().get_gridspec()
    grid.update(left=left / width, right=1 - right / width, wspace=2 * gap / (width - left - right - gap))
    for panel in axes:
        panel.set_position(panel.get_subplotspec().get_position(figure))
