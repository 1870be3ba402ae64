"""The override language: values set by dotted name, in Python (``Scene.with_values``) or on the
command line (``--set key=value``), in one vocabulary.

A name is a scene-file key (``camera.position_m``, ``sun.direction``, ``parts.panels.alpha_x``,
``parts.panels.material``) or a parameter name of :mod:`spacefit.scene.parameters`
(``sun.elevation_deg``, ``target.attitude_x_deg``, ``wrinkles.rms_m``): both are accepted wherever
a value is set. The fit-only ``image.*`` nuisances are not scene values and are refused here. Every
value is checked by the section or material it lands in, so a value is refused with the same
message wherever it is given. An unknown name is answered with the closest valid one at the depth
where it went wrong: the section, the part, or the key.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_direction, check_path, check_vector, closest, inside, quote
from spacefit.geometry.articulation import ARTICULATION_KEYS, pop_articulation
from spacefit.geometry.primitives import pop_primitive
from spacefit.materials import MODELS, make_material, with_material_values
from spacefit.scene.parameters import ATTITUDE, PARAMETERS, is_image, scene_keys, scene_with_values
from spacefit.scene.conversions import VERTICAL_SUN, sun_angles_deg
from spacefit.scene.sections import SECTIONS, SceneLike, unknown_part
from spacefit.scene.target import PartSettings
from spacefit.scene.optics import check_pitch_with_fov

Overrides = Mapping[str, Any] | Sequence[str] | str
# The keys of a part table besides its material's own values and the models' ties (``alpha``) and a primitive's.
PART_KEYS = ("material", "file", *ARTICULATION_KEYS)


def toml_value(raw: str) -> Any:
    """A value written as in a TOML file (``0.3``, ``true``, ``[1, 2]``, ``"text"``); ValueError (TOML's
    decode error) when ``raw`` is not one."""
    import tomllib  # here: only a value typed on the command line needs it (the default render reads no TOML)

    return tomllib.loads(f"v = {raw.strip()}")["v"]


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse ``a.b.c=value`` (value in TOML syntax; bare words are strings) into a key path and value."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise InputError(f"override {text!r} must look like `section.key=value`.")
    try:
        value = toml_value(raw)
    except ValueError:
        value = raw.strip()
    except RecursionError:
        raise InputError(f"the value of override `{key.strip()}` is nested too deep: {quote(raw)}.") from None
    return [k.strip() for k in key.split(".")], value


def override_items(overrides: Overrides) -> list[tuple[list[str], Any]]:
    """Key paths and values from a mapping ``{"a.b": value}``, ``"a.b=value"`` strings, or one such
    string; a table given as a value (``{"parts.panels": {"material": ..., "kd": ...}}``) is its keys."""
    if isinstance(overrides, Mapping):
        for key in overrides:
            if not isinstance(key, str) or not key.strip():
                raise InputError(f"scene value keys must be dotted names like 'camera.position_m', got {key!r}.")
        items = [([k.strip() for k in key.split(".")], _plain_value(value)) for key, value in overrides.items()]
    else:
        if isinstance(overrides, str):
            overrides = [overrides]
        if not isinstance(overrides, Sequence) or not all(isinstance(text, str) for text in overrides):
            raise InputTypeError(f"scene overrides must be a mapping of key -> value or 'key=value' strings, got {quote(overrides)}.")
        items = [parse_override(text) for text in overrides]
    return [leaf for path, value in items for leaf in _leaves(path, value)]


def _leaves(path: list[str], value: Any) -> list[tuple[list[str], Any]]:
    if isinstance(value, Mapping) and not value:
        raise InputError(f"`{'.'.join(path)}` = {{}} sets nothing: give a value, or a table of keys and values.")
    if isinstance(value, Mapping):
        return [leaf for key, v in value.items() for leaf in _leaves([*path, str(key)], v)]
    return [(path, value)]


def _plain_value(value: Any) -> Any:
    """A Python value as the scene file would hold it: numpy / JAX scalars and arrays as numbers and lists."""
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return value.tolist()
    if isinstance(value, tuple):
        return [_plain_value(v) for v in value]
    return value


def apply_overrides(data: dict[str, Any], overrides: Overrides) -> dict[str, Any]:
    """Return a deep copy of scene-file ``data`` (nested dicts) with overrides applied."""
    out = copy.deepcopy(data)
    items = override_items(overrides)
    for path, value in items:
        node = out
        for k in path[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise InputError(f"scene key {'.'.join(path)!r}: {k!r} is not a table.")
        node[path[-1]] = value
    given = {".".join(path) for path, _ in items}
    for key, other in (("camera.fov_deg", "camera.pixel_pitch_mm"), ("camera.pixel_pitch_mm", "camera.fov_deg")):
        if key in given and other not in given and isinstance(out.get("camera"), dict):
            out["camera"].pop(other.split(".")[1], None)  # the field set again the other way replaces the file's
    for path, _ in items:
        table = out.get("parts", {}).get(path[1]) if len(path) == 3 and path[0] == "parts" else None
        if isinstance(table, dict):
            _retie(table, path[1], path[2], given)
    return out


def _retie(table: dict[str, Any], part: str, key: str, given: set[str]) -> None:
    """A part's tie (``alpha``) or one of its fields (``alpha_x``) given as an override replaces the file's
    values the other way: the file's tied fields dropped, or the file's tie spread over its fields first."""
    for model in MODELS.values():
        for tie, (tied, _, _) in model.ties.items():
            if key == tie:
                for name in tied:
                    if f"parts.{part}.{name}" not in given:
                        table.pop(name, None)
            elif key in tied and tie in table and f"parts.{part}.{tie}" not in given:
                value = table.pop(tie)
                for name in tied:
                    table.setdefault(name, value)


def section_keys(section: str) -> list[str]:
    """The last components of the names valid in a section: its scene-file fields and the
    parameter names under it (``sun``: ``irradiance_w_m2``, ``direction``, ``elevation_deg``, ...)."""
    fields = [f.name for f in dataclasses.fields(SECTIONS[section])]
    names = [p.split(".", 1)[1] for p in PARAMETERS if p.startswith(f"{section}.")]
    return list(dict.fromkeys([*fields, *names]))


def part_keys(part: PartSettings | None) -> list[str]:
    """The keys valid in a part's table: ``material``, ``file``, the models' ties (``alpha``) and its
    material's values (any registered model's for a new part)."""
    models = [type(part.material)] if part is not None else list(MODELS.values())
    ties = [t for m in MODELS.values() for t in m.ties]
    return list(dict.fromkeys([*PART_KEYS, *ties, *(f.name for m in models for f in dataclasses.fields(m))]))


def unknown_key(path: Sequence[str], parts: Sequence[str]) -> InputError:
    """The error for an unknown dotted name, suggesting the closest valid one at the depth where it
    went wrong: the section, the part (``parts``: the scene's part names) or the key."""
    key = ".".join(path)

    def hint(depth: int, valid: Sequence[str]) -> str:
        close = closest(path[depth], valid)
        return f" Did you mean `{'.'.join([*path[:depth], close, *path[depth + 1:]])}`?" if close else ""

    sections = [*SECTIONS, "parts"]
    if path[0] == "image" and key in PARAMETERS:
        return InputError(f"`{key}` is a fit-only nuisance, applied to the render by a fit; a scene has no such value.")
    if path[0] not in sections:
        return InputError(f"unknown scene key `{key}`: `{path[0]}` is not a section (sections: {', '.join(sections)})."
                          f"{hint(0, sections)}")
    if path[0] == "parts":
        if len(path) != 3:
            return InputError(f"scene key `{key}` must be `parts.PART.KEY` (parts: {', '.join(parts)}).")
        if path[1] not in parts:
            return unknown_part(key, parts)
        return InputError(f"unknown scene key `{key}`; valid keys here: {', '.join(part_keys(None))}.{hint(2, part_keys(None))}")
    valid = section_keys(path[0])
    if len(path) != 2:
        return InputError(f"scene key `{key}` must be `{path[0]}.KEY`; valid keys here: {', '.join(valid)}.")
    return InputError(f"unknown scene key `{key}`; valid keys here: {', '.join(valid)}.{hint(1, valid)}")


def is_file_key(path: Sequence[str]) -> bool:
    """Whether a key path is a scene-file key: a section's field or a key of a part's table."""
    if path[0] == "parts":
        return len(path) == 3
    return (len(path) == 2 and path[0] in SECTIONS
            and path[1] in {f.name for f in dataclasses.fields(SECTIONS[path[0]])})


# The sun's direction given as a vector and as both its angles: two answers to one question.
SUN_FORMS = ("sun.direction", "sun.elevation_deg", "sun.azimuth_deg")


def check_sun_forms(keys: set[str] | frozenset[str]) -> None:
    """Refuse ``sun.direction`` given together with both of the sun's angles (one form sets the other:
    the direction would be dropped); a direction with one angle keeps the other angle the direction's."""
    if set(SUN_FORMS) <= set(keys):
        raise InputError("`sun.direction` and both `sun.elevation_deg` and `sun.azimuth_deg` are given: each sets the sun's "
                         "direction, so one would be dropped; give the direction or the two angles.")


def with_values(scene: SceneLike, values: Mapping[str, Any]) -> SceneLike:
    """A checked copy of ``scene`` with values set by name: scene-file keys and parameter names
    (module docstring), a mapping of names to Python values.

    Scene-file keys are set first, parameter names then: ``{"sun.direction": ..., "sun.elevation_deg":
    30}`` keeps the given direction's azimuth. A new part needs its ``parts.P.material``.

    Raises:
        InputError: for an unknown name (suggesting the closest at its depth), a fit-only name, or a
            value its section or material refuses (naming the key, the value and the range).
    """
    if not isinstance(values, Mapping):
        raise InputTypeError(f"`values` must be a mapping of dotted scene keys to values, got {quote(values)}.")
    items = override_items(values)
    check_sun_forms({".".join(path) for path, _ in items})
    sections: dict[str, dict[str, Any]] = {}
    parts: dict[str, dict[str, Any]] = {}
    parameters: dict[str, Any] = {}
    for path, value in items:
        key = ".".join(path)
        if is_file_key(path) and path[0] == "parts":
            if path[1] not in scene.parts and not any(p[:2] == ["parts", path[1]] and p[2] == "material" for p, _ in items):
                raise unknown_key(path, list(scene.parts))
            parts.setdefault(path[1], {})[path[2]] = value
        elif is_file_key(path):
            sections.setdefault(path[0], {})[path[1]] = value
        elif key in PARAMETERS and not is_image(key):
            parameters[key] = value
        else:
            raise unknown_key(path, list(scene.parts))
    if "pixel_pitch_mm" in sections.get("camera", {}):
        sections["camera"].setdefault("fov_deg", 0.0)  # a pitch given alone sets the field, in place of a field of view
    changed: dict[str, Any] = {name: dataclasses.replace(getattr(scene, name), **kw) for name, kw in sections.items()}
    new_parts = dict(scene.parts)
    for name, table in parts.items():
        old = scene.parts.get(name)
        file = table.pop("file", old.file if old is not None else "")
        if not isinstance(file, str):
            raise InputTypeError(f"`parts.{name}.file` must be a path string, got {quote(file)}.")
        file = str(Path(file).resolve()) if file and not check_path(f"parts.{name}.file", file).is_absolute() else file
        shape = pop_primitive(table, f"parts.{name}", old.shape if old is not None else None)
        law = pop_articulation(table, f"parts.{name}", old.articulation if old is not None else None,
                               shape.position_m if shape is not None else (0.0, 0.0, 0.0))
        if "material" in table:
            material = make_material(table.pop("material"), table, where=f"parts.{name}")
        else:
            material = with_material_values(old.material, table, where=f"parts.{name}")  # type: ignore[union-attr]
        with inside(f"parts.{name}"):
            new_parts[name] = PartSettings(material, file, shape, law)
    if parts:
        changed["parts"] = new_parts
    out = dataclasses.replace(scene, **changed) if changed else scene
    angles = [key for key in (*(f"target.{k}" for k in sections.get("target", {}) if k == "attitude_deg"), *parameters)
              if key == "target.attitude_deg" or key in ATTITUDE]
    if angles and out.target.attitude != "fixed":
        raise InputError(f"`{angles[0]}` sets an attitude angle, which `target.attitude` = {out.target.attitude!r} does not use "
                         "(the law sets the attitude): set `target.attitude` = \"fixed\" with it.")
    if "pixel_pitch_mm" in sections.get("camera", {}):
        check_pitch_with_fov(out, sections["camera"]["pixel_pitch_mm"])
    return scene_with_values(out, parameters) if parameters else out


def as_parameters(scene: SceneLike, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` by parameter name: the scene-file keys that parameters spell another way become
    them (``sun.direction`` the sun's angles, keeping the scene's azimuth for a vertical sun;
    ``target.attitude_deg`` / ``position_m`` their components); parameter names pass.

    Raises:
        InputError: for a scene-file key no parameter sets (``camera.focal_length_mm``: it changes
            what a :class:`~spacefit.rendering.renderer.Renderer` assembled, so build a new one from
            ``scene.with_values(...)``), or an unknown name (suggesting the closest).
    """
    out: dict[str, Any] = {}
    for path, value in override_items(values):
        key = ".".join(path)
        forms = [n for n in PARAMETERS if "P" not in n.split(".") and not is_image(n) and key in scene_keys(n) - {n}]
        if path[0] == "parts" and len(path) == 3 and path[1] not in scene.parts:
            raise unknown_part(key, list(scene.parts))
        if key in PARAMETERS or (path[0] == "parts" and len(path) == 3 and f"parts.P.{path[2]}" in PARAMETERS):
            out[key] = value
        elif key == "sun.direction":
            direction = check_direction(key, value)
            out["sun.elevation_deg"], azimuth = sun_angles_deg(direction)
            if np.hypot(direction[0], direction[1]) >= VERTICAL_SUN:
                out["sun.azimuth_deg"] = azimuth
        elif forms:
            vector = check_vector(key, value)
            out.update(zip(forms, vector.tolist()))
        elif is_file_key(path) and (path[0] != "parts" or path[2] in part_keys(scene.parts[path[1]])):
            raise InputError(f"`{key}` is a scene-file key that no parameter sets: it changes what a Renderer assembled; "
                             "build a new Renderer from `scene.with_values(...)`.")
        else:
            raise unknown_key(path, list(scene.parts))
    return out
