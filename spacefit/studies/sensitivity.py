"""Sensitivity of the image to scene parameters, each derivative with its Monte Carlo standard error.

A derivative is estimated ``seeds`` times with independent seeds, on one loaded scene
(:func:`spacefit.rendering.derivatives.jacobians`), by the method the fit uses for that parameter
(the registry's ``fd_step``): forward-mode AD for materials and the sun's irradiance, central finite
differences with common random numbers for geometry, the pose and the sun's angles. The result is
their mean, and its standard error is the seeds' standard deviation over sqrt(seeds). A derivative
is *resolved* when its 95 % confidence interval (Student's t with seeds - 1 degrees of freedom)
excludes zero; one that is not is flagged as such wherever it is shown, never given as a bare number.

The normalised sensitivity of a region's mean radiance L to a parameter p is (p / L) dL/dp, the
relative change of radiance per relative change of p, for positive quantities (materials, the
irradiance, D, G, the rms height); for angles and positions, which have no natural zero, it is
(1 / L) dL/dp per radian or per metre.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.display import sensitivity_html
from spacefit.errors import check_choice, check_count, check_range
from spacefit.progress import progress_bar
from spacefit.scene.parameters import check_names, label, parameter
from spacefit.scene.schema import Scene
from spacefit.scene.sections import MAX_SEED, check_scene
from spacefit.units import RADIANCE_UNIT

if TYPE_CHECKING:  # types only: matplotlib loads where a figure is drawn
    from spacefit.plotting import AxesArg, FigureArg

TARGET = "target"  # the region of every part together, beside the parts
CONFIDENCE = 0.95  # two-sided: a derivative is resolved when this interval excludes zero
# The sweep's per-point variables of a sensitivity: name -> (dtype, fill, unit, description).
SUMMARY_VARIABLES: dict[str, tuple[Any, Any, str, str]] = {
    "d_mean_radiance": (np.float64, np.nan, "W m^-2 sr^-1 per parameter_unit", "derivative of the region's mean radiance"),
    "d_mean_radiance_se": (np.float64, np.nan, "W m^-2 sr^-1 per parameter_unit", "its Monte Carlo standard error"),
    "sensitivity": (np.float64, np.nan, "normalised_unit", "normalised sensitivity of the region's mean radiance"),
    "sensitivity_se": (np.float64, np.nan, "normalised_unit", "its Monte Carlo standard error"),
    "resolved": (bool, False, "1", f"the derivative's {CONFIDENCE:.0%} confidence interval excludes zero"),
}


def normalisation(name: str, value: float) -> tuple[float, str]:
    """Factor turning dL/dp / L into the normalised sensitivity of parameter ``name`` at ``value``,
    and its unit: p ("1") for positive quantities, per radian or per metre for angles and positions."""
    p = parameter(name)
    if p.bounds.lo >= 0.0:
        return value, "1"
    if p.unit == "deg":
        return 180.0 / math.pi, "rad^-1"
    return 1.0, f"{p.unit}^-1"


def per_unit(unit: str, parameter_unit: str) -> str:
    """The unit of a derivative of a ``unit`` quantity by a ``parameter_unit`` one (``unit`` alone
    for a dimensionless parameter, "1")."""
    return unit if parameter_unit == "1" else f"{unit} per {parameter_unit}"


def mean_and_error(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over the first axis (independent seeds) and its standard error (sample std / sqrt(n))."""
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / math.sqrt(samples.shape[0])


def t_critical(seeds: int) -> float:
    """Student's t quantile of the two-sided :data:`CONFIDENCE` interval with seeds - 1 degrees of freedom."""
    from scipy.stats import t  # here: SciPy's statistics take 0.4 s to import, which a sweep without derivatives never needs

    return float(t.ppf(0.5 + CONFIDENCE / 2.0, seeds - 1))


