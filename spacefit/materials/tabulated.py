"""A measured in-plane BRDF table used as it is: the material model ``tabulated`` (:class:`TabulatedBRDF`).

A goniometer's table in the plane of incidence gives, at each incident zenith theta_i, the BRDF
along one line of outgoing directions. Off that plane it is extended the way the published
Starlink model extends it (Fankhauser, Askari & Tyson 2023, AJ 166:59: lumos-sat's ``BINOMIAL``
and ``ABG`` models depend on the outgoing direction through ``D = |beta - beta_0|`` alone), by
Harvey's shift-invariance in direction cosines (Harvey 1976): beta = the outgoing direction
projected onto the surface, beta_0 = the specular direction's, and the BRDF a function of theta_i
and the signed offset ``u = sign((beta - beta_0) . beta_0) |beta - beta_0|`` (:func:`signed_offset`:
positive away from the normal beyond the specular direction, negative towards backscatter). ln f
is interpolated linearly in u between the measured offsets of each incidence and linearly in
theta_i between incidences, held at the end values beyond both; ``scale`` multiplies it (1: the
table's values). The renderer evaluates the same interpolation in Dr.Jit
(:func:`spacefit.rendering.materials.tabulated_plugin`).

A scene file names it by its table's file (read by :func:`read_brdf_table`,
relative to the scene file's folder)::

    [parts.chassis]
    material = "tabulated"
    source = "chassis_brdf.csv"
    scale = 1.0
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from spacefit.errors import InputError, check_array, check_type, quote
from spacefit.materials.measured import BRDFTable, read_brdf_table
from spacefit.materials.model import Field, MaterialModel
from spacefit.precision import float64

if TYPE_CHECKING:
    from jaxtyping import Array

SCALE = Field("scale", "1", 0.0, float("inf"), 1.0, "the factor on a measured BRDF table's values (a tabulated material)",
              "table factor", lo_open=True)


def signed_offset(wi: Array | np.ndarray, wo: Array | np.ndarray) -> Array:
    """Harvey's signed offset u of the outgoing direction from the specular one in direction cosines
    (module docstring): |beta - beta_0| signed by (beta - beta_0) . beta_0, for local unit
    directions (..., 3) towards the light (``wi``) and the detector (``wo``); positive at normal incidence."""
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
    beta0 = -wi[..., :2]
    delta = wo[..., :2] - beta0
    d2 = jnp.sum(delta**2, axis=-1)
    d = jnp.where(d2 > 0, jnp.sqrt(jnp.where(d2 > 0, d2, 1.0)), 0.0)
    return jnp.where(jnp.sum(delta * beta0, axis=-1) < 0, -d, d)


@dataclass(frozen=True, eq=False)
class TabulatedBRDF(MaterialModel):
    """A measured in-plane BRDF table used as it is (the guide "BRDF tables and light curves as observations"), the material ``tabulated``
    of any part and of a flat plate (:class:`sf.Plate`). Both sides alike, 0 where sun and observer
    are on opposite sides, as every material's BRDF.
    Isotropic: the part's tangent does not matter. Built from a table's file (``source`` alone,
    as a scene file names it), from a read table (:meth:`from_table`) or from its arrays. ln f is
    piecewise linear in the angles: a fit of directions through it (an attitude) sees one segment's
    slope at a time and may stop at a kink (a simulated 6 deg turn about z with a tabulated array
    came back 7.1 +- 0.05 deg; with a GGX array, 5.7 +- 0.3); its ``scale`` enters linearly and fits cleanly.

    Attributes:
        incidence_rad: (K,) the measured incident zeniths, increasing (None: read from ``source``).
        offset: K arrays of the measured offsets u at each incidence, increasing.
        log_value: K arrays of ln f (f in sr^-1) at those offsets.
        source: where the table came from: its file, or a description of a table made otherwise.
        scale: the factor on the table's values.

    Raises:
        InputError: incidences not increasing or outside [0, 90) deg, offsets not increasing, fewer
            than two offsets at an incidence, arrays of different lengths, a non-positive ``scale``.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> offsets = (np.array([-0.5, 0.0, 0.5]), np.array([-0.5, 0.0, 0.5]))
        >>> table = sf.TabulatedBRDF(incidence_rad=np.radians([10.0, 40.0]), offset=offsets,
        ...                          log_value=(np.log([0.1, 0.5, 0.1]), np.log([0.1, 0.4, 0.1])), source="example")
        >>> mirror = np.array([-np.sin(0.2), 0.0, np.cos(0.2)])  # the specular direction of a light at 0.2 rad
        >>> round(float(table.evaluate(np.array([np.sin(0.2), 0.0, np.cos(0.2)]), mirror)), 3)  # sr^-1
        0.495
    """

    name: ClassVar[str] = "tabulated"
    fields: ClassVar[tuple[Field, ...]] = (SCALE,)
    paths: ClassVar[tuple[str, ...]] = ("source",)

    incidence_rad: np.ndarray | None = dataclasses.field(default=None, metadata={"derived": True})
    offset: tuple[np.ndarray, ...] | None = dataclasses.field(default=None, metadata={"derived": True})
    log_value: tuple[np.ndarray, ...] | None = dataclasses.field(default=None, metadata={"derived": True})
    source: str = ""
    scale: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_type("source", self.source, str, "a string")
        if self.incidence_rad is None:
            if not self.source:
                raise InputError("`source` is missing: a tabulated material names its BRDF table's file (sf.read_brdf_table's formats).")
            read = TabulatedBRDF.from_table(read_brdf_table(self.source))
            for name in ("incidence_rad", "offset", "log_value"):
                object.__setattr__(self, name, getattr(read, name))
            return
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

    def __eq__(self, other: object) -> bool:
        """Equal tables: the same source and scale and the same arrays (compared by value)."""
        if type(other) is not type(self):
            return NotImplemented
        mine, theirs = self._arrays(), other._arrays()
        return ((self.source, self.scale) == (other.source, other.scale) and len(mine) == len(theirs)
                and all(np.array_equal(x, y) for x, y in zip(mine, theirs)))

    def __hash__(self) -> int:
        return hash((self.source, self.scale))

    def _arrays(self) -> tuple[np.ndarray, ...]:
        """The table's arrays in one tuple: the incidences, then each incidence's offsets, then its ln f."""
        return (np.asarray(self.incidence_rad), *(self.offset or ()), *(self.log_value or ()))

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """scale exp(ln f(theta_i, u)), the table's interpolation (the guide "BRDF tables and light curves as observations"), for front-side
        directions towards the light (``wi``) and the detector (``wo``): not reciprocal."""
        import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
        u = signed_offset(wi, wo)
        theta = jnp.arccos(jnp.clip(wi[..., 2], -1.0, 1.0))
        grid = jnp.asarray(self.incidence_rad)
        log_f = jnp.zeros(jnp.shape(u))
        for k, (x, y) in enumerate(zip(self.offset, self.log_value)):
            weight = jnp.interp(theta, grid, jnp.eye(len(grid))[k]) if len(grid) > 1 else 1.0
            log_f = log_f + weight * jnp.interp(u, jnp.asarray(x), jnp.asarray(y))
        return values["scale"] * jnp.exp(log_f)
