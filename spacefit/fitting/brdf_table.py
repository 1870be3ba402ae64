"""Measured BRDF tables (goniometer data): reading them, the material models fitted to them, and a
table used as it is (:class:`TabulatedBRDF`). A table as an observation that :func:`spacefit.fit`
fits, and the choice of the smallest model that fits, are :mod:`spacefit.fitting.observations.brdf`'s.

Two file formats, both text with ``#`` comment lines, angles in degrees (radians inside), the BRDF
in sr^-1:

* the general format, a CSV file whose header names its columns: ``theta_i_deg, phi_i_deg,
  theta_o_deg, phi_o_deg, brdf_sr`` and optionally ``sigma_sr`` (each value's standard error).
  theta is the zenith angle from the surface normal (0 to 90), phi the azimuth in the surface's
  plane from its x axis (the tangent along which a conductor's ``alpha_x`` lies) towards y; ``_i``
  is the direction towards the light, ``_o`` towards the detector.
* the Scatterworks / lumos-sat format of the Starlink tables (Fankhauser, Askari & Tyson 2023, AJ
  166:59): five unnamed columns ``phi_i theta_i phi_o theta_o brdf`` with phi the zenith and theta
  the azimuth of the same two directions; a negative zenith is the direction on the far side of the
  normal (azimuth + 180 deg), as lumos-sat reads it (its ``spherical_to_unit``).

A direction (zenith z, azimuth a) is the unit vector (sin z cos a, sin z sin a, cos z) in the
surface's frame. Rows at or beyond grazing (|zenith| >= 90 deg, where the BRDF is undefined) are
dropped on reading, as are values at or below ``floor`` (an instrument's noise floor).

The models (:data:`BRDF_MODELS`, smallest first) are spacefit's materials with grey values:
``lambert`` (kd), the rough conductors ``ggx`` / ``beckmann`` (eta, k, alpha) and their anisotropic
forms (alpha_x, alpha_y), each conductor plus a diffuse term (``lambert+ggx``: a
:class:`~spacefit.materials.DiffuseConductor`), and every other registered material model under its
own name with all its fields (``oren_nayar``: kd, sigma). They are evaluated by the models' own
BRDFs (:meth:`spacefit.materials.model.MaterialModel.evaluate`), Mitsuba's own evaluation; their
bounds and starts are the models' fields'. The fit compares logarithms
(the values span the specular peak to the diffuse floor, five decades): the residual is
ln(model / data) / sigma_rel, sigma_rel = sigma / value, or the ``relative_error`` given for a table
without errors; with neither, the errors are scaled by the residuals and no verdict is given.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, check_array, check_range, check_type, quote, read_text_rows
from spacefit.fitting.params import Bijection
from spacefit.materials import MODELS, Conductor, DiffuseConductor, Lambert, Material, MaterialModel
from spacefit.materials.registry import Derived, shared_fields
from spacefit.precision import float64

GENERAL_COLUMNS = ("theta_i_deg", "phi_i_deg", "theta_o_deg", "phi_o_deg", "brdf_sr")
# The parameters' ranges in a fit and their default starts: the registered models' fields' (open ranges).
PARAMETER_BOUNDS: Mapping[str, Bijection] = Derived(lambda: {n: Bijection(f.lo, f.hi) for n, f in shared_fields(None).items()})
DEFAULT_START: Mapping[str, float] = Derived(lambda: {n: f.start for n, f in shared_fields(None).items()})


@dataclass(frozen=True)
class BRDFTable:
    """Measured BRDF values.

    Attributes:
        wi, wo: (n, 3) unit directions towards the light and the detector in the surface's frame.
        value: (n,) the BRDF, sr^-1.
        sigma: (n,) its standard errors, sr^-1, or None (not stated).
        source: where it came from (a path), for messages.
    """

    wi: np.ndarray
    wo: np.ndarray
    value: np.ndarray
    sigma: np.ndarray | None
    source: str

    def __post_init__(self) -> None:
        check_type("source", self.source, str, "a string")
        value = check_array("value", self.value).astype(float)
        if value.ndim != 1 or not np.all(np.isfinite(value)) or np.any(value < 0):
            raise InputError(f"`value` must be a vector of finite BRDF values >= 0 sr^-1, got {quote(self.value)}.")
        for name in ("wi", "wo"):
            w = check_array(name, getattr(self, name)).astype(float)
            if w.shape != (len(value), 3) or not np.all(np.isfinite(w)):
                raise InputError(f"`{name}` must be ({len(value)}, 3) finite directions (one per value), got shape {w.shape}.")
            with np.errstate(over="ignore"):
                norm = np.linalg.norm(w, axis=1)
            if not np.allclose(norm, 1.0, atol=1e-6):
                raise InputError(f"`{name}` must hold unit vectors, got lengths {quote(np.linalg.norm(w, axis=1))}.")
            object.__setattr__(self, name, w)
        object.__setattr__(self, "value", value)
        if self.sigma is not None:
            sigma = check_array("sigma", self.sigma).astype(float)
            if sigma.shape != value.shape or not np.all(np.isfinite(sigma) & (sigma > 0)):
                raise InputError(f"`sigma` must be None or {len(value)} positive finite errors (sr^-1), got {quote(self.sigma)}.")
            object.__setattr__(self, "sigma", sigma)

    def __len__(self) -> int:
        return len(self.value)


def unit_vectors(zenith_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    """(n, 3) unit vectors of zenith and azimuth angles (deg; a negative zenith is on the far side)."""
    z, a = np.radians(zenith_deg), np.radians(azimuth_deg)
    return np.stack([np.sin(z) * np.cos(a), np.sin(z) * np.sin(a), np.cos(z)], axis=-1)


def read_brdf_table(path: str | Path, *, floor: float = 0.0) -> BRDFTable:
    """Read a BRDF table in the general format or the Starlink (lumos-sat) format (module docstring),
    dropping grazing rows and values at or below ``floor`` (sr^-1).

    Raises:
        InputError: an unreadable row, missing columns, a negative BRDF or error, nothing left.
        OSError: the file cannot be read.
    """
    check_range("floor", floor, 0.0, unit="sr^-1")
    rows = read_text_rows("path", path, "BRDF table")
    path = Path(path)
    if not rows:
        raise InputError(f"BRDF table {path}: no data rows.")
    header = [h.strip() for h in rows[0].split(",")]
    if all(_is_number(h) for h in rows[0].replace(",", " ").split()):
        numbers = _numbers(path, rows, 5)
        wi, wo = unit_vectors(numbers[:, 0], numbers[:, 1]), unit_vectors(numbers[:, 2], numbers[:, 3])
        zenith = np.abs(numbers[:, [0, 2]])
        value, sigma = numbers[:, 4], None
    else:
        missing = [c for c in GENERAL_COLUMNS if c not in header]
        if missing:
            raise InputError(f"BRDF table {path}: the header {header} lacks {missing}; the general format's columns are "
                             f"{', '.join(GENERAL_COLUMNS)} (and optionally sigma_sr).")
        table = list(csv.DictReader(rows))
        names = [*GENERAL_COLUMNS, *(["sigma_sr"] if "sigma_sr" in header else [])]
        numbers = _numbers(path, [",".join(r[c] or "" for c in names) for r in table], len(names))
        wi, wo = unit_vectors(numbers[:, 0], numbers[:, 1]), unit_vectors(numbers[:, 2], numbers[:, 3])
        zenith = numbers[:, [0, 2]]
        if np.any((zenith < 0) | (zenith > 90)):
            raise InputError(f"BRDF table {path}: theta_i_deg and theta_o_deg must lie in [0, 90] deg (zenith from the normal).")
        value = numbers[:, 4]
        sigma = numbers[:, 5] if len(names) == 6 else None
        if sigma is not None and np.any(sigma <= 0):
            raise InputError(f"BRDF table {path}: sigma_sr must be positive, row {int(np.argmax(sigma <= 0)) + 1} has {sigma[sigma <= 0][0]:g}.")
    if np.any(value < 0):
        raise InputError(f"BRDF table {path}: a BRDF is never negative, row {int(np.argmax(value < 0)) + 1} has {value[value < 0][0]:g} sr^-1.")
    keep = np.all(zenith < 90.0, axis=1) & (value > floor)
    if not keep.any():
        raise InputError(f"BRDF table {path}: no value above the floor {floor:g} sr^-1 away from grazing.")
    return BRDFTable(wi[keep], wo[keep], value[keep], None if sigma is None else sigma[keep], str(path))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _numbers(path: Path, rows: Sequence[str], columns: int) -> np.ndarray:
    if not rows:
        raise InputError(f"BRDF table {path}: no data rows.")
    out = []
    for i, row in enumerate(rows):
        fields = row.replace(",", " ").split()
        if len(fields) != columns or not all(_is_number(f) for f in fields):
            raise InputError(f"BRDF table {path}: data row {i + 1} must hold {columns} numbers, got {row.strip()!r}.")
        out.append([float(f) for f in fields])
    values = np.array(out, dtype=float)
    if not np.all(np.isfinite(values)):
        raise InputError(f"BRDF table {path}: every value must be finite.")
    return values


@dataclass(frozen=True)
class BRDFModel:
    """A material model to fit: the registered ``model`` with its ``options`` (a conductor's
    ``distribution``), its free ``parameters`` its fields' names or ties (``alpha``), in order."""

    name: str
    model: type[MaterialModel]
    parameters: tuple[str, ...]
    options: tuple[tuple[str, object], ...] = ()

    def values(self, p: Mapping[str, jax.Array]) -> dict[str, jax.Array]:
        """The model's field values of the parameter values ``p`` (by name; a tie sets its fields)."""
        out: dict[str, jax.Array] = {}
        for name in self.parameters:
            out.update(dict.fromkeys(self.model.ties[name][0] if name in self.model.ties else (name,), p[name]))
        return out

    def evaluate(self, p: Mapping[str, jax.Array], wi: jax.Array, wo: jax.Array) -> jax.Array:
        """The BRDF (sr^-1) at parameter values ``p`` (by name) for local directions ``wi``, ``wo`` (n, 3)."""
        template = self.model(**{f.name: f.start for f in self.model.fields}, **dict(self.options))
        return template.evaluate(wi, wo, self.values(p))

    def material(self, p: Mapping[str, float]) -> Material:
        """The spacefit material of these parameter values (by name): what the renderer draws."""
        return self.model(**{k: float(v) for k, v in self.values(p).items()}, **dict(self.options))


