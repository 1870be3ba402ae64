"""How a material model declares itself: its fields, its BRDF and its level-of-detail rule.

A model is a frozen dataclass deriving from :class:`MaterialModel`. Its :data:`~MaterialModel.fields`
(:class:`Field`) are the one home of each value's unit, range, start, label and whether it may be
RGB: construction checks them, and the parameter table (``parts.P.<field>``,
:mod:`spacefit.scene.parameters`), the BRDF-table fits (:mod:`spacefit.fitting.brdf_table`) and the
flat plates' fits (:mod:`spacefit.studies.plate_fit`) take their bounds from them. Its
:meth:`~MaterialModel.f_r` is its BRDF in JAX under the paper's names, for one grey channel and
front-side directions; :meth:`~MaterialModel.evaluate` wraps it the way the renderer wraps every
BSDF (Mitsuba's ``twosided``) and averages the RGB channels. :meth:`~MaterialModel.effective` is its
level-of-detail rule (:class:`WrinkleSettings`' ``lod``). A model is added by
:func:`register_material`; its rendering backends' entries live in
:mod:`spacefit.rendering` (docs/reference/development.md, "Adding a material model").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, TYPE_CHECKING, Union


from spacefit.errors import InputError, check_range

if TYPE_CHECKING:
    from jaxtyping import Array

Spectrum = Union[float, tuple[float, float, float]]


@dataclass(frozen=True)
class Field:
    """One numeric value of a material model.

    Attributes:
        name: its name in the model, the scene file and the parameter table (``parts.P.<name>``).
        unit: its SI unit ("1": dimensionless; "rad" for angles).
        lo, hi: its range; a fit moves in the open interval (lo, hi), a stated value may reach a
            bound unless ``lo_open`` / ``hi_open``.
        start: a fit's default start, inside (lo, hi).
        doc: what it is, in a sentence (the parameter table's text).
        label: what it is in a few words, for axes and tables.
        spectral: whether it may be RGB (a 3-tuple) as well as grey.
        lo_open, hi_open: whether a stated value may not reach the bound.
    """

    name: str
    unit: str
    lo: float
    hi: float
    start: float
    doc: str
    label: str
    spectral: bool = False
    lo_open: bool = False
    hi_open: bool = False

    def check(self, value: object) -> Any:
        """``value`` checked against the field (finite, in range; grey, or RGB where spectral), as floats."""
        values = value if self.spectral and isinstance(value, (tuple, list)) else (value,)
        if len(values) not in (1, 3):
            raise InputError(f"`{self.name}` must be one number or 3 (RGB), got {value!r}.")
        checked = tuple(check_range(self.name, v, self.lo, self.hi, lo_open=self.lo_open, hi_open=self.hi_open,
                                    unit="" if self.unit == "1" else self.unit) for v in values)
        return checked[0] if len(checked) == 1 else checked


def channel(value: Any, c: int) -> Any:
    """Channel ``c`` of a grey or RGB value (a grey value is every channel's)."""
    return value[c] if isinstance(value, (tuple, list)) else value


def two_sided(wi: Array, wo: Array, f_r: Any) -> Array:
    """``f_r(wi, wo)`` of front-side directions, shading the back as the front (Mitsuba's
    ``twosided``: both directions on the back are mirrored to the front), 0 where ``wi`` and ``wo``
    lie on opposite sides; ``f_r`` sees the normal direction instead of a direction it is 0 for."""
    import jax.numpy as jnp  # deferred: a model's fields are read without JAX (the parameter table, a scene file)
    wi, wo = jnp.asarray(wi, dtype=float), jnp.asarray(wo, dtype=float)
    back = (wi[..., 2] < 0)[..., None]
    flip = jnp.array([1.0, 1.0, -1.0])
    wi, wo = jnp.where(back, wi * flip, wi), jnp.where(back, wo * flip, wo)
    front = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    up = jnp.array([0.0, 0.0, 1.0])
    safe_i, safe_o = jnp.where(front[..., None], wi, up), jnp.where(front[..., None], wo, up)
    return jnp.where(front, f_r(safe_i, safe_o), 0.0)


@dataclass(frozen=True)
class MaterialModel:
    """Base of the material models: validation from :attr:`fields`, the two-sided RGB-mean BRDF, the
    level-of-detail rule. Subclasses are frozen dataclasses whose numeric dataclass fields are
    declared in :attr:`fields` (other dataclass fields are options, e.g. a conductor's ``distribution``).

    Subclass it (a frozen dataclass with ``name``, ``fields`` and ``f_r``) and add it with
    :func:`register_material` to give scene files and fits a material of your own; the
    development page's "Adding a material model" shows one whole.

    Example:
        >>> import spacefit as sf
        >>> [f.name for f in sf.Conductor.fields]
        ['eta', 'k', 'alpha_x', 'alpha_y']
        >>> issubclass(sf.Lambert, sf.MaterialModel)
        True
    """

    # The name a scene file gives the model (``material = "conductor"``).
    name: ClassVar[str] = ""
    # Its numeric values, in the order the model's dataclass fields are given.
    fields: ClassVar[tuple[Field, ...]] = ()
    # Shorthands setting several fields to one value, each (its fields, doc, label): a conductor's
    # ``alpha`` sets alpha_x and alpha_y (``parts.P.alpha``).
    ties: ClassVar[Mapping[str, tuple[tuple[str, ...], str, str]]] = {}
    # Whether the BRDF is a delta function (no finite value to evaluate).
    delta: ClassVar[bool] = False
    # Its dataclass fields that name files (a measured table's ``source``): a scene file's relative
    # path is resolved against the scene file's folder.
    paths: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        for f in self.fields:
            object.__setattr__(self, f.name, f.check(getattr(self, f.name)))

    @classmethod
    def field(cls, name: str) -> Field:
        """The field ``name`` (a tie gives its first field's)."""
        name = cls.ties[name][0][0] if name in cls.ties else name
        return next(f for f in cls.fields if f.name == name)

    def f_r(self, wi: Array, wo: Array, **values: Array) -> Array:
        """The BRDF (sr^-1) of one grey channel for front-side local unit directions (..., 3), the
        fields' values given by name (JAX-traceable). A model with a finite BRDF defines it."""
        raise NotImplementedError(f"{type(self).__name__} defines no BRDF")

    def evaluate(self, wi: Array, wo: Array, values: Mapping[str, Array] | None = None) -> Array:
        """f_r (sr^-1) for local unit directions ``wi`` (towards the light) and ``wo`` (towards the
        observer), arrays (..., 3), both sides alike (:func:`two_sided`); RGB values give the
        channels' mean (the renderer's light curve is the channels' mean radiance). ``values``
        replace fields by name with grey values (JAX-traceable: what a fit varies)."""
        if self.delta:
            raise TypeError(f"a {type(self).__name__}'s BRDF is a delta function: it has no finite value to evaluate")
        values = dict(values or {})
        own = {f.name: getattr(self, f.name) for f in self.fields if f.name not in values}
        channels = 3 if any(isinstance(v, tuple) for v in own.values()) else 1
        out = [two_sided(wi, wo, lambda a, b, c=c: self.f_r(a, b, **values, **{k: channel(v, c) for k, v in own.items()}))
               for c in range(channels)]
        return sum(out) / channels

    def effective(self, slope_rms: float) -> MaterialModel | None:
        """The level-of-detail rule: a flat part's material that renders this one's as wrinkled with
        rms slope ``slope_rms`` (per axis), or None where the model has none (:class:`WrinkleSettings`' ``lod``)."""
        return None


# A part's material: an instance of any registered model (:mod:`spacefit.materials.registry`).
Material = MaterialModel
