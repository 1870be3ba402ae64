"""Named material presets, chosen per part by name; unknown names list the valid ones."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from spacefit.errors import InputError, check_choice
from spacefit.materials.models import Conductor, Lambert, Material, Mirror

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


def make_material(name: str, overrides: Mapping[str, object] | None = None, *, where: str = "material") -> Material:
    """The preset ``name`` with some of its parameters replaced.

    Args:
        name: a key of :data:`PRESETS`.
        overrides: parameter name -> value; only the preset model's own parameters are allowed,
            and ``alpha`` for both roughnesses of a conductor.
        where: how the user addressed this material, used in messages (e.g. ``"parts.panels"``).

    Raises:
        InputError: for an unknown preset, an unknown parameter or a value out of range.
    """
    preset = PRESETS[check_choice(f"{where}.material", name, PRESETS)]
    overrides = dict(overrides or {})
    if "alpha" in overrides and isinstance(preset, Conductor):
        # shorthand for an isotropic roughness
        if {"alpha_x", "alpha_y"} & set(overrides):
            raise InputError(f"`{where}.alpha` sets alpha_x and alpha_y; do not give them as well.")
        overrides["alpha_x"] = overrides["alpha_y"] = overrides.pop("alpha")
    fields = {f.name for f in dataclasses.fields(preset)}
    for key in overrides:
        check_choice(f"{where}.{key} (a parameter of {type(preset).__name__})", key, fields)
    try:
        return dataclasses.replace(preset, **overrides)
    except InputError as err:
        raise InputError(f"{where}: {err}") from None
