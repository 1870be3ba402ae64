"""The BRDF-table kind of observation: a measured table (:class:`BRDFTable`)
of one part's material, predicted by a material model (:data:`BRDF_MODELS`),
and the conveniences that fit it with :func:`fit` and choose the smallest model that fits.

The model's values are the part's registered parameters: a table measuring part ``chassis`` fits
``parts.chassis.eta``, ``parts.chassis.alpha`` (:mod:`spacefit.scene.parameters`, whose bounds they
take), so that a table and an image of the same part share them in a joint fit. The residuals compare
logarithms (the values span the specular peak to the diffuse floor, five decades): ln(model / data) /
sigma_rel, sigma_rel = sigma / value, or the ``relative_error`` given for a table without errors;
with neither, the errors are scaled by the residuals and no verdict is given.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_choice, check_count, check_name_list, check_range, check_type
from spacefit.fitting.brdf_table import BRDF_MODELS, DEFAULT_START
from spacefit.materials.measured import BRDFTable
from spacefit.fitting.loop import fit
from spacefit.fitting.result import FitResult
from spacefit.fitting.observations.base import Block, MeasuredValues, ValueObservation
from spacefit.materials import Material
from spacefit.scene.parameters import check_value

BRDF_UNIT = "sr^-1"


@dataclass(frozen=True, eq=False)
class BRDFTableObservation(ValueObservation):
    """A measured BRDF table of part ``part``'s material, predicted by the material model ``model``.

    Attributes:
        table: the measured values.
        model: a name in :data:`BRDF_MODELS`.
        part: the part whose material the table measures: its parameters are ``parts.<part>.<field>``.
        relative_error: each value's relative error where the table states none (None: unknown).
        values: the model's values by field (``{"k": 0.0}``), what a fit holds them at when they
            are not free and its default start (otherwise the model's own start, :class:`MaterialModel`).

    Raises:
        InputError: an unknown model, or values of fields the model does not have.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> observation = sf.BRDFTableObservation(table, "lambert", part="paint")
        >>> result = sf.fit([observation], ["parts.paint.kd"])
        >>> round(result.values["parts.paint.kd"], 3)
        0.3
    """

    table: BRDFTable
    model: str = "lambert+ggx"
    part: str = "sample"
    relative_error: float | None = None
    values: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_type("table", self.table, BRDFTable, "an sf.BRDFTable (sf.read_brdf_table)")
        check_choice("model", self.model, BRDF_MODELS)
        check_type("part", self.part, str, "a part name (a string)")
        if self.relative_error is not None:
            check_range("relative_error", self.relative_error, 0.0, lo_open=True)
        if self.table.sigma is not None and self.relative_error is not None:
            raise InputError(f"BRDF table {self.table.source} states its errors (sigma_sr); do not give `relative_error` as well.")
        check_type("values", self.values, Mapping, "a dict of the model's values by field")
        for key, value in self.values.items():
            check_choice("values", key, BRDF_MODELS[self.model].parameters)
            check_value(self.name_of(key), value, key)

    def name_of(self, field_name: str) -> str:
        """The registered name of the model's field ``field_name``: ``parts.<part>.<field>``."""
        return f"parts.{self.part}.{field_name}"

    def parameters(self) -> tuple[str, ...]:
        """``parts.<part>.<field>`` of each of the model's fields."""
        return tuple(self.name_of(f) for f in BRDF_MODELS[self.model].parameters)

    def start(self, name: str) -> float:
        """The model's value of ``name``: :attr:`values`'s, else the model's own start."""
        key = name.rsplit(".", 1)[-1]
        return float(self.values.get(key, DEFAULT_START[key]))

    def block(self, free: tuple[str, ...]) -> Block:
        """ln(model / data) against the relative errors."""
        m, table = BRDF_MODELS[self.model], self.table
        sigma = table.sigma / table.value if table.sigma is not None else self.relative_error
        data = MeasuredValues(table.value, sigma, True, BRDF_UNIT, f"BRDF table {table.source}")
        wi, wo = jnp.asarray(table.wi), jnp.asarray(table.wo)

        @jax.jit
        def predict(x: jax.Array) -> jax.Array:
            return m.evaluate({n.rsplit(".", 1)[-1]: v for n, v in self.values_of(free, x).items()}, wi, wo)

        return Block(data, lambda x, j: predict(x), tuple(n for n in free if n in self.parameters()))

    def abscissa(self, count: int) -> tuple[np.ndarray, str]:
        """Each value's angle of observation: the zenith angle of ``wo``, degrees."""
        return np.degrees(np.arccos(np.clip(self.table.wo[:, 2], -1.0, 1.0))), "angle of observation from the normal (deg)"

    def shown(self, values: np.ndarray, unit: str) -> tuple[np.ndarray, str, str]:
        """The BRDF values as they are, on a log scale (they span the specular peak to the diffuse floor)."""
        return np.asarray(values, dtype=float), f"BRDF of part {self.part} ({unit})", "log"


def fit_brdf_table(table: BRDFTable, model: str = "lambert+ggx", *, relative_error: float | None = None,
                   start: dict[str, float] | None = None, fixed: dict[str, float] | None = None,
                   max_steps: int = 200, part: str = "sample") -> FitResult:
    """Fit the material model ``model`` (:data:`BRDF_MODELS`) of part
    ``part`` to a measured table with :func:`fit`: every field of the
    model is free (``parts.<part>.<field>``) but those ``fixed`` holds at given values (``{"k": 0.0}``:
    a dielectric's Fresnel factor, for a coated surface whose eta and k the table cannot separate;
    the result's ``extras["fixed"]`` records them); ``start``: start values by field.

    Args:
        table: the measured table.
        model: a name in :data:`BRDF_MODELS`.
        relative_error: each value's relative error where the table states none; None: unknown
            (the fit then has no chi^2 verdict).
        start: start values by field; default the model's.
        fixed: values by field held fixed.
        max_steps: the solver's step limit.
        part: the part name the parameters carry (``parts.<part>.<field>``).

    Returns:
        The :class:`FitResult`: values, standard errors, status and a chi^2 verdict against the errors.

    Raises:
        InputError: an unknown model, a field the model does not have, a value out of range.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> result = sf.fit_brdf_table(table, "lambert")
        >>> result.status.value, round(result.values["parts.sample.kd"], 3)
        ('converged', 0.3)
    """
    check_count("max_steps", max_steps, optional=False)
    for name, given in (("start", start), ("fixed", fixed)):
        check_type(name, given, (dict, type(None)), "a dict of parameter values by name, or None")
        for key in given or {}:
            check_choice(name, key, BRDF_MODELS[check_choice("model", model, BRDF_MODELS)].parameters)
    fixed = dict(fixed or {})
    observation = BRDFTableObservation(table, model, part, relative_error, {**(start or {}), **fixed})
    free = [n for n in observation.parameters() if n.rsplit(".", 1)[-1] not in fixed]
    if not free:
        raise InputError(f"no parameter is left to fit: `fixed` holds every field of the model {model!r}.")
    result = fit(observation, free, max_steps=max_steps)
    result.extras["fixed"] = {observation.name_of(k): float(v) for k, v in fixed.items()}
    return result


def fitted_material(model: str, fit: FitResult) -> Material:
    """The material of a :func:`fit_brdf_table` fit of ``model``: its estimates and fixed values.

    Args:
        model: the model name the fit was made with.
        fit: the :func:`fit_brdf_table` result.

    Returns:
        The material (:class:`Lambert`, :class:`Conductor`, :class:`DiffuseConductor`, ...), for a
        scene's part.

    Raises:
        InputError: an unknown model, or a fit of another model.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> material = sf.fitted_material("lambert", sf.fit_brdf_table(table, "lambert"))
        >>> type(material).__name__, round(material.kd, 3)
        ('Lambert', 0.3)
    """
    check_choice("model", model, BRDF_MODELS)
    check_type("fit", fit, FitResult, "an sf.FitResult (of sf.fit_brdf_table)")
    values = {name.rsplit(".", 1)[-1]: v for name, v in {**fit.values, **fit.extras.get("fixed", {})}.items()}
    if sorted(values) != sorted(BRDF_MODELS[model].parameters):
        raise InputError(f"`fit` is not a fit of the model {model!r}: it has {sorted(values)}, the model {list(BRDF_MODELS[model].parameters)}.")
    return BRDF_MODELS[model].material(values)


def smallest_adequate(fits: Sequence[FitResult]) -> int | None:
    """The index of the first fit (give them smallest model first) that is not a misfit and converged:
    the smallest model that explains the data within their errors; None if none does (or the errors
    are unknown, when no fit has a verdict)."""
    for i, f in enumerate(fits):
        if f.goodness is not None and f.goodness.noise_known and f.status.success:
            return i
    return None


@dataclass(frozen=True)
class ModelComparison:
    """Fits of several models to one table, smallest first, and the smallest that fits within the errors."""

    fits: dict[str, FitResult]
    chosen: str | None

    def table(self) -> str:
        """One line per model: its parameters' count, chi^2 / dof against the misfit limit, its verdict."""
        lines = [f"{'model':>24s} {'params':>6s} {'chi2/dof':>10s} {'limit':>7s}  verdict"]
        for name, f in self.fits.items():
            g = f.goodness
            chi2 = f"{g.chi2_dof:10.4g} {g.limit:7.4g}" if g is not None and g.noise_known else f"{'unknown':>10s} {'':7s}"
            mark = "  <- smallest within the errors" if name == self.chosen else ""
            lines.append(f"{name:>24s} {len(f.names):6d} {chi2}  {f.status.name.lower()}{mark}")
        if self.chosen is None:
            known = any(f.goodness is not None and f.goodness.noise_known for f in self.fits.values())
            lines.append("no model fits within the errors" if known else "errors unknown: give `relative_error` to choose a model")
        return "\n".join(lines)


def compare_brdf_models(table: BRDFTable, models: Sequence[str] = ("lambert", "ggx", "lambert+ggx", "lambert+beckmann",
                                                                  "lambert+ggx_aniso"), *,
                        relative_error: float | None = None, fixed: dict[str, float] | None = None) -> ModelComparison:
    """Fit each of ``models`` (ordered by their number of parameters; ``fixed`` values held in those that
    have them) and choose the smallest that is no misfit (:func:`smallest_adequate`).

    Args:
        table: the measured table.
        models: names in :data:`BRDF_MODELS`.
        relative_error: each value's relative error where the table states none.
        fixed: values by field held fixed where a model has the field.

    Returns:
        The fits by model name (``fits``), the smallest adequate one's name (``chosen``; None if every
        one is a misfit) and ``table()``, one line per model.

    Raises:
        InputError: an unknown model.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> comparison = sf.compare_brdf_models(table, ["lambert", "lambert+ggx"])
        >>> comparison.chosen
        'lambert'
    """
    check_type("table", table, BRDFTable, "an sf.BRDFTable (sf.read_brdf_table)")
    for name in check_name_list("models", models):
        check_choice("models", name, BRDF_MODELS)
    check_type("fixed", fixed, (dict, type(None)), "a dict of parameter values by name, or None")
    ordered = sorted(models, key=lambda n: len(BRDF_MODELS[n].parameters))
    fits = {name: fit_brdf_table(table, name, relative_error=relative_error,
                                 fixed={k: v for k, v in (fixed or {}).items() if k in BRDF_MODELS[name].parameters})
            for name in ordered}
    chosen = smallest_adequate(list(fits.values()))
    return ModelComparison(fits, None if chosen is None else ordered[chosen])