@dataclass(frozen=True)
class Sensitivity:
    """Derivatives of the image and of each region's mean radiance at one point, with standard errors.

    Attributes:
        names: the parameters; ``units`` their units (degrees for angles, as in the scene file).
        at: each parameter's value.
        seeds: the (primal and finite-difference seed, AD seed) pair of each independent estimate.
        image: (h, w, 3) radiance, W m^-2 sr^-1, mean over the seeds.
        derivative, derivative_se: (n, h, w, 3) d(radiance)/d(parameter), W m^-2 sr^-1 per unit, and its error.
        regions: each part, then ``target`` (all parts); ``pixels`` whose centre sees each.
        mean_radiance: (regions,) W m^-2 sr^-1.
        d_mean_radiance, d_mean_radiance_se: (n, regions) derivative of each region's mean radiance.
        sensitivity, sensitivity_se: (n, regions) normalised sensitivities (the Studies guide),
            in ``normalised_units``.
        t: the Student t factor of the confidence interval (``t * se``).

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> s = sf.sensitivity(scene, ["parts.legs.kd"], seeds=2, quiet=True)
        >>> s.to_dataset()["derivative"].dims  # the derivative image of each parameter
        ('parameter', 'y', 'x', 'channel')
    """

    names: tuple[str, ...]
    units: dict[str, str]
    at: dict[str, float]
    seeds: tuple[tuple[int, int], ...]
    image: np.ndarray
    derivative: np.ndarray
    derivative_se: np.ndarray
    regions: tuple[str, ...]
    pixels: np.ndarray
    mean_radiance: np.ndarray
    d_mean_radiance: np.ndarray
    d_mean_radiance_se: np.ndarray
    sensitivity: np.ndarray
    sensitivity_se: np.ndarray
    normalised_units: dict[str, str]
    t: float

    @property
    def resolved(self) -> np.ndarray:
        """(n, regions) whether each region's derivative is resolved from its noise."""
        return np.abs(self.d_mean_radiance) > self.t * self.d_mean_radiance_se

    def resolved_pixels(self, name: str) -> np.ndarray:
        """(h, w) pixels where d(radiance)/d(``name``) (RGB mean) is resolved from its noise."""
        i = self.names.index(name)
        return np.abs(self.derivative[i].mean(axis=-1)) > self.t * self.derivative_se[i].mean(axis=-1)

    @property
    def exact_zero(self) -> np.ndarray:
        """(n, regions) where a region's derivative is exactly zero in every seed (no pixel of it
        depends on the parameter: another part's material, say): zero, not noise."""
        return (self.d_mean_radiance == 0.0) & (self.d_mean_radiance_se == 0.0)

    def rows(self) -> list[dict[str, str]]:
        """The table's rows as text cells: ``parameter``, ``region``, ``dL/dp`` (with its standard error),
        its ``unit``, ``normalised`` (with its error and unit, none where it is dimensionless) and a
        ``note``: ``UNRESOLVED (noise)`` where the confidence interval holds zero, ``NOT FINITE``
        without a finite error; an exact zero (:attr:`exact_zero`) is ``0`` with no note."""
        out = []
        for i, name in enumerate(self.names):
            unit = per_unit(RADIANCE_UNIT, self.units[name])
            for j, region in enumerate(self.regions):
                d, d_se = self.d_mean_radiance[i, j], self.d_mean_radiance_se[i, j]
                if self.exact_zero[i, j]:
                    out.append({"parameter": name, "region": region, "dL/dp": "0", "unit": unit, "normalised": "0", "note": ""})
                    continue
                finite = np.isfinite(d_se)
                note = "" if self.resolved[i, j] else "UNRESOLVED (noise)" if finite else "NOT FINITE (no pixels, or NaN renders)"
                normalised_unit = "" if self.normalised_units[name] == "1" else f" {self.normalised_units[name]}"
                out.append({"parameter": name, "region": region, "dL/dp": f"{d:+.4g} +- {d_se:.2g}", "unit": unit,
                            "normalised": f"{self.sensitivity[i, j]:+.4g} +- {self.sensitivity_se[i, j]:.2g}{normalised_unit}",
                            "note": note})
        return out

    def table(self) -> str:
        """The regions' derivatives and normalised sensitivities as text, each with its standard error
        (:meth:`rows`)."""
        lines = [f"{'parameter':28s} {'region':10s} {'dL/dp':>22s}  {'unit':26s} {'normalised':>24s}"]
        lines += [f"{r['parameter']:28s} {r['region']:10s} {r['dL/dp']:>22s}  {r['unit']:26s} {r['normalised']:>24s}"
                  + (f"  {r['note']}" if r["note"] else "") for r in self.rows()]
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        return sensitivity_html(self)

    def chart_steps(self, steps: Mapping[str, float] | None = None) -> dict[str, tuple[float, str]]:
        """Each parameter's step in the chart of :meth:`figure`, and how it was chosen: ``steps``'s
        where it gives one (in the parameter's unit), else a tenth of the parameter's valid range
        where that is finite (D: 0.1), else its size of a change that matters (``Parameter.scale``:
        0.1 deg for an attitude angle), else a tenth of its value (the sun's irradiance)."""
        steps = dict(steps or {})
        for name, step in steps.items():
            check_choice("steps", name, self.names)
            check_range(f"steps[{name!r}]", step, 0.0, lo_open=True, unit=self.units[name])
        out = {}
        for name in self.names:
            p = parameter(name)
            if name in steps:
                out[name] = (float(steps[name]), "as given")
            elif math.isfinite(p.bounds.hi - p.bounds.lo):
                out[name] = ((p.bounds.hi - p.bounds.lo) / 10.0, f"a tenth of its range {p.bounds.describe()}")
            elif p.scale > 0:
                out[name] = (p.scale, "a change that matters")
            else:
                out[name] = (abs(self.at[name]) / 10.0, "a tenth of its value")
        return out

    def figure(self, *, ax: AxesArg = None, fig: FigureArg = None, crop: bool = True, steps: Mapping[str, float] | None = None) -> np.ndarray:
        """Each derivative image (unresolved pixels grey), cropped to the target and a margin unless
        ``crop=False``; and each region's change of mean radiance for a step of each parameter
        (:meth:`chart_steps`, ``steps``: name -> step in its unit), relative to the region's mean
        radiance, with its confidence interval (unresolved bars hatched; an exact zero is 0).
        ``ax``: the axes to draw into (one per parameter, then the chart's); or ``fig``: a matplotlib
        Figure or SubFigure to lay them out in (default: a new one).

        Returns:
            the array of axes drawn: the derivative images' in ``names`` order, then the chart's.
        """
        from spacefit.plotting import cropped, image_box, panels, show_image, unit_label  # here: matplotlib (0.5 s), for a figure only

        chart = self.chart_steps(steps)
        n = len(self.names)
        columns = min(n, 3)
        rows = math.ceil(n / columns)

        def layout(f: Any) -> list[Any]:
            grid = f.add_gridspec(rows + 1, columns)
            return [*(f.add_subplot(grid[i // columns, i % columns]) for i in range(n)), f.add_subplot(grid[rows, :])]

        axes = panels(ax, fig, n + 1, (4.2 * columns, 3.4 * rows + 3.6), layout)
        grey = self.derivative.mean(axis=-1)
        box = image_box([self.image, *np.abs(grey)], crop)
        for i, (name, image_ax) in enumerate(zip(self.names, axes)):
            shown = cropped(np.where(self.resolved_pixels(name), grey[i], np.nan), box)
            limit = float(np.nanmax(np.abs(shown))) if np.isfinite(shown).any() else 0.0
            show_image(image_ax, np.zeros_like(grey[i]), box, cmap="Greys", vmin=-1, vmax=4)  # grey under unresolved pixels
            im = show_image(image_ax, np.where(self.resolved_pixels(name), grey[i], np.nan), box, cmap="RdBu_r",
                            vmin=-(limit or 1.0), vmax=limit or 1.0)
            image_ax.figure.colorbar(im, ax=image_ax, shrink=0.8, label=unit_label(per_unit(RADIANCE_UNIT, self.units[name])))
            image_ax.set_title(f"d radiance / d {label(name)}", fontsize=9)
            image_ax.set_xticks([])
            image_ax.set_yticks([])
        bars = axes[-1]
        width = 0.8 / n
        x = np.arange(len(self.regions))
        with np.errstate(divide="ignore", invalid="ignore"):
            relative = 100.0 * self.d_mean_radiance / self.mean_radiance
            relative_se = 100.0 * self.d_mean_radiance_se / np.abs(self.mean_radiance)
        for i, name in enumerate(self.names):
            step, how = chart[name]
            shown = np.where(self.exact_zero[i], 0.0, relative[i] * step)
            clear = self.resolved[i] | self.exact_zero[i]
            for j in range(len(self.regions)):
                bars.bar(x[j] + i * width, shown[j], width, yerr=self.t * relative_se[i, j] * step, color=f"C{i}",
                         hatch="" if clear[j] else "//", alpha=1.0 if clear[j] else 0.4,
                         label=f"{label(name)}: step {step:.3g} {unit_label(self.units[name])} ({how})".replace("  ", " ")
                         if j == 0 else None)
        bars.axhline(0.0, color="k", lw=0.5)
        bars.set_xticks(x + width * (n - 1) / 2, self.regions)
        bars.set_ylabel("change of mean radiance per step (%)")
        bars.set_title(f"{CONFIDENCE:.0%} intervals; hatched: unresolved", fontsize=9)
        bars.legend(fontsize=7)
        return axes

    def to_dataset(self) -> Any:
        """The sensitivity as a labelled xarray Dataset (dimensions parameter, region, y, x, channel)."""
        import xarray as xr  # here: only a dataset needs xarray (slow to import)

        per_unit = "W m^-2 sr^-1 per parameter_unit"
        return xr.Dataset(
            {"image": (("y", "x", "channel"), self.image, {"units": RADIANCE_UNIT}),
             "derivative": (("parameter", "y", "x", "channel"), self.derivative, {"units": per_unit}),
             "derivative_se": (("parameter", "y", "x", "channel"), self.derivative_se, {"units": per_unit}),
             "mean_radiance": (("region",), self.mean_radiance, {"units": RADIANCE_UNIT}),
             "pixels": (("region",), self.pixels),
             **{k: (("parameter", "region"), v, {"units": SUMMARY_VARIABLES[k][2], "description": SUMMARY_VARIABLES[k][3]})
                for k, v in point_summaries(self).items()}},
            coords={"parameter": list(self.names), "region": list(self.regions),
                    "parameter_unit": ("parameter", [self.units[n] for n in self.names]),
                    "normalised_unit": ("parameter", [self.normalised_units[n] for n in self.names]),
                    "at": ("parameter", [self.at[n] for n in self.names])},
            attrs={"seeds": [list(s) for s in self.seeds], "confidence": CONFIDENCE})


def point_summaries(s: Sensitivity) -> dict[str, np.ndarray]:
    """The per-region variables of a sensitivity that a sweep stores (:data:`SUMMARY_VARIABLES`)."""
    return {"d_mean_radiance": s.d_mean_radiance, "d_mean_radiance_se": s.d_mean_radiance_se,
            "sensitivity": s.sensitivity, "sensitivity_se": s.sensitivity_se, "resolved": s.resolved}


def sensitivity(
    scene: Scene, names: Sequence[str], *, at: Mapping[str, float] | None = None, seeds: int = 4,
    spp: int | None = None, spp_grad: int | None = None, quiet: bool = False,
) -> Sensitivity:
    """Derivatives of the image and of each part's and the whole target's mean radiance with respect
    to the registered parameters ``names`` (``sf.available_parameters(scene)``), at the scene's values
    or ``at`` (parameter names or scene-file keys, as :meth:`Scene.with_values` takes them), each
    from ``seeds`` independent estimates (>= 2) with its standard error. ``spp`` / ``spp_grad``: samples per pixel of the primal and finite
    difference renders / of the AD renders (default: the scene's).

    Args:
        scene: the scene.
        names: registered parameter names.
        at: values (parameter names or scene-file keys) replacing the scene's.
        seeds: independent estimates of each derivative, >= 2.
        spp, spp_grad: samples per pixel (None: the scene's).
        quiet: no progress bar.

    Returns:
        A :class:`Sensitivity`.

    Raises:
        InputError: a name the scene cannot free, ``seeds`` < 2 or past (2^31 - ``render.seed``) / 2 (the
            estimates' render seeds, ``render.seed`` + 2 k and + 2 k + 1, are Mitsuba's, below 2^31).

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> s = sf.sensitivity(scene, ["parts.legs.kd"], seeds=2, quiet=True)
        >>> s.names
        ('parts.legs.kd',)
    """
    # here: the fitting and rendering stack imports JAX and Mitsuba (seconds), which a sweep without derivatives never needs
    from spacefit.fitting.problem import fit_scene
    from spacefit.rendering.derivatives import jacobians

    check_scene(scene)
    names = check_names(scene, names, "names")
    if at:
        scene = scene.with_values(at)
    scene = fit_scene(scene, names)  # as the fit: wrinkles rendered as geometry, where D and G act
    s0 = scene.render.seed
    # before the pairs are made: 2**70 seeds would fill the memory building them, not be refused
    check_count("seeds", seeds, 2, (MAX_SEED + 1 - s0) // 2, f"estimate k's renders take the seeds render.seed + 2 k and "
                f"+ 2 k + 1 (render.seed = {s0}), Mitsuba's, at most 2^31 - 1", optional=False)
    pairs = tuple((s0 + 2 * k, s0 + 2 * k + 1) for k in range(seeds))
    bar = progress_bar(seeds, "sensitivity", quiet=quiet)
    try:
        results, renderer = jacobians(scene, names, pairs, spp=spp, spp_grad=spp_grad, progress=bar.update)
    finally:
        bar.close()
    part_image = renderer.part_image()
    regions, masks = part_image.regions, part_image.masks()
    images = np.stack([r.image for r in results]).astype(float)
    columns = np.stack([[r.columns[n] for n in names] for r in results]).astype(float)  # (seeds, n, h, w, 3)

    def region_means(a: np.ndarray) -> np.ndarray:  # (..., h, w, 3) -> (..., regions), NaN where none
        grey = a.mean(axis=-1)
        return np.stack([grey[..., m].mean(axis=-1) if m.any() else np.full(grey.shape[:-2], np.nan) for m in masks], axis=-1)

    L = region_means(images)  # (seeds, regions)
    dL = region_means(columns)  # (seeds, n, regions)
    at_values = results[0].at
    scale = {n: normalisation(n, at_values[n]) for n in names}
    factors = np.array([scale[n][0] for n in names])[None, :, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        normalised = factors * dL / L[:, None, :]
    image, _ = mean_and_error(images)
    derivative, derivative_se = mean_and_error(columns)
    mean_L, _ = mean_and_error(L)
    d, d_se = mean_and_error(dL)
    sens, sens_se = mean_and_error(normalised)
    return Sensitivity(names, {n: parameter(n).unit for n in names}, dict(at_values), pairs, image.astype(np.float32),
                       derivative.astype(np.float32), derivative_se.astype(np.float32), regions,
                       np.array([int(m.sum()) for m in masks]), mean_L, d, d_se, sens, sens_se,
                       {n: scale[n][1] for n in names}, t_critical(seeds))
