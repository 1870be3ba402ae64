"""What the figures share: axis labels in words with units, the crop to the target, their axes.

Every figure function takes ``ax=`` as matplotlib users pass it (:data:`AxesArg`): one Axes for a
figure of one panel, or an array or sequence of Axes (``plt.subplots``'s, in any shape) for one of
several, one per panel in the user's own layout; a wrong count is refused, naming the count given
and the count needed. Or it takes ``fig=`` (a matplotlib Figure or SubFigure to lay its panels out
in). It returns the flat array of axes it drew (:func:`panels`). Without either it makes a Figure of
its own without pyplot, so the global backend (a notebook's) is left alone:
``axes[0].figure.savefig(path)`` saves it. A figure-wide title is drawn only on a figure the
function lays out. A panel that would be empty is not drawn (its reason is in the function's
docstring and, where the others are drawn, in the figure). Images are cropped to the target by
default (its bounding box and a margin, :func:`target_box`), their axes keeping the film's pixel
coordinates; ``crop=False`` shows the whole film. Labels come from the parameter registry (each
parameter's words, :func:`spacefit.scene.parameters.label`, and unit) and
:data:`spacefit.display.QUANTITIES` for what is not a parameter. matplotlib is imported with this
module, which only the figure functions load.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Callable, Sequence
from typing import Any, TypeAlias

import numpy as np
from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.cbook import is_math_text
from matplotlib.figure import Figure, SubFigure
from matplotlib.font_manager import FontProperties
from matplotlib.image import AxesImage
from matplotlib.ticker import LogFormatterSciNotation

from spacefit.display import describe
from spacefit.errors import InputError, check_choice, check_type

# What ``ax=`` takes: one Axes, Axes in a sequence or an array of any shape, or None (a new figure).
AxesArg: TypeAlias = Axes | Sequence[Axes] | np.ndarray | None
# What ``fig=`` takes: a Figure or SubFigure to lay the panels out in, or None.
FigureArg: TypeAlias = Figure | SubFigure | None

# The crop's margin on each side: a fraction of the target's box, and at least this many pixels.
TARGET_MARGIN = 0.15
MIN_MARGIN_PX = 2
# A pixel shows the target where it differs from the background by more than this fraction of the
# image's largest difference (a sensor's Airy rings and bias are below it, the lit target above).
TARGET_THRESHOLD = 0.01
# An exponent's characters as Unicode superscripts.
SUPERSCRIPTS = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def _superscript(power: re.Match[str]) -> str:
    """A matched exponent (its first group) in Unicode superscripts."""
    return power[1].translate(SUPERSCRIPTS)


def unit_label(unit: str) -> str:
    """A unit as axis text, powers as Unicode superscripts (``W m^-2 sr^-1`` -> ``W m⁻² sr⁻¹``: plain text, which
    matplotlib draws without its mathtext parser); "" for a dimensionless one ("1")."""
    return "" if unit in ("1", "") else re.sub(r"\^(-?\d+)", _superscript, unit)


def with_unit(words: str, unit: str) -> str:
    """``words (unit)``, or the words alone for a dimensionless quantity."""
    text = unit_label(unit)
    return f"{words} ({text})" if text else words


def axis_label(name: str) -> str:
    """``name`` (a parameter, or a quantity of :data:`spacefit.display.QUANTITIES`) in words with its
    unit: "albedo kd of panels", "target attitude about z (deg)", "solar phase angle (deg)"."""
    return with_unit(*describe(name))


class PlainLogFormatter(LogFormatterSciNotation):
    """matplotlib's labels of a log axis ("10⁵", "2×10⁴"; the ticks it labels are its own) as plain text with
    Unicode superscripts: they look the same as its mathtext labels, and are drawn without mathtext's parser
    (a third of a small log-scale figure's draw, 0.03 s; 0.05 s more for a process's first, which builds the parser)."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        """The label of the tick at ``x``, "" for a tick left unlabelled."""
        text = super().__call__(x, pos).removeprefix(r"$\mathdefault{").removesuffix("}$").replace(r"\times", "×")
        return re.sub(r"\^\{(-?\d+)\}", _superscript, text).replace("-", "−")  # mathtext's minus


def log_scale(ax: Axes) -> None:
    """``ax``'s y axis on a log scale, its ticks labelled in plain text (:class:`PlainLogFormatter`)."""
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(PlainLogFormatter())
    ax.yaxis.set_minor_formatter(PlainLogFormatter())


