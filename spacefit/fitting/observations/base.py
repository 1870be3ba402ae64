"""The contract of an observation whose data are a vector of values (a table, a light curve), and the
block of residuals it adds to a fit.

A :class:`ValueObservation` names the registered parameters it depends on (``parts.chassis.kd``,
``target.attitude_z_deg``), gives its own value of each (what it holds them at when they are not
free, and a fit's default start), and, for an ordered set of free names, builds its
:class:`Block`: a JAX model of its data and the residuals of a model. The residuals are
(model - data) / sigma, or, for values spanning decades (a BRDF's specular peak over its diffuse
floor, a light curve's irradiances), ln(model / data) / sigma_rel with sigma_rel the relative error
(:class:`MeasuredValues`); without stated errors sigma is 1 and the fit's covariance scales them by
their mean square (:func:`spacefit.fitting.uncertainty.covariance`).

Every kind, images and passes included, also keeps the contract of :class:`Reported`: its part of a
fit's report (:meth:`Reported.report`, lines of :func:`~spacefit.fitting.report.format_result`) and its
figure (:meth:`Reported.plot`), read from the fit's result at the entries that are its own
(:attr:`~spacefit.fitting.result.FitResult.entries`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError
from spacefit.fitting.params import Bijection, bijection
from spacefit.fitting.result import FitResult
from spacefit.scene.names import Name

if TYPE_CHECKING:  # types only: matplotlib loads where a figure is drawn
    from spacefit.plotting import AxesArg, FigureArg

# a model of the data: (the fit's free values, physical; the seed index j: 0 the fit's, 1 an
# independent one, more further ones) -> the predicted values, in the data's unit
Model = Callable[[jax.Array, int], jax.Array]


@dataclass(frozen=True)
class MeasuredValues:
    """Measured values with their errors.

    Attributes:
        value: (n,) the values, in ``unit``.
        sigma: (n,) their standard errors, absolute, or relative with ``log``; None: not stated.
        log: the residuals compare logarithms (every value must be positive).
        unit: the values' unit, for reports.
        source: where they came from, for messages.
    """

    value: np.ndarray
    sigma: np.ndarray | None
    log: bool
    unit: str
    source: str

    def __post_init__(self) -> None:
        value = np.asarray(self.value, dtype=float)
        if value.ndim != 1 or not value.size or not np.all(np.isfinite(value)):
            raise InputError(f"{self.source}: the data must be a vector of finite values, got shape {value.shape}.")
        if self.log and not np.all(value > 0):
            raise InputError(f"{self.source}: the data must be positive to fit their logarithm; {int(np.sum(~(value > 0)))} values are not.")
        object.__setattr__(self, "value", value)
        if self.sigma is not None:
            sigma = np.broadcast_to(np.asarray(self.sigma, dtype=float), value.shape)
            if not np.all(np.isfinite(sigma) & (sigma > 0)):
                raise InputError(f"{self.source}: every sigma must be positive and finite.")
            object.__setattr__(self, "sigma", sigma)

    def residual(self, model: jax.Array) -> jax.Array:
        """The residuals of predicted values ``model``: (model - value) / sigma, or with ``log``
        ln(model / value) / sigma (sigma 1 where not stated)."""
        scale = jnp.asarray(self.sigma if self.sigma is not None else np.ones_like(self.value))
        if self.log:
            return (jnp.log(jnp.maximum(model, 1e-300)) - jnp.asarray(np.log(self.value))) / scale
        return (model - jnp.asarray(self.value)) / scale


@dataclass(frozen=True)
class Block:
    """What one value observation adds to a fit's problem: its data, their model and residuals.

    Attributes:
        data: the measured values and errors.
        model: (x, j) -> the predicted values at the fit's free values x at seed index j.
        known: which of the fit's free names the model depends on (the others do not move it).
        rendered: the model is rendered (Monte Carlo): seed index j changes it.
        spp: a rendered model's samples per pixel (None: not rendered, or not resampled).
        resampled: factor -> the block rendered with factor times :attr:`spp` (a verdict's render,
            :mod:`spacefit.fitting.judging`); None: the model cannot take more samples.
    """

    data: MeasuredValues
    model: Model
    known: tuple[str, ...]
    rendered: bool = False
    spp: int | None = None
    resampled: Callable[[int], Block] | None = None

    @property
    def noise_known(self) -> bool:
        """Whether the residuals are in units of the data's noise (their errors are stated)."""
        return self.data.sigma is not None

    def residual(self, model: jax.Array) -> jax.Array:
        """The residuals of predicted values (:meth:`MeasuredValues.residual`)."""
        return self.data.residual(model)