def _models() -> dict[str, BRDFModel]:
    """The conductor families by their short names, then every other registered model that has a BRDF."""
    out = {"lambert": BRDFModel("lambert", Lambert, ("kd",))}
    for aniso in (False, True):
        for diffuse in (False, True):
            for dist in ("ggx", "beckmann"):
                name = f"{'lambert+' if diffuse else ''}{dist}{'_aniso' if aniso else ''}"
                params = (*(("kd",) if diffuse else ()), "eta", "k", *(("alpha_x", "alpha_y") if aniso else ("alpha",)))
                out[name] = BRDFModel(name, DiffuseConductor if diffuse else Conductor, params, (("distribution", dist),))
    for m in MODELS.values():
        if not m.delta and m not in (Lambert, Conductor, DiffuseConductor):
            out[m.name] = BRDFModel(m.name, m, tuple(f.name for f in m.fields))
    return dict(sorted(out.items(), key=lambda item: len(item[1].parameters)))


# The models by name, smallest (fewest parameters) first; a model registered later is among them.
BRDF_MODELS: Mapping[str, BRDFModel] = Derived(_models)


def simulate_brdf_table(material: Material, zenith_i_deg: Sequence[float], zenith_o_deg: Sequence[float],
                        azimuth_o_deg: Sequence[float] = (0.0,), *, relative_error: float = 0.0, seed: int = 0) -> BRDFTable:
    """A table of ``material``'s BRDF at every combination of incident zenith (azimuth 180 deg) and
    outgoing zenith and azimuth, with multiplicative Gaussian noise of ``relative_error`` (stated
    as each value's sigma when positive)."""
    check_range("relative_error", relative_error, 0.0, 1.0)
    zi, zo, ao = np.meshgrid(np.asarray(zenith_i_deg, float), np.asarray(zenith_o_deg, float), np.asarray(azimuth_o_deg, float),
                             indexing="ij")
    wi = unit_vectors(zi.ravel(), np.full(zi.size, 180.0))
    wo = unit_vectors(zo.ravel(), ao.ravel())
    value = np.array(jax.jit(material.evaluate)(wi, wo), dtype=float)
    value *= np.exp(relative_error * np.random.default_rng(seed).standard_normal(value.size))
    keep = value > 0
    sigma = relative_error * value[keep] if relative_error > 0 else None
    return BRDFTable(wi[keep], wo[keep], value[keep], sigma, f"simulated {type(material).__name__}")



