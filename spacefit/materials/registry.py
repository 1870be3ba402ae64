"""Named material presets and models, as a scene file names them; unknown names list the valid ones."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from spacefit.errors import InputError, check_choice, closest, inside
from spacefit.materials.models import Conductor, DiffuseConductor, Lambert, Material, Mirror

# pbrt-v3's Metal material, which the thesis used for the MLI, defaults to roughness 0.01 remapped
# by RoughnessToAlpha to a Trowbridge-Reitz alpha of 0.14; a true mirror is never lit directly by a
# distant sun, so the MLI presets keep that small roughness.
MLI_ALPHA = 0.14

# RGB complex refractive indices of gold and silver (as tabulated for pbrt / Mitsuba RGB renders).
GOLD_ETA = (0.143119, 0.374957, 1.44248)
GOLD_K = (3.98316, 2.38572, 1.60322)
SILVER_ETA = (0.155265, 0.116723, 0.138342)
SILVER_K = (4.82835, 3.12225, 2.14696)

PRESETS: Mapping[str, Material] = {
    "mli_thesis": Conductor(eta=0.18, k=0.01, alpha_x=MLI_ALPHA, alpha_y=MLI_ALPHA),
    "mli_gold": Conductor(eta=GOLD_ETA, k=GOLD_K, alpha_x=MLI_ALPHA, alpha_y=MLI_ALPHA),
    "mli_silver": Conductor(eta=SILVER_ETA, k=SILVER_K, alpha_x=MLI_ALPHA, alpha_y=MLI_ALPHA),
    "mirror_thesis": Mirror(eta=0.18, k=0.01),
    "panel_thesis": Conductor(eta=2.05, k=0.055, alpha_x=0.08, alpha_y=0.05),
    "white_paint": Lambert(kd=0.2),
}


# The models by the name a scene file gives them when it states every value (``material = "conductor"``).
MODELS: Mapping[str, type] = {"conductor": Conductor, "mirror": Mirror, "lambert": Lambert,
                              "diffuse_conductor": DiffuseConductor}


def make_material(name: str, overrides: Mapping[str, object] | None = None, *, where: str = "material") -> Material:
    """The preset ``name`` with some of its parameters replaced, or the model ``name`` with all of them given.

    Args:
        name: a key of :data:`PRESETS` or of :data:`MODELS`.
        overrides: parameter name -> value; only the model's own parameters are allowed, and
            ``alpha`` for both roughnesses of a conductor.
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
    given = {*overrides, *(("alpha_x", "alpha_y") if "alpha" in overrides else ())}
    missing = [f.name for f in dataclasses.fields(model) if f.default is dataclasses.MISSING and f.name not in given]
    if missing:
        raise InputError(f"`{where}.{missing[0]}` is missing: `{where}.material` = {name!r} states every value itself "
                         f"(a {model.__name__} has {', '.join(f.name for f in dataclasses.fields(model))}).")
    return with_material_values(model, overrides, where=where)


def with_material_values(material: Material | type, values: Mapping[str, object], *, where: str = "material") -> Material:
    """A copy of ``material`` with some parameters replaced (or, given a model class, one built from
    all of them); ``alpha`` sets both roughnesses of a conductor. Errors name ``where.key``."""
    model = material if isinstance(material, type) else type(material)
    values = dict(values)
    if "alpha" in values and model in (Conductor, DiffuseConductor):
        # shorthand for an isotropic roughness
        if {"alpha_x", "alpha_y"} & set(values):
            raise InputError(f"`{where}.alpha` sets alpha_x and alpha_y; do not give them as well.")
        values["alpha_x"] = values["alpha_y"] = values.pop("alpha")
    fields = [f.name for f in dataclasses.fields(model)]
    for key in values:
        if key not in fields:
            close = closest(key, [*fields, *(["alpha"] if model in (Conductor, DiffuseConductor) else [])])
            hint = f" Did you mean `{where}.{close}`?" if close else ""
            raise InputError(f"unknown scene key `{where}.{key}`: a {model.__name__} has {', '.join(fields)}; a part "
                             f"has `material` and `file` too.{hint}")
    with inside(where):
        return model(**values) if isinstance(material, type) else dataclasses.replace(material, **values)


def material_table(material: Material) -> dict[str, object]:
    """A material as a scene file's part table states it in full: its model's name and every value."""
    name = next(n for n, m in MODELS.items() if isinstance(material, m))
    return {"material": name, **{f.name: _plain(getattr(material, f.name)) for f in dataclasses.fields(material)}}


def _plain(value: object) -> object:
    return list(value) if isinstance(value, tuple) else value
