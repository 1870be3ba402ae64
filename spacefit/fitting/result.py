"""The one result of :func:`fit`, whatever observations it fitted: values in physical units,
their standard errors and correlation, the verdict, the goodness of fit and what was run."""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacefit.display import fit_html
from spacefit.errors import InputError
from spacefit.fitting.goodness import Goodness
from spacefit.fitting.status import Status
from spacefit.rendering.mitsuba_scene import mitsuba_scene_dict
from spacefit.scene.parameters import is_nuisance, parameter
from spacefit.scene.schema import Scene
from spacefit.units import DN_UNIT, RADIANCE_UNIT


# The fields of a fit's summary (:meth:`FitResult.to_dict`) without which it is not one.
SUMMARY_FIELDS = ("names", "values", "stderr", "correlation", "success", "status", "warnings", "history", "loss", "solver",
                  "loss_name", "steps", "wall_time_s")


@dataclass
class FitResult:
    """Outcome of :func:`fit`: values in physical units and how far to trust them. A saved one
    (its folder or ``fit.json``) reads back with :func:`read_fit`.

    Attributes:
        names: free parameter names, in order.
        values: fitted value of each, physical units; :attr:`estimates` and :attr:`nuisances` split them.
        stderr: standard error of each (from J^T J and the residual); inf if not determined.
        correlation: (n, n) correlation matrix of the estimates.
        success: whether the fit succeeded: the solver converged, at least one step lowered the
            loss, no parameter is at a bound and the residuals are within the noise
            (``status.success``).
        status: how the fit ended, a verdict (``str(status)`` is its words; :class:`Status`).
        warnings: identifiability and convergence warnings, in words.
        history: one entry per step: the point the step evaluated (step 1 evaluates the start;
            the accepted point of the last step is ``values``), its loss (the one the solver descends: with a
            sensor, the quasi-deviance: docs/explanation/uncertainty.md), ``accepted`` (the step
            evaluated another point than the best so far and lowered its loss: accepted losses never rise), ``loss_noise`` (the loss's
            Monte Carlo noise at the best point so far, the Fitting guide's stop rule),
            time_s since the start.
        renders: each observation's final model, the images' first (the render with the image
            nuisances), then the other kinds' (their predicted values), in the unit of its data: ``units``.
        units: per observation, the unit of its data and model: for an image W m^-2 sr^-1 (radiance),
            or DN where it has a sensor (the sensor's expected DN of the render); a value
            observation's own (sr^-1 for a BRDF table, W m^-2 for a light curve's irradiances).
        loss: final loss, 0.5 * sum of squared residuals (the noise-weighted differences, whose chi^2 the goodness judges).
        solver, loss_name, steps, wall_time_s, start: what was run.
        extras: derived quantities, e.g. the rms height (and its standard error) of a (D, G) fit.
        parts: per observation, per part (and the whole ``target``): the fitted pixels (not masked
            out) that see it and the mean of the reference and of the fit's render there, in ``units`` (keys
            ``reference_mean_w_m2_sr`` and ``fit_mean_w_m2_sr``, or ``reference_mean_dn`` and ``fit_mean_dn``).
            With the pixel loss, each row also holds ``chi2_per_value`` (the noise known) or
            ``r2_over_render_noise`` (mean r^2 over the render noise's; the Fitting guide's goodness of fit).
        scene: the first observation's scene with the fitted values: ``scene.to_toml()`` is a scene
            file that renders the fit again (the image nuisances are not scene values); None if
            the values are not finite.
        goodness: the goodness of fit at the result (chi^2, degrees of freedom, p-value; printed by :func:`format_result`);
            None where there is no finite result (interrupted, non-finite).
        residuals: per observation, data - model in ``units`` (for an image NaN where not fitted).
        observation_goodness: per observation, the goodness of fit of its own residuals (the
            pixel loss), counting as free the shared parameters and its own (``name@k``; a value
            observation those it depends on).
        observations: the observations as the fit was given them (an image, a pass, a table, a light
            curve), each of which reports its part (:meth:`Observation.report`, :meth:`PassObservation.report`).
        entries: per one of ``observations``, its indices into the per-observation lists above (an
            image's one, a pass's one per frame, the images' first, then the value observations').

    Example:
        >>> import numpy as np, spacefit as sf
        >>> zenith = np.radians([10.0, 30.0, 50.0, 70.0])  # the light's; the detector looks down the normal
        >>> wi = np.stack([np.sin(zenith), 0 * zenith, np.cos(zenith)], axis=1)
        >>> wo = np.tile([0.0, 0.0, 1.0], (4, 1))
        >>> table = sf.BRDFTable(wi=wi, wo=wo, value=np.full(4, 0.3 / np.pi), sigma=np.full(4, 0.002), source="white paint")
        >>> result = sf.fit_brdf_table(table, "lambert")
        >>> result.names, result.status.value
        (('parts.sample.kd',), 'converged')
        >>> print(sf.format_result(result).splitlines()[2])
          parts.sample.kd = 0.3 +/- 0.00314  (start 0.1)
    """

    names: tuple[str, ...]
    values: dict[str, float]
    stderr: dict[str, float]
    correlation: np.ndarray
    success: bool
    status: Status
    warnings: list[str]
    history: list[dict[str, Any]]
    renders: list[np.ndarray]
    loss: float
    solver: str
    loss_name: str
    steps: int
    wall_time_s: float
    start: dict[str, float] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)
    parts: list[dict[str, dict[str, float]]] = field(default_factory=list)
    scene: Scene | None = None
    units: list[str] = field(default_factory=list)
    goodness: Goodness | None = None
    residuals: list[np.ndarray] = field(default_factory=list)
    observation_goodness: list[Goodness] = field(default_factory=list)
    observations: tuple[Any, ...] = ()
    entries: tuple[tuple[int, ...], ...] = ()

    def _repr_html_(self) -> str:
        return fit_html(self)

    def mitsuba_scene_dict(self) -> dict[str, Any]:
        """The fitted scene as a Mitsuba scene dictionary (``mi.load_dict`` loads it).

        Raises:
            InputError: if the fit has no scene (its values are not finite).
        """
        if self.scene is None:
            raise InputError("this fit has no fitted scene: its values are not finite.")
        return mitsuba_scene_dict(self.scene)

    @property
    def headline(self) -> str:
        """The verdict and what was run, in one line: the solver on its loss ("lm on the pixel loss"), or, for a fit
        of tables and light curves alone, on their residuals (their loss is least squares whatever ``loss_name``)."""
        images = any(unit in (RADIANCE_UNIT, DN_UNIT) for unit in self.units)
        on = f"the {self.loss_name} loss" if images else "the values' residuals"
        return f"{self.status} ({self.solver} on {on}, {self.steps} steps, {self.wall_time_s:.1f} s, loss {self.loss:.4g})"

    @property
    def images(self) -> list[int]:
        """The indices of the observations that are images (their residuals are (h, w, channels));
        a table's or a light curve's residuals are a vector."""
        return [k for k, r in enumerate(self.residuals) if np.ndim(r) == 3]

    def uncertainty(self) -> dict[str, Any]:
        """The values, standard errors and correlation matrix (rows and columns in ``names`` order),
        with each parameter's unit: JSON-ready (``uncertainty.json`` of a fit's folder).
        ``stderr_valid`` is False for a misfit (the errors assume a correct model: they are too
        small, not scaled) and where the fit did not succeed; ``stderr_note`` says why."""
        return {"names": list(self.names), "values": self.values, "stderr": self.stderr,
                "units": {n: parameter(n).unit for n in self.names},
                "correlation": np.asarray(self.correlation).tolist(), "nuisances": list(self.nuisances),
                "stderr_valid": self.success, "stderr_note": self.stderr_note}

    @property
    def stderr_note(self) -> str:
        """Whether the standard errors can be taken as such, in words ("" when they can)."""
        if self.status is Status.MISFIT:
            return "misfit: the errors assume a correct model and are too small (not scaled)"
        return "" if self.success else f"not an estimate: {self.status}"

    @property
    def nuisances(self) -> dict[str, float]:
        """The fitted nuisance parameters (image gain, offset, PSF, shift; the target's pose, the camera's
        roll), physical units."""
        return {n: v for n, v in self.values.items() if is_nuisance(n)}

    @property
    def estimates(self) -> dict[str, float]:
        """The fitted values of the parameters that are not nuisances (materials, wrinkles, sun)."""
        return {n: v for n, v in self.values.items() if not is_nuisance(n)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no images); ``nuisances`` names the nuisance parameters among ``names``."""
        d = dataclasses.asdict(dataclasses.replace(self, renders=[], residuals=[], scene=None, observations=()))
        for name in ("renders", "residuals", "scene", "observations"):
            d.pop(name)
        d["goodness"] = None if self.goodness is None else self.goodness.to_dict()
        d["observation_goodness"] = [q.to_dict() for q in self.observation_goodness]
        d["nuisances"] = list(self.nuisances)
        d["correlation"] = np.asarray(self.correlation).tolist()
        d["status"] = self.status.value
        d["status_name"] = self.status.name
        d["stderr_undetermined"] = [n for n, e in self.stderr.items() if math.isinf(e)]
        d["entries"] = [list(e) for e in self.entries]
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "fit") -> FitResult:
        """The result of :meth:`to_dict`'s summary (as JSON gives it back: a non-finite number as
        None), without what it leaves out (renders, residuals, the scene, the observations:
        :func:`read_fit` reads a fit's folder with its scene and residuals).
        A None standard error reads back as inf where ``stderr_undetermined`` names it (not determined),
        else NaN (not estimated), and any other None number as NaN. ``where`` names the source in errors.

        Raises:
            InputError: a field of :data:`SUMMARY_FIELDS` missing or malformed, or a status that is none of :class:`Status`'s.
        """
        missing = [key for key in SUMMARY_FIELDS if key not in data]
        if missing:
            raise InputError(f"{where} has no {missing[0]!r}: it is not a fit's summary (FitResult.to_dict).")
        try:
            status = Status[data["status_name"]] if "status_name" in data else Status(data["status"])
        except (KeyError, ValueError, TypeError):
            raise InputError(f"{where}: the status {data.get('status_name', data['status'])!r} is none of "
                             f"sf.Status's ({', '.join(s.name for s in Status)}).") from None
        try:
            names = tuple(data["names"])

            def by_name(values: Mapping[str, Any]) -> dict[str, Any]:  # in ``names`` order (JSON's keys are sorted)
                return {n: values[n] for n in sorted(values, key=lambda n: names.index(n) if n in names else len(names))}

            undetermined = set(data.get("stderr_undetermined", ()))
            stderr = {n: (math.inf if n in undetermined else math.nan) if e is None else float(e) for n, e in data["stderr"].items()}
            history = [{**h, "values": by_name(h["values"])} if isinstance(h.get("values"), dict) else h for h in _numbers(data["history"])]
            units = data.get("units", [])
            return cls(
                names=names, values=by_name(_numbers(data["values"])), stderr=by_name(stderr),
                correlation=np.array(_numbers(data["correlation"]), dtype=float).reshape(len(names), len(names)),
                success=bool(data["success"]), status=status, warnings=list(data["warnings"]), history=history,
                renders=[], loss=_numbers(data["loss"]), solver=data["solver"], loss_name=data["loss_name"],
                steps=int(data["steps"]), wall_time_s=_numbers(data["wall_time_s"]), start=by_name(_numbers(data.get("start", {}))),
                extras=_numbers(data.get("extras", {})), parts=_numbers(data.get("parts", [])),
                units=list(units["observations"] if isinstance(units, Mapping) else units),  # a fit folder's: with the unit words
                goodness=None if data.get("goodness") is None else _goodness(data["goodness"]),
                observation_goodness=[_goodness(g) for g in data.get("observation_goodness", [])],
                entries=tuple(tuple(e) for e in data.get("entries", [])))
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise InputError(f"{where} is not a fit's summary (FitResult.to_dict): {type(err).__name__} {err}.") from None


def _numbers(value: Any) -> Any:
    """``value`` (JSON's numbers, lists and dicts) with every None as NaN."""
    if value is None:
        return math.nan
    if isinstance(value, dict):
        return {k: _numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_numbers(v) for v in value]
    return value


def _goodness(data: Mapping[str, Any]) -> Goodness:
    """The :class:`Goodness` of its ``to_dict`` (its fields; a None float as NaN, tuples from lists)."""
    hints = typing.get_type_hints(Goodness)
    fields = {}
    for f in dataclasses.fields(Goodness):
        if f.name in data:
            value = data[f.name]
            fields[f.name] = (math.nan if value is None else float(value)) if hints[f.name] is float else (
                tuple(value) if isinstance(value, list) else value)
    return Goodness(**fields)