@dataclass(frozen=True, eq=False)
class TabulatedBRDF:
    """A measured in-plane BRDF table used as it is, as a flat plate's material (:class:`sf.Plate`).

    A goniometer's table in the plane of incidence gives, at each incident zenith theta_i, the BRDF
    along one line of outgoing directions. Off that plane it is extended the way the published
    Starlink model extends it (Fankhauser, Askari & Tyson 2023: lumos-sat's ``BINOMIAL`` and ``ABG``
    models depend on the outgoing direction through ``D = |beta - beta_0|`` alone), by Harvey's
    shift-invariance in direction cosines (Harvey 1976): beta = the outgoing direction projected
    onto the surface, beta_0 = the specular direction's, and the BRDF a function of theta_i and the
    signed offset ``u = sign((beta - beta_0) . beta_0) |beta - beta_0|`` (positive away from the normal
    beyond the specular direction, negative towards backscatter). ln f is interpolated linearly in
    u between the measured offsets of each incidence and linearly in theta_i between incidences,
    held at the end values beyond both; ``scale`` multiplies it (1: the table's values). Both
    sides of the plate alike, 0 where sun and observer are on opposite sides, as the materials'
    BRDFs (:func:`spacefit.materials.brdf.brdf`). Isotropic: the plate's tangent does not
    matter. Not a renderer material: it serves the flat-plate light curves only. ln f is piecewise
    linear in the angles: a fit of directions through it (an attitude) sees one segment's slope at a
    time and may stop at a kink (a simulated 6 deg turn about z with a tabulated array came back 7.1
    +- 0.05 deg; with a GGX array, 5.7 +- 0.3); its ``scale`` enters linearly and fits cleanly.

    Attributes:
        incidence_rad: (K,) the measured incident zeniths, increasing.
        offset: K arrays of the measured offsets u at each incidence, increasing.
        log_value: K arrays of ln f (f in sr^-1) at those offsets.
        source: where the table came from.
        scale: the factor on the table's values.
    """

    incidence_rad: np.ndarray
    offset: tuple[np.ndarray, ...]
    log_value: tuple[np.ndarray, ...]
    source: str
    scale: float = 1.0

    def __post_init__(self) -> None:
        check_type("source", self.source, str, "a string")
        check_range("scale", self.scale, 0.0, lo_open=True)
        grid = check_array("incidence_rad", self.incidence_rad).astype(float)
        if grid.ndim != 1 or not len(grid) or np.any(~np.isfinite(grid)) or np.any(np.diff(grid) <= 0) or grid[0] < 0 or grid[-1] >= np.pi / 2:
            raise InputError(f"`incidence_rad` must be increasing zeniths in [0, pi/2) rad, got {quote(self.incidence_rad)}.")
        lines = []
        for name in ("offset", "log_value"):
            value = getattr(self, name)
            if not isinstance(value, (tuple, list)) or len(value) != len(grid):
                raise InputError(f"`{name}` must hold one array per incidence ({len(grid)}), got {quote(value)}.")
            lines.append([check_array(f"{name}[{k}]", v).astype(float) for k, v in enumerate(value)])
        for k, (x, y) in enumerate(zip(*lines)):
            if x.ndim != 1 or x.shape != y.shape or len(x) < 2 or not np.all(np.isfinite(x) & np.isfinite(y)) or np.any(np.diff(x) <= 0):
                raise InputError(f"`offset[{k}]` and `log_value[{k}]` must be two or more finite values each, the offsets "
                                 f"increasing, got {quote(x)} and {quote(y)}.")
        object.__setattr__(self, "incidence_rad", grid)
        object.__setattr__(self, "offset", tuple(lines[0]))
        object.__setattr__(self, "log_value", tuple(lines[1]))

    @classmethod
    @float64
    def from_table(cls, table: BRDFTable, scale: float = 1.0) -> TabulatedBRDF:
        """The tabulated BRDF of ``table``, whose every row must lie in its plane of incidence, away
        from normal incidence (where that plane is undefined), with two or more offsets per incidence."""
        check_type("table", table, BRDFTable, "an sf.BRDFTable (sf.read_brdf_table)")
        wi, wo, value = table.wi, table.wo, table.value
        across = np.abs(wi[:, 0] * wo[:, 1] - wi[:, 1] * wo[:, 0])
        beta0 = np.linalg.norm(wi[:, :2], axis=1)
        if np.any(across > 1e-6) or np.any(beta0 < 1e-6) or np.any(value <= 0):
            bad = int(np.argmax((across > 1e-6) | (beta0 < 1e-6) | (value <= 0)))
            raise InputError(f"BRDF table {table.source}: a tabulated BRDF needs positive values in the plane of incidence away "
                             f"from normal incidence; row {bad + 1} (wi {tuple(np.round(wi[bad], 6))}, wo {tuple(np.round(wo[bad], 6))}, "
                             f"{value[bad]:g} sr^-1) is not.")
        u = np.asarray(signed_offset(wi, wo))
        theta = np.round(np.arccos(np.clip(wi[:, 2], -1.0, 1.0)), 9)
        incidences, offsets, logs = np.unique(theta), [], []
        for t in incidences:
            rows = theta == t
            x, where = np.unique(u[rows], return_inverse=True)
            if len(x) < 2:
                raise InputError(f"BRDF table {table.source}: the incidence {np.degrees(t):.4g} deg has {len(x)} distinct outgoing "
                                 "direction; a tabulated BRDF needs two or more per incidence.")
            offsets.append(x)
            logs.append(np.bincount(where, np.log(value[rows])) / np.bincount(where))
        return cls(incidences, tuple(offsets), tuple(logs), table.source, scale)

    def evaluate(self, wi: jax.Array, wo: jax.Array, scale: jax.Array | float | None = None) -> jax.Array:
        """f_r (sr^-1) for local unit directions ``wi``, ``wo`` (..., 3) (class docstring); ``scale``
        replaces the table's (JAX-traceable: what a fit varies)."""
        wi, wo = jnp.asarray(wi, dtype=float), jnp.asarray(wo, dtype=float)
        back = (wi[..., 2] < 0)[..., None]
        flip = jnp.array([1.0, 1.0, -1.0])
        wi, wo = jnp.where(back, wi * flip, wi), jnp.where(back, wo * flip, wo)
        front = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        u = signed_offset(wi, wo)
        theta = jnp.arccos(jnp.clip(wi[..., 2], -1.0, 1.0))
        grid = jnp.asarray(self.incidence_rad)
        log_f = jnp.zeros(jnp.shape(u))
        for k, (x, y) in enumerate(zip(self.offset, self.log_value)):
            weight = jnp.interp(theta, grid, jnp.eye(len(grid))[k]) if len(grid) > 1 else 1.0
            log_f = log_f + weight * jnp.interp(u, jnp.asarray(x), jnp.asarray(y))
        return jnp.where(front, (self.scale if scale is None else scale) * jnp.exp(log_f), 0.0)


def signed_offset(wi: jax.Array | np.ndarray, wo: jax.Array | np.ndarray) -> jax.Array:
    """Harvey's signed offset u of the outgoing direction from the specular one in direction cosines
    (:class:`TabulatedBRDF`): |beta - beta_0| signed by (beta - beta_0) . beta_0, for local unit
    directions (..., 3); positive at normal incidence."""
    beta0 = -wi[..., :2]
    delta = wo[..., :2] - beta0
    d2 = jnp.sum(delta**2, axis=-1)
    d = jnp.where(d2 > 0, jnp.sqrt(jnp.where(d2 > 0, d2, 1.0)), 0.0)
    return jnp.where(jnp.sum(delta * beta0, axis=-1) < 0, -d, d)
