"""Fits of a few parameters to a table of measured values with errors (a BRDF table, a light curve).

The same pieces as an image fit, on a vector of values: the solvers (:mod:`spacefit.fitting.solvers`,
Levenberg-Marquardt by default) step the unconstrained coordinates of each parameter's
:class:`~spacefit.fitting.params.Bijection`; the residuals are (model - data) / sigma, or, for
values spanning decades (a BRDF's specular peak over its diffuse floor, magnitudes' irradiances),
ln(model / data) / sigma_rel (``log=True``, sigma_rel the relative error). With the errors known
the covariance is the noise model's own (J^T J)^-1 and the goodness of fit
(:func:`spacefit.fitting.goodness.goodness`) gives its chi^2 verdict (a rendered model's own Monte
Carlo noise, measured per value from two seeds, (r - r_alt)^2 / 2, is added through the sandwich
B J^T diag(.) J B, B = (J^T J)^-1, as in the image fits); without, the errors are
scaled by the residuals' mean square s^2 (J^T J)^-1 and no verdict is given. The verdicts on the
solve (no progress, at a bound, misfit) are :func:`spacefit.fitting.loop.verdict`'s. A model that is
rendered (Monte Carlo) passes ``predict_alt``, the same model with an independent seed, whose
difference is the render noise the goodness of fit allows for.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, InputTypeError, check_count, check_flag, check_name_list, check_path, check_type, quote
from spacefit.fitting.goodness import Goodness, goodness
from spacefit.fitting.loop import verdict
from spacefit.fitting.params import Bijection
from spacefit.fitting.solvers import Solver, Status, drive, make_solver
from spacefit.fitting.uncertainty import CORRELATION_WARN
from spacefit.locks import holding_lock
from spacefit.output import prepare_output, staged_output, versions, write_json
from spacefit.precision import float64

Predict = Callable[[jax.Array], jax.Array]


@dataclass(frozen=True)
class TableFit:
    """The outcome of :func:`fit_table`.

    Attributes:
        names: the parameters, in order; ``values`` their estimates, ``stderr`` their standard
            errors (inf where the data do not determine them), ``covariance`` the full matrix.
        status: the verdict (:class:`~spacefit.fitting.solvers.Status`); ``goodness`` the chi^2 test.
        residuals: the normalised residuals at the estimate (one per value).
        steps: solver steps taken.
        fixed: parameters held at given values (name -> value), not fitted.
    """

    names: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    status: Status
    goodness: Goodness
    residuals: np.ndarray
    steps: int
    fixed: dict[str, float] = dataclasses.field(default_factory=dict)

    @property
    def success(self) -> bool:
        """Whether the fit converged to an estimate its data do not contradict."""
        return self.status.success

    def value(self, name: str) -> float:
        """The estimate of parameter ``name``."""
        return float(self.values[self.names.index(name)])

    def warnings(self) -> list[str]:
        """Pairs of parameters correlated beyond :data:`~spacefit.fitting.uncertainty.CORRELATION_WARN` (not
        separately determined) and parameters the data leave undetermined."""
        out = [f"{n} is not determined by these data (infinite error)" for n, s in zip(self.names, self.stderr) if np.isinf(s)]
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = self.covariance / np.outer(self.stderr, self.stderr)
        for i in range(len(self.names)):
            for j in range(i + 1, len(self.names)):
                if np.isfinite(corr[i, j]) and abs(corr[i, j]) > CORRELATION_WARN:
                    out.append(f"{self.names[i]} and {self.names[j]} are correlated {corr[i, j]:+.3f}: not separately determined")
        return out

    def report(self) -> str:
        """The verdict, the goodness of fit, each parameter with its standard error, the warnings."""
        g = self.goodness
        spread = (f"goodness of fit (errors unknown, no verdict): residual RMS {math.sqrt(np.mean(self.residuals**2)):.4g} over "
                  f"{g.dof} dof; the standard errors are scaled by it")
        lines = [str(self.status), g.line() if g.noise_known or np.isfinite(g.spread) else spread]
        lines += [f"  {n:>10s} = {v:.6g} +- {s:.2g}" for n, v, s in zip(self.names, self.values, self.stderr)]
        lines += [f"  {n:>10s} = {v:.6g} (fixed)" for n, v in self.fixed.items()]
        return "\n".join(lines + [f"  warning: {w}" for w in self.warnings()])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: values, errors (None where infinite), status, goodness."""
        return {"values": dict(zip(self.names, self.values.tolist())), "fixed": dict(self.fixed),
                "stderr": {n: (float(s) if np.isfinite(s) else None) for n, s in zip(self.names, self.stderr)},
                "status": self.status.name, "goodness": self.goodness.to_dict(), "steps": self.steps, "warnings": self.warnings()}


