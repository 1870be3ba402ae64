"""Measured BRDF tables (goniometer data): reading them, the material models fitted to them, and a
table used as it is (:class:`TabulatedBRDF`, re-exported here). A table as an observation that :func:`fit`
fits, and the choice of the smallest model that fits, are :mod:`spacefit.fitting.observations.brdf`'s.
The tables are read by :mod:`spacefit.materials.measured` (the file formats are described there);
a table used as it is is a material of its own (:mod:`spacefit.materials.tabulated`).

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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import jax
import numpy as np

from spacefit.errors import check_range
from spacefit.materials import MODELS, Conductor, DiffuseConductor, Lambert, Material, MaterialModel
from spacefit.materials.measured import BRDFTable, unit_vectors
from spacefit.materials.registry import Derived, shared_fields

# The parameters' default starts in a fit: the registered models' fields' (their ranges are the registry's).
DEFAULT_START: Mapping[str, float] = Derived(lambda: {n: f.start for n, f in shared_fields(None).items()})


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
    """The conductor families by their short names, then every other registered model that has a BRDF
    (one read from a file, a measured table, is one surface, not a family to fit)."""
    out = {"lambert": BRDFModel("lambert", Lambert, ("kd",))}
    for aniso in (False, True):
        for diffuse in (False, True):
            for dist in ("ggx", "beckmann"):
                name = f"{'lambert+' if diffuse else ''}{dist}{'_aniso' if aniso else ''}"
                params = (*(("kd",) if diffuse else ()), "eta", "k", *(("alpha_x", "alpha_y") if aniso else ("alpha",)))
                out[name] = BRDFModel(name, DiffuseConductor if diffuse else Conductor, params, (("distribution", dist),))
    for m in MODELS.values():
        if not m.delta and not m.paths and m not in (Lambert, Conductor, DiffuseConductor):
            out[m.name] = BRDFModel(m.name, m, tuple(f.name for f in m.fields))
    return dict(sorted(out.items(), key=lambda item: len(item[1].parameters)))


#: The material models a BRDF table is fitted with (:func:`fit_brdf_table`, :func:`compare_brdf_models`)
#: by name, smallest (fewest parameters) first: Lambert, the conductors (GGX or Beckmann, isotropic or
#: anisotropic, with or without a diffuse term) and every other model registered with a BRDF
#: (:func:`register_material`), a model registered later among them.
#:
#: Example:
#:     >>> import spacefit as sf
#:     >>> list(sf.BRDF_MODELS)[:4]
#:     ['lambert', 'oren_nayar', 'ggx', 'beckmann']
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