@runtime_checkable
class Reported(Protocol):
    """What every kind of observation reports of a fit: ``entries`` are its own indices into the
    result's per-observation lists (``renders``, ``residuals``, ``units``, ``observation_goodness``:
    an image's one, a pass's one per frame, a value observation's one)."""

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """Its lines of the fit's report (indented, no verdict: the fit's own lines give it)."""

    def plot(self, result: FitResult, entries: Sequence[int], *, ax: AxesArg = None, fig: FigureArg = None) -> np.ndarray:
        """Its figure of the fit into ``ax`` or ``fig`` (:mod:`spacefit.plotting`): the array of axes drawn."""


@runtime_checkable
class Sequenced(Reported, Protocol):
    """An observation made of images (a pass, :class:`~spacefit.fitting.observations.passes.PassObservation`):
    the fit's set-up puts its images in its place and frees its per-image names."""

    images: Sequence[Any]

    def names(self, first: int) -> list[Name]:
        """Its per-image free names when its first image is the fit's observation ``first``."""


class ValueObservation(ABC):
    """An observation whose data are a vector of values predicted from named parameter values."""

    @abstractmethod
    def parameters(self) -> tuple[str, ...]:
        """The registered parameter names this observation's prediction depends on."""

    @abstractmethod
    def start(self, name: str) -> float:
        """This observation's own value of parameter ``name`` (one of :meth:`parameters`)."""

    @abstractmethod
    def block(self, free: tuple[str, ...]) -> Block:
        """The residual block of a fit whose free values are ``free``, in order (the model takes
        their vector; names it does not depend on are ignored, the others held at :meth:`start`)."""

    def size(self, free: Sequence[str], *, allow_large: bool = False) -> tuple[str, int] | None:
        """Its renders' size in words and their estimated peak memory (bytes), refused above the
        memory available unless ``allow_large``; None (the default) where it renders nothing."""
        return None

    def coordinate(self, name: str) -> Bijection:
        """The solver's coordinate of ``name``: a bijection onto the registry's bounds
        (:func:`spacefit.fitting.params.bijection`), unless this observation narrows them."""
        return bijection(name)

    def values_of(self, free: tuple[str, ...], x: jax.Array) -> dict[str, jax.Array]:
        """Its parameters' values at the fit's free values ``x``: the free ones from ``x``, the
        others at :meth:`start`."""
        own = self.parameters()
        values: dict[str, jax.Array] = {n: jnp.asarray(self.start(n)) for n in own}
        values.update({n: x[i] for i, n in enumerate(free) if n in own})
        return values

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """Its goodness of fit, and how many values it has in which unit (:class:`Reported`)."""
        k = entries[0]
        head = f"  observation {k} ({result.units[k]} values)"
        if k < len(result.observation_goodness):
            return [f"{head}: {result.observation_goodness[k].line()}"]
        return [f"{head}: {len(result.residuals[k]) if k < len(result.residuals) else 'no'} residuals"]

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """What its ``count`` values are plotted against and the axis label: by default their index."""
        return np.arange(count, dtype=float), "value"

    def shown(self, values: np.ndarray, unit: str) -> tuple[np.ndarray, str, str]:
        """Its values in ``unit`` as its figure shows them, their axis label and the axis's scale
        (:func:`~spacefit.plotting.plot_values`): by default as they are, on a linear scale."""
        return np.asarray(values, dtype=float), f"value ({unit})", "linear"

    def plot(self, result: FitResult, entries: Sequence[int], *, ax: AxesArg = None, fig: FigureArg = None) -> np.ndarray:
        """Its data and model (:attr:`~spacefit.fitting.result.FitResult.renders`) against
        :meth:`abscissa` as :meth:`shown`, and below the residual data - model
        (:attr:`~spacefit.fitting.result.FitResult.residuals`; for magnitudes, observed - predicted
        magnitude) (:func:`~spacefit.plotting.plot_values`)."""
        from spacefit.plotting import plot_values  # deferred: matplotlib, which only figures need

        k = entries[0]
        unit = result.units[k] if k < len(result.units) else ""
        model = np.asarray(result.renders[k], dtype=float) if k < len(result.renders) else np.zeros(0)
        residual = np.asarray(result.residuals[k], dtype=float) if k < len(result.residuals) else np.zeros(0)
        data = model + residual
        x = self.abscissa(len(model))
        shown_data, label, scale = self.shown(data, unit)
        shown_model = self.shown(model, unit)[0]
        difference, what = ((shown_data - shown_model, "observed - predicted (mag)") if scale == "magnitude"
                            else (residual, f"data - model ({unit})"))
        return plot_values(x[0], shown_data, shown_model, difference, xlabel=x[1], ylabel=label, difference_label=what,
                           scale=scale, title=f"observation {k}", ax=ax, fig=fig)
