"""Material models in Mitsuba 3: one table entry per model, its BSDF and its parameters' traverse keys.

Each entry (:class:`MitsubaMaterial`) gives a model's one-sided Mitsuba BSDF dictionary and, per
field, the traverse keys it sets relative to the part's BSDF and how its value is written there
(``reflectance`` as an RGB of the value, a blend's halves doubled). :func:`bsdf_dict` wraps every
BSDF in Mitsuba's ``twosided``: the thesis's renderer, pbrt-v3, shades the back of a face as its
front (its BSDFs flip the shading frame to the side of the outgoing ray), so a folded or
inward-wound face is lit, not black. ``twosided`` names the BSDF it shades both sides with
``brdf_0`` (:func:`bsdf_key`). A model is added by :func:`register_mitsuba`; a model Mitsuba lacks
brings its own plugin (``plugin``), registered once per variant before its first load.

Mitsuba 3 has no Oren-Nayar BSDF: :func:`oren_nayar_plugin` is a Python ``mi.BSDF``
(:mod:`spacefit.materials.oren_nayar`'s qualitative model, cosine-weighted hemisphere sampling),
differentiable in its ``reflectance`` and ``sigma``; nor a measured table's: :func:`tabulated_plugin`
(:mod:`spacefit.materials.tabulated`'s interpolation, the table's arrays given as tensors),
differentiable in its ``scale``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.materials import Conductor, DiffuseConductor, Lambert, Material, Mirror, OrenNayar, TabulatedBRDF
from spacefit.rendering.backend import dr, mi

if TYPE_CHECKING:
    from jaxtyping import Array

# How a parameter's value (grey, JAX) is written to its traverse key.
Write = Callable[["Array"], "Array"]


def scalar(x: Array) -> Array:
    """The value itself (a grey Mitsuba parameter)."""
    return x


def rgb(x: Array) -> Array:
    """The value in every RGB channel (an ``rgb`` texture's value)."""
    import jax.numpy as jnp  # deferred: only a fit's scene values need JAX, a render does not

    return jnp.full(3, x)


def rgb_doubled(x: Array) -> Array:
    """Twice the value in every RGB channel (one half of a ``blendbsdf`` at weight 0.5)."""
    return rgb(2.0 * x)


@dataclass(frozen=True)
class MitsubaMaterial:
    """A material model's Mitsuba form.

    Attributes:
        bsdf: the one-sided BSDF dictionary of a material of the model.
        keys: per field, its (traverse key relative to the part's BSDF, write) pairs.
        plugin: registers the model's own Mitsuba plugin in the current variant (None: built in).
    """

    bsdf: Callable[[Any], dict]
    keys: Mapping[str, tuple[tuple[str, Write], ...]]
    plugin: Callable[[], None] | None = None


MITSUBA: dict[type, MitsubaMaterial] = {}
_plugins_loaded: set[tuple[type, str]] = set()


def register_mitsuba(model: type, entry: MitsubaMaterial) -> None:
    """Add (or replace) the Mitsuba entry of a material model."""
    MITSUBA[model] = entry


def _entry(material: Material) -> MitsubaMaterial:
    if type(material) not in MITSUBA:
        raise TypeError(f"no Mitsuba BSDF for {type(material).__name__}: register one with register_mitsuba")
    return MITSUBA[type(material)]


def bsdf_dict(material: Material) -> dict:
    """Mitsuba BSDF for a material, shading both sides of every face alike (``twosided``, module
    docstring); a model's own plugin is registered first (in the current variant). Traverse keys:
    :func:`material_keys`."""
    entry = _entry(material)
    if entry.plugin is not None and (type(material), mi.variant()) not in _plugins_loaded:
        entry.plugin()
        _plugins_loaded.add((type(material), mi.variant()))
    return {"type": "twosided", "bsdf": entry.bsdf(material)}


def bsdf_key(part: str, key: str) -> str:
    """Mitsuba traverse key of BSDF parameter ``key`` (``alpha_u``, ``reflectance``) of ``part``'s
    one-sided BSDF (inside ``twosided``'s ``brdf_0``)."""
    return f"{part}.bsdf.brdf_0.{key}.value"


def material_keys(part: str, material: Material, name: str) -> list[tuple[str, Write]]:
    """The traverse keys (and how each is written) that parameter ``parts.<part>.<name>`` sets in a
    part of ``material`` (a tie, ``alpha``, sets each of its fields')."""
    model = type(material)
    fields = model.ties[name][0] if name in model.ties else (name,)
    keys = _entry(material).keys
    return [(f"{part}.bsdf.brdf_0.{key}", write) for f in fields for key, write in keys.get(f, ())]


def _spectrum(value: float | tuple[float, ...]) -> dict | float:
    return {"type": "rgb", "value": list(value)} if isinstance(value, tuple) else float(value)


def _rgb_list(value: float | tuple[float, ...]) -> list[float]:
    return list(value) if isinstance(value, tuple) else [float(value)] * 3


def _conductor(m: Conductor | DiffuseConductor) -> dict:
    """Mitsuba's ``roughconductor``; the microfacet distribution always named (Mitsuba's default is Beckmann)."""
    return {"type": "roughconductor", "distribution": m.distribution, "alpha_u": m.alpha_x, "alpha_v": m.alpha_y,
            "eta": _spectrum(m.eta), "k": _spectrum(m.k)}


def _diffuse_conductor(m: DiffuseConductor) -> dict:
    """kd / pi + the conductor as 0.5 (2 kd / pi) + 0.5 (2 x the conductor): Mitsuba's blend is a mean."""
    return {"type": "blendbsdf", "weight": 0.5,
            "diffuse": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [2.0 * v for v in _rgb_list(m.kd)]}},
            "specular": {**_conductor(m), "specular_reflectance": 2.0}}


