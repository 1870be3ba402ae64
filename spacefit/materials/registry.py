"""The material models by the name a scene file gives them, and the named presets; unknown names list the valid ones.

A model (:class:`MaterialModel`) is added by one call,
:func:`register_material`, from any module (a test's own included); the parameter table
(``parts.P.<field>``) and every place that asks for a model by name see it from then on.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Mapping
from typing import TypeVar

from spacefit.errors import InputError, check_choice, closest, inside
from spacefit.materials.conductor import Conductor
from spacefit.materials.diffuse_conductor import DiffuseConductor
from spacefit.materials.lambert import Lambert
from spacefit.materials.mirror import Mirror
from spacefit.materials.model import Field, Material, MaterialModel
from spacefit.materials.oren_nayar import OrenNayar
from spacefit.materials.tabulated import TabulatedBRDF

# pbrt-v3's Metal material, which the thesis used for the MLI, defaults to roughness 0.01 remapped
# by RoughnessToAlpha to a Trowbridge-Reitz alpha of 0.14; a true mirror is never lit directly by a
# distant sun, so the MLI presets keep that small roughness.
MLI_ALPHA = 0.14

# RGB complex refractive indices of gold and silver (as tabulated for pbrt / Mitsuba RGB renders).
GOLD_ETA = (0.143119, 0.374957, 1.44248)
GOLD_K = (3.98316, 2.38572, 1.60322)
SILVER_ETA = (0.155265, 0.116723, 0.138342)
SILVER_K = (4.82835, 3.12225, 2.14696)

#: Named materials a scene file gives a part (``material = "mli_gold"``) or Python takes as they are:
#: the thesis's MLI, mirror and panel values, gold and silver MLI (RGB complex refractive indices
#: as tabulated for pbrt / Mitsuba) and a white paint. Each is a :class:`Conductor`, :class:`Mirror`
#: or :class:`Lambert` value (frozen); roughness alpha is dimensionless.
#:
#: Example:
#:     >>> import spacefit as sf
#:     >>> list(sf.PRESETS)
#:     ['mli_thesis', 'mli_gold', 'mli_silver', 'mirror_thesis', 'panel_thesis', 'white_paint']
#:     >>> sf.PRESETS["white_paint"]
#:     Lambert(kd=0.2)
PRESETS: Mapping[str, Material] = {
    "mli_thesis": Conductor(eta=0.18, k=0.01, alpha_x=MLI_ALPHA, alpha_y=MLI_ALPHA),
    "mli_gold": Conductor(eta=GOLD_ETA, k=GOLD_K, alpha_x=MLI_ALPHA, alpha_y=MLI_ALPHA),
    "mli_silver": Conductor(eta=SILVER_ETA, k=SILVER_K, alpha_x=MLI_ALPHA, alpha_y=MLI_ALPHA),
    "mirror_thesis": Mirror(eta=0.18, k=0.01),
    "panel_thesis": Conductor(eta=2.05, k=0.055, alpha_x=0.08, alpha_y=0.05),
    "white_paint": Lambert(kd=0.2),
}


# The models by the name a scene file gives them when it states every value (``material = "conductor"``).
MODELS: dict[str, type[MaterialModel]] = {}
V = TypeVar("V")


class Derived(Mapping[str, V]):
    """A read-only mapping computed from the registered models (by ``compute``), computed again after
    a model is registered: the tables of other floors that derive from the models' fields
    (``parts.P.<field>``, a BRDF-table fit's bounds) see a model registered later."""

    def __init__(self, compute: Callable[[], dict[str, V]]) -> None:
        self._compute = compute
        self._models: tuple[type, ...] | None = None
        self._table: dict[str, V] = {}

    def _current(self) -> dict[str, V]:
        if self._models != tuple(MODELS.values()):
            self._table, self._models = self._compute(), tuple(MODELS.values())
        return self._table

    def __getitem__(self, key: str) -> V:
        return self._current()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._current())

    def __len__(self) -> int:
        return len(self._current())

    def __repr__(self) -> str:
        return repr(self._current())


def register_material(model: type[MaterialModel]) -> type[MaterialModel]:
    """Add a material model under its :attr:`MaterialModel.name` (returned,
    so that it may decorate the class). Registering the same class again is a no-op.

    Raises:
        ValueError: for a class that is not a frozen MaterialModel dataclass, a name taken by another
            model or a preset, or a field whose name another model's field has with another unit or
            range (one name, one meaning: ``parts.P.<field>`` is one parameter).

    Args:
        model: the class, a frozen dataclass subclassing :class:`MaterialModel`.

    Returns:
        ``model`` itself.

    Example:
        >>> import spacefit as sf
        >>> sf.register_material(sf.Lambert) is sf.Lambert  # registered already: a no-op
        True
    """
    if not (isinstance(model, type) and issubclass(model, MaterialModel) and dataclasses.is_dataclass(model) and model.name):
        raise ValueError(f"{model!r} is not a named MaterialModel dataclass")
    if MODELS.get(model.name, model) is not model or model.name in PRESETS:
        raise ValueError(f"the material name {model.name!r} is taken")
    numeric = {f.name for f in model.fields}
    if not numeric <= {f.name for f in dataclasses.fields(model)} or set(model.ties) & numeric:
        raise ValueError(f"{model.__name__}: its fields {sorted(numeric)} and ties {sorted(model.ties)} must be distinct dataclass fields")
    for name, f in shared_fields(model).items():
        other = shared_fields(None)[name]
        if (f.unit, f.lo, f.hi) != (other.unit, other.lo, other.hi):
            raise ValueError(f"{model.__name__}.{name} is in {f.unit} on [{f.lo:g}, {f.hi:g}], another model's on "
                             f"[{other.lo:g}, {other.hi:g}] in {other.unit}: one field name is one parameter")
    MODELS[model.name] = model
    return model