def wrapped(text: str, length_px: float, dpi: float, fontsize: float) -> str:
    """``text`` in lines that fit ``length_px`` pixels at ``dpi`` and ``fontsize`` points (a character taken as
    0.6 of the size wide; at least 12 characters a line)."""
    return textwrap.fill(text, max(int(length_px / dpi * 72 / (0.6 * fontsize)), 12))


def suptitle(figure: Figure | SubFigure, text: str, fontsize: float) -> None:
    """``figure``'s title, ``text`` in lines that fit its width: a fit's verdict runs to 250 characters, which one
    line would cut off at both sides."""
    figure.suptitle(wrapped(text, figure.bbox.width, figure.dpi, fontsize), fontsize=fontsize)


def points_renderer() -> RendererAgg:
    """A renderer that measures text in points (72 dots per inch), for a layout computed before the figure is drawn."""
    return RendererAgg(1, 1, 72)


def line_pt(renderer: RendererAgg, prop: FontProperties) -> float:
    """The height of a line of text in ``prop``'s font, points (``renderer``: :func:`points_renderer`): that of "lp",
    as matplotlib measures a line."""
    return renderer.get_text_width_height_descent("lp", prop, False)[1]


def tick_labels(axis: Axis) -> list[str]:
    """The tick labels ``axis`` draws at its present view and size (major and minor; those left empty left out), as its
    locators and formatters make them when it is drawn, without making its ticks: what a layout computed before the
    draw measures."""
    view = np.sort(axis.get_transform().transform(np.asarray(axis.get_view_interval(), dtype=float)))
    close = 1e-10 * (view[1] - view[0])  # matplotlib draws the ticks within the view, or this close to it
    labels = []
    for locs, formatter in ((axis.get_majorticklocs(), axis.get_major_formatter()),
                            (axis.get_minorticklocs(), axis.get_minor_formatter())):
        at = axis.get_transform().transform(np.asarray(locs, dtype=float))
        labels += [text for text, x in zip(formatter.format_ticks(locs), at) if text and view[0] - close <= x <= view[1] + close]
    return labels


def left_decoration_pt(ax: Axes, renderer: RendererAgg) -> float:
    """How far ``ax``'s y axis reaches to the left of it, points (``renderer``: :func:`points_renderer`): its ticks,
    their labels (:func:`tick_labels`, where shown) and its label."""
    axis = ax.yaxis
    tick = axis.get_major_ticks(1)[0]
    prop = tick.label1.get_fontproperties()
    widest = max((renderer.get_text_width_height_descent(text, prop, is_math_text(text))[0] for text in tick_labels(axis)),
                 default=0.0) if tick.label1.get_visible() else 0.0
    label = axis.label.get_window_extent(renderer).width + axis.labelpad if axis.label.get_text() else 0.0
    return tick.get_tick_padding() + tick.get_pad() + widest + label


def target_box(images: Sequence[np.ndarray], margin: float = TARGET_MARGIN) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1), the half-open pixel bounds of what differs from the background in any of
    ``images`` ((h, w) or (h, w, channels), all as large), with ``margin`` of the box (at least
    :data:`MIN_MARGIN_PX`) on each side, within the film. An image's background is the median of its
    border; a pixel differs where its channels' mean is over :data:`TARGET_THRESHOLD` of the
    image's largest difference away (values that are not finite are background). The whole film
    where no pixel differs."""
    height, width = np.shape(images[0])[:2]
    seen = np.zeros((height, width), dtype=bool)
    for image in images:
        grey = np.asarray(image, dtype=float)
        grey = np.nan_to_num(grey.mean(axis=-1) if grey.ndim == 3 else grey, nan=0.0, posinf=0.0, neginf=0.0)
        border = np.concatenate([grey[0], grey[-1], grey[:, 0], grey[:, -1]])
        away = np.abs(grey - np.median(border))
        if away.max() > 0:
            seen |= away > TARGET_THRESHOLD * away.max()
    if not seen.any():
        return 0, 0, width, height
    rows, columns = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
    y0, y1, x0, x1 = rows[0], rows[-1] + 1, columns[0], columns[-1] + 1
    pad = max(MIN_MARGIN_PX, round(margin * max(x1 - x0, y1 - y0)))
    return max(x0 - pad, 0), max(y0 - pad, 0), min(x1 + pad, width), min(y1 + pad, height)


def image_box(images: Sequence[np.ndarray], crop: bool) -> tuple[int, int, int, int]:
    """:func:`target_box` of ``images`` where ``crop``, else the whole film."""
    check_type("crop", crop, bool, "True (the target and a margin) or False (the whole film)")
    height, width = np.shape(images[0])[:2]
    return target_box(images) if crop else (0, 0, width, height)


def cropped(image: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The part of ``image`` inside ``box`` (:func:`target_box`)."""
    x0, y0, x1, y1 = box
    return np.asarray(image)[y0:y1, x0:x1]