_CONDUCTOR_KEYS = {"eta": (("eta.value", scalar),), "k": (("k.value", scalar),), "alpha_x": (("alpha_u.value", scalar),),
                   "alpha_y": (("alpha_v.value", scalar),)}
register_mitsuba(Conductor, MitsubaMaterial(_conductor, _CONDUCTOR_KEYS))
register_mitsuba(Mirror, MitsubaMaterial(lambda m: {"type": "conductor", "eta": _spectrum(m.eta), "k": _spectrum(m.k)},
                                         {f: _CONDUCTOR_KEYS[f] for f in ("eta", "k")}))
register_mitsuba(Lambert, MitsubaMaterial(lambda m: {"type": "diffuse", "reflectance": {"type": "rgb", "value": _rgb_list(m.kd)}},
                                          {"kd": (("reflectance.value", rgb),)}))
register_mitsuba(DiffuseConductor, MitsubaMaterial(
    _diffuse_conductor, {"kd": (("bsdf_0.reflectance.value", rgb_doubled),),
                         **{f: tuple((f"bsdf_1.{key}", write) for key, write in keys) for f, keys in _CONDUCTOR_KEYS.items()}}))


def _cosine_sampled_bsdf() -> type:
    """The base (in the current variant) of spacefit's Python BSDFs: diffuse-flagged, front-side,
    sampled over the cosine-weighted hemisphere; a subclass gives ``eval`` and ``traverse``."""

    class CosineSampledBSDF(mi.BSDF):
        def __init__(self, props: Any) -> None:
            mi.BSDF.__init__(self, props)
            flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            front = (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
            on = front & active & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
            return dr.select(on, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

        def eval_pdf(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> tuple[Any, Any]:
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def sample(self, ctx: Any, si: Any, sample1: Any, sample2: Any, active: Any = True) -> tuple[Any, Any]:
            """A cosine-weighted hemisphere sample and its weight f cos / pdf."""
            bs = mi.BSDFSample3f()
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = mi.UInt32(0)
            on = active & (bs.pdf > 0) & (mi.Frame3f.cos_theta(si.wi) > 0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
            value = self.eval(ctx, si, bs.wo, on)
            bs.pdf = dr.select(on, bs.pdf, 0.0)
            return bs, dr.select(on, value / dr.select(on, bs.pdf, 1.0), 0.0)

    return CosineSampledBSDF


def oren_nayar_plugin() -> None:
    """Register the Python BSDF ``oren_nayar`` in the current Mitsuba variant: f_r cos(theta_o) of
    Oren & Nayar's qualitative model (:func:`spacefit.materials.oren_nayar.oren_nayar_brdf`, the same
    terms in Dr.Jit), cosine-weighted hemisphere sampling; ``reflectance`` (a texture) and ``sigma``
    (rad) are differentiable traverse parameters."""

    class OrenNayarBSDF(_cosine_sampled_bsdf()):
        def __init__(self, props: Any) -> None:
            super().__init__(props)
            self.reflectance = props.get_texture("reflectance")
            self.sigma = mi.Float(props["sigma"])

        def _value(self, si: Any, wo: Any) -> tuple[Any, Any]:
            """f_r / cos-weighted pdf ratio's numerator parts: (kd (A + B ...) / pi, front-side mask)."""
            cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
            s2 = dr.square(self.sigma)
            a = 1.0 - 0.5 * s2 / (s2 + 0.33)
            b = 0.45 * s2 / (s2 + 0.09)
            azimuthal = dr.maximum(0.0, si.wi.x * wo.x + si.wi.y * wo.y)
            f = self.reflectance.eval(si) * dr.inv_pi * (a + b * azimuthal / dr.maximum(cos_i, cos_o))
            return f, (cos_i > 0) & (cos_o > 0)

        def eval(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            f, front = self._value(si, wo)
            on = front & active & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
            return dr.select(on, f * mi.Frame3f.cos_theta(wo), 0.0)

        def traverse(self, callback: Any) -> None:
            callback.put("reflectance", self.reflectance, mi.ParamFlags.Differentiable)
            callback.put("sigma", self.sigma, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys: Any = None) -> None:
            """Nothing is precomputed: A and B are evaluated from sigma at each call."""

        def to_string(self) -> str:
            return f"OrenNayarBSDF[reflectance={self.reflectance}, sigma={self.sigma}]"

    mi.register_bsdf("oren_nayar", lambda props: OrenNayarBSDF(props))


register_mitsuba(OrenNayar, MitsubaMaterial(
    lambda m: {"type": "oren_nayar", "reflectance": {"type": "rgb", "value": _rgb_list(m.kd)}, "sigma": float(m.sigma)},
    {"kd": (("reflectance.value", rgb),), "sigma": (("sigma", scalar),)}, plugin=oren_nayar_plugin))


def tabulated_plugin() -> None:
    """Register the Python BSDF ``tabulated`` in the current Mitsuba variant: f_r cos(theta_o) of a
    measured table (:class:`spacefit.materials.tabulated.TabulatedBRDF`'s interpolation in Dr.Jit:
    per incidence a binary search among its offsets, linear weights between incidences), the light
    the direction ``wo`` and the detector ``si.wi`` (radiance transport: the table need not be
    reciprocal); cosine-weighted hemisphere sampling; ``scale`` a differentiable traverse parameter.
    Its properties: ``incidence``, (K,) zeniths (rad); ``offset`` and ``log_value``, the K lines
    concatenated; ``start``, (K + 1,) where each line starts in them (tensors)."""

    class TabulatedBSDF(_cosine_sampled_bsdf()):
        def __init__(self, props: Any) -> None:
            super().__init__(props)
            self.scale = mi.Float(props["scale"])
            self.incidence = [float(t) for t in props["incidence"].numpy()]
            self.start = [int(i) for i in props["start"].numpy()]
            self.offset = mi.Float(props["offset"].array)
            self.log_value = mi.Float(props["log_value"].array)

        def _line(self, k: int, u: Any) -> Any:
            """ln f of line k at offsets u: linear between its points, held at its ends."""
            lo, hi = self.start[k], self.start[k + 1]
            j = dr.binary_search(lo, hi - 2, lambda i: dr.gather(mi.Float, self.offset, i + 1) <= u)
            x0, x1 = dr.gather(mi.Float, self.offset, j), dr.gather(mi.Float, self.offset, j + 1)
            y0, y1 = dr.gather(mi.Float, self.log_value, j), dr.gather(mi.Float, self.log_value, j + 1)
            t = dr.clip((u - x0) / (x1 - x0), 0.0, 1.0)
            return dr.lerp(y0, y1, t)

        def _weight(self, k: int, theta: Any) -> Any:
            """The linear interpolation weight of incidence k at zenith theta (1 beyond the ends)."""
            grid, weight = self.incidence, mi.Float(0.0)
            if k > 0:
                rise = dr.clip((theta - grid[k - 1]) / (grid[k] - grid[k - 1]), 0.0, 1.0)
                weight = dr.select((theta > grid[k - 1]) & (theta <= grid[k]), rise, weight)
            else:
                weight = dr.select(theta <= grid[0], 1.0, weight)
            if k < len(grid) - 1:
                fall = dr.clip((grid[k + 1] - theta) / (grid[k + 1] - grid[k]), 0.0, 1.0)
                weight = dr.select((theta > grid[k]) & (theta < grid[k + 1]), fall, weight)
            else:
                weight = dr.select(theta > grid[-1], 1.0, weight)
            return weight

        def eval(self, ctx: Any, si: Any, wo: Any, active: Any = True) -> Any:
            light, detector = wo, si.wi
            beta0 = -mi.Vector2f(light.x, light.y)
            delta = mi.Vector2f(detector.x, detector.y) - beta0
            d = dr.norm(delta)
            u = dr.select(dr.dot(delta, beta0) < 0, -d, d)
            theta = dr.acos(dr.clip(mi.Frame3f.cos_theta(light), -1.0, 1.0))
            log_f = mi.Float(0.0)
            for k in range(len(self.incidence)):
                log_f += self._weight(k, theta) * self._line(k, u)
            front = (mi.Frame3f.cos_theta(light) > 0) & (mi.Frame3f.cos_theta(detector) > 0)
            on = front & active & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
            return dr.select(on, self.scale * dr.exp(log_f) * mi.Frame3f.cos_theta(light), 0.0)

        def traverse(self, callback: Any) -> None:
            callback.put("scale", self.scale, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys: Any = None) -> None:
            """Nothing is precomputed: the table is fixed, ``scale`` multiplies at each call."""

        def to_string(self) -> str:
            return f"TabulatedBSDF[{len(self.incidence)} incidences, scale={self.scale}]"

    mi.register_bsdf("tabulated", lambda props: TabulatedBSDF(props))


def _tabulated(m: TabulatedBRDF) -> dict:
    """The ``tabulated`` plugin's properties of a measured table (:func:`tabulated_plugin`)."""
    start = np.concatenate([[0], np.cumsum([len(x) for x in m.offset])])
    return {"type": "tabulated", "scale": float(m.scale), "incidence": mi.TensorXf(np.asarray(m.incidence_rad)),
            "start": mi.TensorXf(start.astype(float)), "offset": mi.TensorXf(np.concatenate(m.offset)),
            "log_value": mi.TensorXf(np.concatenate(m.log_value))}


register_mitsuba(TabulatedBRDF, MitsubaMaterial(_tabulated, {"scale": (("scale", scalar),)}, plugin=tabulated_plugin))