def fit_table(
    predict: Predict,
    data: np.ndarray,
    sigma: np.ndarray | None,
    names: Sequence[str],
    bounds: Sequence[Bijection],
    start: Sequence[float],
    *,
    log: bool = False,
    predict_alt: Predict | None = None,
    solver: str | Solver = "lm",
    max_steps: int = 200,
) -> TableFit:
    """Fit ``predict(x)`` (a JAX function of the physical parameters, one value per datum) to ``data``.

    Args:
        data: the measured values (n,).
        sigma: their standard errors (n,), absolute, or relative with ``log``; None: unknown (the
            errors are then scaled by the residuals and the goodness of fit gives no verdict).
        names, bounds, start: the parameters, their open ranges and start values (inside them).
        log: fit ln(model / data) (data must be positive).
        predict_alt: the model with an independent Monte Carlo seed (rendered models), else none.
        solver, max_steps: as :func:`spacefit.fit`.
    """
    data = np.asarray(data, dtype=float)
    check_count("max_steps", max_steps)
    if not names:
        raise InputError("no parameter is left to fit: `free` names none (e.g. ['array.kd']), or every one is `fixed`.")
    if data.ndim != 1 or data.size <= len(names):
        raise InputError(f"`data` must be a vector of more values than the {len(names)} free parameters, got shape {data.shape}.")
    if log and not np.all(data > 0):
        raise InputError(f"`data` must be positive to fit its logarithm; {int(np.sum(~(data > 0)))} values are not.")
    if sigma is not None:
        sigma = np.broadcast_to(np.asarray(sigma, dtype=float), data.shape)
        if not np.all(np.isfinite(sigma) & (sigma > 0)):
            raise InputError("every `sigma` must be positive and finite.")
    for name, b, v in zip(names, bounds, start):
        if not b.contains(float(v)):
            raise InputError(f"start of `{name}` must be inside {b.describe()}, got {float(v):g}.")
    return _fit(predict, data, sigma, tuple(names), tuple(bounds), np.asarray(start, dtype=float), log, predict_alt,
                make_solver(solver), max_steps)


