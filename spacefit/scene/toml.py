"""Reading scene files: TOML text to a checked :class:`Scene` (whose module
docstring gives the defaults, the units and the sun's conventions).

A part's articulation keys (``articulation``, ``axis``, ``angle_deg``, ``pivot_m``,
:func:`spacefit.geometry.articulation.pop_articulation`) pivot by default about a primitive's
``position_m``. A part's ``material`` names a preset (:data:`PRESETS`, the other keys of its
table replacing the preset's values) or a model (``"conductor"``, ``"mirror"``, ``"lambert"``, with
every value given, as :meth:`Scene.to_toml` writes it); it becomes a material object here, when
the file is read. A section may also give parameter names (``[sun] elevation_deg = 30``,
:mod:`spacefit.scene.overrides`); they are set after the file's own keys.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from spacefit.errors import InputError, InputTypeError, check_path, inside, quote
from spacefit.geometry.articulation import pop_articulation
from spacefit.geometry.mesh import load_grouped
from spacefit.geometry.primitives import pop_primitive
from spacefit.materials import MODELS, make_material
from spacefit.scene.overrides import Overrides, apply_overrides, check_sun_forms, section_keys, unknown_key, with_values
from spacefit.scene.schema import Scene
from spacefit.scene.sections import SECTIONS
from spacefit.scene.target import BUILTIN, DEFAULT_PRESETS, MESHLESS, PartSettings, TargetSettings
from spacefit.scene.optics import check_pitch_with_fov


def read_scene_dict(path: str | Path) -> dict[str, Any]:
    """Read a scene TOML file as a nested dict (no checks of its values yet)."""
    if not isinstance(path, (str, Path)):
        raise InputTypeError(f"the scene file must be a path (str or pathlib.Path), got {quote(path)}.")
    p = Path(path)
    if p.is_dir():
        raise InputError(f"scene file {str(p)!r} is a folder; give the TOML file in it.")
    if not p.is_file():
        raise InputError(f"scene file {str(p)!r} does not exist.")
    import tomllib  # here: a render of the default scene reads no TOML

    try:
        return tomllib.loads(p.read_text(encoding="utf-8-sig"))  # a byte-order mark is not TOML
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise InputError(f"scene file {str(p)!r} is not valid TOML: {err}") from None
    except RecursionError:
        raise InputError(f"scene file {str(p)!r} holds arrays or tables nested too deep to read.") from None


def _section(name: str, data: Mapping[str, Any], later: dict[str, Any]) -> Any:
    """A section from its table; parameter names (not fields) go to ``later``."""
    cls = SECTIONS[name]
    fields = {f.name for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in data.items():
        if key in fields:
            kwargs[key] = value
        elif key in section_keys(name):
            later[f"{name}.{key}"] = value
        else:
            raise unknown_key([name, key], [])
    return cls(**kwargs)


def _parts(data: Mapping[str, Any], builtin: bool, base: Path) -> dict[str, PartSettings]:
    """The parts: with the built-in lander, tables merge into its default parts (a table without a
    ``material`` changes the preset's values; ``NAME = false`` removes the part); with a mesh file
    exactly those given."""
    names = list(DEFAULT_PRESETS) if builtin else []
    tables: dict[str, dict[str, Any]] = {name: {"material": preset} for name, preset in DEFAULT_PRESETS.items()} if builtin else {}
    for name, table in data.items():
        if table is False:
            if name not in names:
                raise InputError(f"`parts.{name} = false` removes a part of the built-in lander ({', '.join(DEFAULT_PRESETS)}); "
                                 f"{name!r} is not one" + ("." if builtin else " (`target.mesh` is not \"builtin\")."))
            del tables[name]
            continue
        if not isinstance(table, Mapping):
            raise InputError(f"`parts.{name}` must be a table with at least `material`, got {quote(table)}.")
        if "material" in table:
            tables[name] = dict(table)
        elif name in tables:
            tables[name] = {**tables[name], **table}
        else:
            key = next(iter(table), "material")
            if names:
                raise unknown_key(["parts", name, key], names)
            raise InputError(f"`parts.{name}.material` is missing (a preset name or a model).")
    parts = {}
    for name, table in tables.items():
        file = table.pop("file", "")
        if not isinstance(file, str):
            raise InputTypeError(f"`parts.{name}.file` must be a path string, got {quote(file)}.")
        if file and not check_path(f"parts.{name}.file", file).is_absolute():
            file = str((base / file).resolve())
        model = MODELS.get(table["material"]) if isinstance(table["material"], str) else None
        for key in model.paths if model is not None else ():  # files a model reads (a measured table), beside the scene file
            if isinstance(table.get(key), str) and table[key] and not Path(table[key]).is_absolute():
                table[key] = str((base / table[key]).resolve())
        shape = pop_primitive(table, f"parts.{name}")
        law = pop_articulation(table, f"parts.{name}", default_pivot_m=shape.position_m if shape is not None else (0.0, 0.0, 0.0))
        material = make_material(table.pop("material"), table, where=f"parts.{name}")
        with inside(f"parts.{name}"):
            parts[name] = PartSettings(material, file, shape, law)
    return parts


def scene_from_dict(data: Mapping[str, Any], base_dir: str | Path = ".") -> Scene:
    """Build a checked :class:`Scene` from nested mappings as a scene file holds them; missing keys
    take defaults.

    With the built-in lander, ``parts`` tables merge into the default parts (so
    ``parts.panels.alpha_x = 0.1`` keeps the panels' preset) and ``parts.legs = false`` removes one
    (as :meth:`Scene.to_toml` writes a lander without it); with a mesh file the parts are exactly
    those given. Relative mesh paths are resolved against ``base_dir`` (the TOML's folder).
    """
    base = Path(base_dir)
    sections: dict[str, Any] = {}
    later: dict[str, Any] = {}
    if isinstance(data.get("sun"), Mapping):
        check_sun_forms({f"sun.{key}" for key in data["sun"]})
    for key, value in data.items():
        if key not in [*SECTIONS, "parts"]:
            first = next(iter(value), None) if isinstance(value, Mapping) else None
            raise unknown_key([key] if first is None else [key, str(first)], [])
        if not isinstance(value, Mapping):
            raise InputError(f"`{key}` must be a table, got {quote(value)}.")
        if key != "parts":
            sections[key] = _section(key, value, later)
    target = sections.get("target", TargetSettings())
    builtin = target.mesh in BUILTIN
    if target.mesh not in MESHLESS and not Path(target.mesh).is_absolute():
        sections["target"] = target = dataclasses.replace(target, mesh=str((base / target.mesh).resolve()))
    if target.quaternions and not Path(target.quaternions).is_absolute():
        sections["target"] = dataclasses.replace(target, quaternions=str((base / target.quaternions).resolve()))
    user_parts = data.get("parts", {})
    if target.mesh not in MESHLESS and not user_parts:
        try:
            groups = list(load_grouped(sections["target"].mesh))
            have = f"its groups: {', '.join(groups)}" if groups else "it has no named groups (give each part a `file`)"
        except InputError as err:
            have = f"it cannot be read ({err})"
        raise InputError(f"`parts` must list the parts of the mesh file `target.mesh` ({sections['target'].mesh!r}), "
                         f"each with a `material`; {have}; parts found: none.")
    scene = Scene(**sections, parts=_parts(user_parts, builtin, base))
    if "pixel_pitch_mm" in data.get("camera", {}):
        check_pitch_with_fov(scene, data["camera"]["pixel_pitch_mm"])
    return with_values(scene, later) if later else scene


def load_scene(path: str | Path | None = None, overrides: Overrides = ()) -> Scene:
    """Load a scene TOML file (or the defaults when ``path`` is None) and apply overrides.

    ``overrides``: a mapping of names (scene-file keys or parameter names, :func:`available_parameters`) to Python values (``{"camera.position_m": [0, 0, 50],
    "parts.panels.alpha_x": 0.1, "sun.elevation_deg": 30}``), or ``"key=value"`` strings with the
    value in TOML syntax, as on the command line (``--set``).

    Args:
        path: a scene TOML file; None: the default scene (:func:`default_scene`).
        overrides: values by scene-file key or parameter name, or ``"key=value"`` strings.

    Returns:
        The checked :class:`Scene`; its relative file names resolved against the file's folder.

    Raises:
        InputError: a missing or malformed file, an unknown key (the message suggests the nearest),
            a value out of range.

    Example:
        >>> import spacefit as sf
        >>> with open("lander.toml", "w") as f:
        ...     _ = f.write(sf.default_scene().to_toml())
        >>> scene = sf.load_scene("lander.toml", {"render.spp": 8, "sun.elevation_deg": 30})
        >>> scene.render.spp
        8
        >>> try:
        ...     sf.load_scene(None, {"render.sp": 8})
        ... except sf.InputError as err:
        ...     print(err)
        unknown scene key `render.sp`; valid keys here: resolution, spp, depth, seed, variant, filter, deterministic, sampler. Did you mean `render.spp`?
    """
    data = read_scene_dict(path) if path is not None else {}
    base = Path(path).parent if path is not None else Path.cwd()
    return scene_from_dict(apply_overrides(data, overrides), base)


def default_scene() -> Scene:
    """The default scene: the thesis's Table 4-2 (its lander, camera, sun and wrinkles, G read as micrometres: 1e-5 m).

    The same scene as ``sf.Scene()`` and ``sf.load_scene(None)``: a lunar lander of three parts
    (``body`` in wrinkled MLI, ``panels``, ``legs``) 70 m in front of a 600 x 600 px camera, lit by a
    sun of 5 W m^-2. Change it with :meth:`Scene.with_values` or :func:`load_scene`'s overrides.

    Returns:
        The default :class:`Scene`.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene()
        >>> scene
        Scene(600x600 px, 20 spp; camera at (0, 0, 70) m; sun 5 W m^-2; parts body (conductor), panels (conductor), legs (lambert); wrinkles D 2.3 G 1e-05 m on body)
        >>> scene.with_values({"render.resolution": [64, 64]}).render.resolution
        (64, 64)
    """
    return Scene()