def shared_fields(model: type[MaterialModel] | None) -> dict[str, Field]:
    """The fields (and ties, as their first field) of ``model`` that registered models have too, by
    name; or, for None, every registered model's fields by name (the first model's where several share one)."""
    registered: dict[str, Field] = {}
    for m in MODELS.values():
        for name in (*(f.name for f in m.fields), *m.ties):
            registered.setdefault(name, m.field(name))
    if model is None:
        return registered
    return {name: model.field(name) for name in (*(f.name for f in model.fields), *model.ties) if name in registered}


for _model in (Conductor, Mirror, Lambert, DiffuseConductor, OrenNayar, TabulatedBRDF):
    register_material(_model)


def make_material(name: str, overrides: Mapping[str, object] | None = None, *, where: str = "material") -> Material:
    """The preset ``name`` with some of its parameters replaced, or the model ``name`` with all of them given.

    Args:
        name: a key of :data:`PRESETS` or of :data:`MODELS`.
        overrides: parameter name -> value; only the model's own parameters are allowed, and
            a tie (``alpha`` for both roughnesses of a conductor).
        where: how the user addressed this material, used in messages (e.g. ``"parts.panels"``).

    Raises:
        InputError: for an unknown preset, an unknown or missing parameter or a value out of range,
            naming ``where.key``.
    """
    check_choice(f"{where}.material", name, [*PRESETS, *MODELS])
    overrides = dict(overrides or {})
    if name in PRESETS:
        return with_material_values(PRESETS[name], overrides, where=where)
    model = MODELS[name]
    given = {*overrides, *(f for tie, (tied, _, _) in model.ties.items() if tie in overrides for f in tied)}
    missing = [f.name for f in dataclasses.fields(model) if f.default is dataclasses.MISSING and f.name not in given]
    if missing:
        raise InputError(f"`{where}.{missing[0]}` is missing: `{where}.material` = {name!r} states every value itself "
                         f"(a {model.__name__} has {', '.join(f.name for f in dataclasses.fields(model))}).")
    return with_material_values(model, overrides, where=where)


def with_material_values(material: Material | type, values: Mapping[str, object], *, where: str = "material") -> Material:
    """A copy of ``material`` with some parameters replaced (or, given a model class, one built from
    all of them); a tie (``alpha``) sets its fields (both roughnesses of a conductor). Errors name ``where.key``."""
    model = material if isinstance(material, type) else type(material)
    values = dict(values)
    for tie, (tied, _, _) in model.ties.items():
        if tie in values:  # a shorthand for several fields' one value (an isotropic roughness)
            if set(tied) & set(values):
                raise InputError(f"`{where}.{tie}` sets {' and '.join(tied)}; do not give them as well.")
            values.update(dict.fromkeys(tied, values.pop(tie)))
    fields = [f.name for f in dataclasses.fields(model)]
    for key in values:
        if key not in fields:
            close = closest(key, [*fields, *model.ties])
            hint = f" Did you mean `{where}.{close}`?" if close else ""
            raise InputError(f"unknown scene key `{where}.{key}`: a {model.__name__} has {', '.join(fields)}; a part "
                             f"has `material` and `file` too.{hint}")
    if not isinstance(material, type) and any(values.get(k, getattr(material, k)) != getattr(material, k) for k in model.paths):
        # another file: what was read from the old one (the ``derived`` fields) is read again from the new
        values.update({f.name: f.default for f in dataclasses.fields(model) if f.metadata.get("derived") and f.name not in values})
    with inside(where):
        return model(**values) if isinstance(material, type) else dataclasses.replace(material, **values)


def material_table(material: Material) -> dict[str, object]:
    """A material as a scene file's part table states it in full: its model's name and every value
    (not the values it derives from others: a measured table's arrays, read from its ``source``)."""
    name = type(material).name
    return {"material": name, **{f.name: _plain(getattr(material, f.name)) for f in dataclasses.fields(material)
                                 if not f.metadata.get("derived")}}


def _plain(value: object) -> object:
    return list(value) if isinstance(value, tuple) else value