@float64
def _fit(predict: Predict, data: np.ndarray, sigma: np.ndarray | None, names: tuple[str, ...], bounds: tuple[Bijection, ...],
         start: np.ndarray, log: bool, predict_alt: Predict | None, solver: Solver, max_steps: int) -> TableFit:
    scale = jnp.asarray(sigma if sigma is not None else np.ones_like(data))
    target = jnp.asarray(np.log(data) if log else data)

    def residuals(model: Predict) -> Callable[[jax.Array], jax.Array]:
        def residual_x(x: jax.Array) -> jax.Array:
            y = model(x)
            return ((jnp.log(jnp.maximum(y, 1e-300)) if log else y) - target) / scale
        return residual_x

    def to_x(u: jax.Array) -> jax.Array:
        return jnp.stack([b.forward(u[i]) for i, b in enumerate(bounds)])

    # compiled whole: evaluated op by op, each JAX primitive compiles on its own (139 compilations, 25 s)
    residual_x = jax.jit(residuals(predict))
    u0 = jnp.stack([b.inverse(jnp.asarray(v)) for b, v in zip(bounds, start)])
    loss0 = 0.5 * float(jnp.sum(residual_x(to_x(u0)) ** 2))
    residual_u = jax.jit(lambda u: residuals(predict)(to_x(u)))
    run = drive(solver, residual_u, u0, max_steps, None)
    best_u, best_loss = u0, loss0
    try:
        while True:
            step = next(run)
            if np.isfinite(step.loss) and step.loss < best_loss:
                best_u, best_loss = jnp.asarray(step.u), step.loss
    except StopIteration as stop:
        outcome = stop.value
    x = np.asarray(to_x(best_u))
    r = np.asarray(residual_x(jnp.asarray(x)))
    J = np.asarray(jax.jit(jax.jacfwd(residuals(predict)))(jnp.asarray(x)))
    noise_known = sigma is not None
    r_alt = np.asarray(residuals(predict_alt)(jnp.asarray(x))) if predict_alt is not None else r
    fit_goodness = goodness(r, (r - r_alt) / np.sqrt(2.0), len(x), noise_known)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        n = len(x)
        return TableFit(names, x, np.full(n, np.nan), np.full((n, n), np.nan), Status.NONFINITE, fit_goodness, r, outcome.steps)
    dof = max(r.size - len(x), 1)
    s2 = 1.0 if noise_known else float(r @ r) / dof
    info = J.T @ J
    eigval, eigvec = np.linalg.eigh(info)
    tiny = eigval <= 1e-12 * max(float(np.abs(eigval).max()), 1e-300)
    cov = s2 * (eigvec[:, ~tiny] / eigval[~tiny]) @ eigvec[:, ~tiny].T
    if noise_known and predict_alt is not None:
        # the model's own Monte Carlo noise, one draw per value (r - r_alt) / sqrt(2), through the
        # sandwich: the data's noise alone would make a rendered model's errors too small
        d2 = 0.5 * (r - r_alt) ** 2
        cov = cov + cov @ ((J * d2[:, None]).T @ J) @ cov
    if tiny.any():
        touched = np.any(np.abs(eigvec[:, tiny]) > 1e-6, axis=1)
        cov[touched, :] = np.inf
        cov[:, touched] = np.inf
    at_bound = any(b.at_bound(float(v)) for b, v in zip(bounds, x))
    status = verdict(outcome.status, best_loss < loss0, at_bound, fit_goodness.misfit)
    return TableFit(names, x, np.sqrt(np.diag(cov)), cov, status, fit_goodness, r, outcome.steps)


@holding_lock("out_dir")
def write_table_fit(out_dir: str | Path, fit: TableFit, *, inputs: Mapping[str, Any] | None = None, overwrite: bool = False) -> Path:
    """Write ``fit.json`` (:meth:`TableFit.to_dict`, the package versions and, if given, the
    ``inputs``: names and JSON values) and ``report.txt`` (:meth:`TableFit.report`) into ``out_dir``
    all at once (on an error nothing is left behind), as an image fit's folder has them. The folder
    must be new or empty, or hold an earlier table fit and ``overwrite`` be given
    (:func:`~spacefit.output.prepare_output`); it is written holding its lock (:mod:`spacefit.locks`)."""
    check_type("fit", fit, TableFit, "an sf.TableFit")
    check_type("inputs", inputs, (Mapping, type(None)), "a dict of names and JSON values, or None")
    check_name_list("inputs", list(inputs or {}))
    try:
        json.dumps(dict(inputs or {}), allow_nan=False)
    except (TypeError, ValueError, RecursionError) as err:
        raise InputTypeError(f"`inputs` must hold JSON values (strings, finite numbers, lists, dicts): {err}; got {quote(inputs)}.") from None
    prepare_output(check_path("out_dir", out_dir), "table-fit", overwrite=check_flag("overwrite", overwrite))
    with staged_output(out_dir) as stage:
        write_json(stage / "fit.json", {**fit.to_dict(), "versions": versions(), **({"inputs": dict(inputs)} if inputs else {})})
        (stage / "report.txt").write_text(fit.report() + "\n", encoding="utf-8")
    return Path(out_dir)


def smallest_adequate(fits: Sequence[TableFit]) -> int | None:
    """The index of the first fit (give them smallest model first) that is not a misfit and converged:
    the smallest model that explains the data within their errors; None if none does (or the errors
    are unknown, when no fit has a verdict)."""
    for i, f in enumerate(fits):
        if f.goodness.noise_known and f.status.success:
            return i
    return None