def show_image(ax: Axes, image: np.ndarray, box: tuple[int, int, int, int], **kwargs: Any) -> AxesImage:
    """``ax.imshow`` of ``image``'s part inside ``box``, placed at the film's pixel coordinates
    (pixel centres at whole numbers, y down)."""
    x0, y0, x1, y1 = box
    return ax.imshow(cropped(image, box), extent=(x0 - 0.5, x1 - 0.5, y1 - 0.5, y0 - 0.5), **kwargs)


def panels(ax: AxesArg, fig: FigureArg, count: int | Sequence[int], figsize: tuple[float, float],
           make: Callable[[Figure | SubFigure], Any], layout: str = "constrained") -> np.ndarray:
    """The axes a figure function draws, flat: ``ax`` (:data:`AxesArg`: one Axes, or a sequence or
    array of them in any shape: the user's layout), checked to hold ``count`` Axes (or one of the
    counts ``count`` lists, for a figure that draws fewer panels into fewer axes); else
    ``make(figure)``'s, on ``fig`` or on a new Figure of ``figsize`` (inches) made without pyplot,
    laid out by matplotlib's ``layout`` engine ("none": by the figure function).

    Raises:
        InputError: ``ax`` and ``fig`` both given, an ``ax`` that is not Axes, or a count of them that
            is not ``count`` (naming both).
    """
    if ax is None:
        return np.asarray(make(new_figure(fig, figsize, layout)), dtype=object).ravel()
    if fig is not None:
        raise InputError("give `ax` (the axes to draw into) or `fig` (a figure to lay them out in), not both.")
    counts = (count,) if isinstance(count, int) else tuple(count)
    needed = " or ".join(map(str, counts))
    axes = np.asarray([ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object))), dtype=object)
    for one in axes:
        check_type("ax", one, Axes, f"a matplotlib Axes, or an array of {needed} (one per panel)")
    if len(axes) not in counts:
        raise InputError(f"`ax` must be {needed} matplotlib Axes here (one per panel), got {len(axes)}.")
    return axes


def new_figure(fig: FigureArg, figsize: tuple[float, float], layout: str = "constrained") -> Figure | SubFigure:
    """``fig``, checked, or a new Figure of ``figsize`` (inches) made without pyplot, laid out by ``layout``."""
    if fig is None:
        return Figure(figsize=figsize, layout=layout)
    check_type("fig", fig, (Figure, SubFigure), "a matplotlib Figure or SubFigure (fig.subfigures() makes one)")
    return fig


def plot_values(x: np.ndarray, data: np.ndarray, model: np.ndarray, difference: np.ndarray, *, xlabel: str, ylabel: str,
                difference_label: str, scale: str = "linear", title: str = "", ax: AxesArg = None,
                fig: FigureArg = None) -> np.ndarray:
    """Measured values ``data`` and their ``model`` against ``x`` (top; ``scale`` "linear", "log", or
    "magnitude": linear with brighter up) and ``difference`` (data against model, bottom), into
    ``ax`` (two Axes) or ``fig``: the array of the two axes drawn."""
    check_choice("scale", scale, ("linear", "log", "magnitude"))
    axes = panels(ax, fig, 2, (6.0, 4.4), lambda f: f.subplots(2, 1, sharex=True, squeeze=False, height_ratios=(2, 1)))
    top, bottom = axes
    top.plot(x, data, "o", ms=3, label="data")
    top.plot(x, model, "x", ms=4, label="model")
    if scale == "log":
        log_scale(top)
    elif scale == "magnitude":
        top.invert_yaxis()
    top.set_ylabel(ylabel, fontsize=8)
    top.legend(fontsize=7)
    if title:
        top.set_title(title, fontsize=9)
    bottom.plot(x, difference, "o", ms=3, color="C2")
    bottom.axhline(0.0, color="0.5", lw=0.8)
    bottom.set_ylabel(difference_label, fontsize=8)
    bottom.set_xlabel(xlabel)
    for panel in axes:
        panel.grid(alpha=0.3)
    return axes
