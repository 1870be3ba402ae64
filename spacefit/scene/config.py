"""Scene description: dataclasses read from and written to TOML, with overrides and validation.

Defaults are the thesis's Table 4-2. Units are in the key names: metres (``_m``), millimetres for
the optics as the thesis gives them (``_mm``), degrees at this user-facing edge only (``_deg``),
irradiance in W m^-2. The sun's ``direction`` is the direction the light travels.

The thesis's "light radiance 5 W m^-2 sr^-1" for its distant light is, in pbrt's convention, the
irradiance on a surface facing the light: ``sun.irradiance_w_m2 = 5``. ``"physical"`` selects the
total solar irradiance at 1 au, 1361 W m^-2 (Kopp & Lean 2011).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_choice, check_direction, check_range, check_vector, quote

SOLAR_IRRADIANCE_W_M2 = 1361.0
# The differentiable variants: the bridge needs AD (scalar variants cannot render a Jacobian).
VARIANTS = ("auto", "llvm_ad_rgb", "cuda_ad_rgb")
# Mitsuba's pixel filters and how far (px) each spreads a sample: the tent's radius 1, the box's
# half pixel, the Gaussian's 4 standard deviations of 0.5 px.
FILTER_RADIUS_PX = {"tent": 1.0, "box": 0.5, "gaussian": 2.0}
FILTERS = tuple(FILTER_RADIUS_PX)
# Mitsuba samplers; "independent" draws every sample alone, the others stratify a pixel's samples.
SAMPLERS = ("independent", "stratified", "multijitter", "ldsampler")
WRINKLE_MODELS = ("auto", "geometry", "effective")
Vec3 = tuple[float, float, float]
# Radiance is float32 (at most 3.4e38) and a glint's BRDF can reach 1e6 or more: irradiances above
# this overflow it (1e39 rendered inf / NaN). The physical sun at 1 au is 1361 W m^-2.
MAX_IRRADIANCE_W_M2 = 1e20
# Mitsuba traces in float32 (7 significant digits): beyond 100 km from the origin a position is
# coarser than 1 cm and a metre-sized target is no longer resolved; the observer of a far target is
# rendered near and rescaled (light curves), or seen with a long focal length.
MAX_COORDINATE_M = 1e5


@dataclass(frozen=True)
class RenderSettings:
    """Image size (width, height px), samples per pixel, thesis trace depth, seed, backend, filter.

    ``depth`` is the thesis's (pbrt's) trace depth: the number of bounces after the camera ray's
    first hit; Mitsuba's ``max_depth`` is ``depth + 1``. Depth 1 is direct sun light only.

    ``deterministic`` makes a seed give a bitwise-identical image on the CPU: Mitsuba's film adds
    float32 samples from parallel threads in a varying order (differences about 1e-7 relative), so
    deterministic renders run on one thread (about 2x slower on 2 cores). On CUDA images agree to
    that rounding only.

    ``sampler`` is Mitsuba's: ``multijitter`` stratifies each pixel's samples on a jittered grid of
    any count and reaches the error of ``independent`` (the default) with about half the samples on
    the default scene (``experiments/forward_pareto.py --methods``). Each is unbiased and one seed
    gives one image. ``independent`` stays the default until fits stop reliably at the lower noise
    floor that ``multijitter`` gives (a resumed LM fit then ran into its step limit).
    """

    resolution: tuple[int, int] = (600, 600)
    spp: int = 20
    depth: int = 2
    seed: int = 0
    variant: str = "auto"
    filter: str = "tent"
    deterministic: bool = True
    sampler: str = "independent"

    def validate(self) -> None:
        for i, axis in enumerate(("width", "height")):
            _check_int(f"render.resolution ({axis})", self.resolution[i], 1, 16384)
        _check_int("render.spp", self.spp, 1, 1 << 16)
        _check_int("render.depth", self.depth, 1, 64)
        _check_int("render.seed", self.seed, 0, 2**31 - 1)
        check_choice("render.variant", self.variant, VARIANTS)
        check_choice("render.filter", self.filter, FILTERS)
        check_choice("render.sampler", self.sampler, SAMPLERS)
        # Mitsuba would round other counts up (20 -> 25 or 64) with only a log line: more time than asked.
        if self.sampler == "stratified" and math.isqrt(self.spp) ** 2 != self.spp:
            raise InputError(f"`render.spp` = {self.spp} must be a perfect square with render.sampler = 'stratified' "
                             "(4, 9, 16, 25, ...); 'multijitter' takes any count.")
        if self.sampler == "ldsampler" and (self.spp & (self.spp - 1) or math.isqrt(self.spp) ** 2 != self.spp):
            raise InputError(f"`render.spp` = {self.spp} must be a power of 4 with render.sampler = 'ldsampler' "
                             "(4, 16, 64, 256, ...); 'multijitter' takes any count.")


@dataclass(frozen=True)
class CameraSettings:
    """Pinhole camera: optics in mm as in Table 4-2, pose by attitude or by ``look_at_m``.

    ``principal_offset_px`` moves the principal point from the image centre (u right, v down).
    When ``look_at_m`` holds 3 numbers it replaces ``attitude_deg``, with ``up`` as image up.
    ``roll_deg`` then turns the camera about its optical axis, in either mode (right-handed about the
    viewing direction: image up turns towards image right, the scene turns anticlockwise in the image).
    """

    focal_length_mm: float = 7000.0
    pixel_pitch_mm: float = 4.0
    principal_offset_px: tuple[float, float] = (0.0, 0.0)
    position_m: Vec3 = (0.0, 0.0, 70.0)
    attitude_deg: Vec3 = (0.0, 0.0, 0.0)
    look_at_m: tuple[float, ...] = ()
    up: Vec3 = (0.0, 1.0, 0.0)
    roll_deg: float = 0.0

    def validate(self) -> None:
        check_range("camera.focal_length_mm", self.focal_length_mm, 0.0, lo_open=True, unit="mm")
        check_range("camera.pixel_pitch_mm", self.pixel_pitch_mm, 0.0, lo_open=True, unit="mm")
        check_vector("camera.principal_offset_px", self.principal_offset_px, 2)
        check_position("camera.position_m", self.position_m)
        check_vector("camera.attitude_deg", self.attitude_deg)
        if len(self.look_at_m) not in (0, 3):
            raise InputError(f"`camera.look_at_m` must be empty or 3 numbers, got {list(self.look_at_m)}.")
        if self.look_at_m:
            check_position("camera.look_at_m", self.look_at_m)
        check_direction("camera.up", self.up)
        check_range("camera.roll_deg", self.roll_deg, unit="deg")


@dataclass(frozen=True)
class SunSettings:
    """One distant sun: irradiance on a surface facing it (W m^-2) and direction of travel."""

    irradiance_w_m2: float = 5.0
    direction: Vec3 = (0.0, 0.0, -1.0)

    def validate(self) -> None:
        check_range("sun.irradiance_w_m2", self.irradiance_w_m2, 0.0, MAX_IRRADIANCE_W_M2, lo_open=True, unit="W m^-2")
        check_direction("sun.direction", self.direction)


@dataclass(frozen=True)
class TargetSettings:
    """Target pose and geometry source: ``"builtin"`` or a mesh file whose groups are the parts."""

    position_m: Vec3 = (0.0, 0.0, 0.0)
    attitude_deg: Vec3 = (90.0, 0.0, 0.0)
    mesh: str = "builtin"

    def validate(self) -> None:
        check_position("target.position_m", self.position_m)
        check_vector("target.attitude_deg", self.attitude_deg)


@dataclass(frozen=True)
class WrinkleSettings:
    """W-M wrinkles (thesis eq. 2-1, section 2.2) on the named parts; lengths in metres.

    D, gamma, M, L and Ls are the thesis's values. Its G = 10 read in metres, like L and Ls, gives
    an rms height of 0.27 m on a 1.4 m body and an rms slope of 37 (spikes like hair; the body
    folds over itself), and no common unit for all lengths changes the slope. The default G is
    1e-5 m, the thesis's "10" read as micrometres with L and Ls in metres: rms height 4.3 mm, rms
    slope 0.59, inside :data:`spacefit.geometry.wrinkle.MLI_SLOPE_RANGE` (crumpled foil). The literal
    reading is kept as the scene ``data/scenes/thesis-literal.toml`` (README, "Wrinkles").

    ``spacing_m`` is the refinement density: the distance between the sample points that carry
    heights (the thesis's sampling grid inside each triangle).

    ``model`` chooses how wrinkles are rendered: ``"geometry"`` displaces a refined mesh, the
    thesis's way; ``"effective"`` keeps the flat mesh and widens the part's microfacet roughness by
    the wrinkles' slopes (:func:`spacefit.scene.lod.effective_material`); ``"auto"`` (default)
    takes the effective model, cheaper and far less noisy, where a pixel at the part spans at least
    ``lod_footprint`` times the largest wrinkle (L) and the wrinkles are gentle enough for a
    roughness, and the geometry otherwise. The default ``lod_footprint`` is where the level of
    detail study measured the effective model within :data:`spacefit.scene.lod.LOD_TOLERANCE` of
    the geometry (README, "Level of detail"). Fits render the geometry for ``"auto"``.
    """

    enabled: bool = True
    parts: tuple[str, ...] = ("body",)
    D: float = 2.3
    G: float = 1e-5
    gamma: float = 1.5
    M: int = 5
    L: float = 0.1
    Ls: float = 5e-3
    seed: int = 0
    spacing_m: float = 0.02
    model: str = "auto"
    lod_footprint: float = 3.0

    def validate(self) -> None:
        from spacefit.geometry.wm import check_wm_params

        check_wm_params(self.D, self.G, self.gamma, self.M, self.L, self.Ls)
        _check_int("wrinkles.seed", self.seed, 0, 2**31 - 1)
        check_range("wrinkles.spacing_m", self.spacing_m, 0.0, lo_open=True, unit="m")
        check_choice("wrinkles.model", self.model, WRINKLE_MODELS)
        check_range("wrinkles.lod_footprint", self.lod_footprint, 0.0, lo_open=True)


@dataclass(frozen=True)
class PartSettings:
    """A part's material preset name, optional mesh file, and overrides of the preset's values."""

    material: str
    file: str = ""
    overrides: Mapping[str, Any] = field(default_factory=dict)


def _default_parts() -> dict[str, PartSettings]:
    return {
        "body": PartSettings("mli_thesis"),
        "panels": PartSettings("panel_thesis"),
        "legs": PartSettings("white_paint"),
    }


@dataclass(frozen=True)
class Scene:
    """A whole scene: what :func:`load_scene` reads and the sidecar of every render records."""

    render: RenderSettings = field(default_factory=RenderSettings)
    camera: CameraSettings = field(default_factory=CameraSettings)
    sun: SunSettings = field(default_factory=SunSettings)
    target: TargetSettings = field(default_factory=TargetSettings)
    wrinkles: WrinkleSettings = field(default_factory=WrinkleSettings)
    parts: Mapping[str, PartSettings] = field(default_factory=_default_parts)

    def validate(self) -> Scene:
        """Check every value; return ``self`` for chaining. Geometry-dependent checks come later."""
        for section in (self.render, self.camera, self.sun, self.target, self.wrinkles):
            section.validate()
        if not self.parts:
            raise InputError("`parts` must name at least one part.")
        if self.wrinkles.enabled:
            for name in self.wrinkles.parts:
                check_choice("wrinkles.parts", name, self.parts)
        from spacefit.materials import make_material

        for name, part in self.parts.items():
            make_material(part.material, part.overrides, where=f"parts.{name}")
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (TOML-ready): every value, defaults included."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name == "parts":
                out["parts"] = {
                    name: {"material": p.material, **({"file": p.file} if p.file else {}), **dict(p.overrides)}
                    for name, p in self.parts.items()
                }
            else:
                out[f.name] = {k: _plain(v) for k, v in dataclasses.asdict(getattr(self, f.name)).items()}
        return out

    def to_toml(self) -> str:
        """The scene as TOML text, loadable by :func:`load_scene`."""
        return tomli_w.dumps(self.to_dict())

    def replace(self, **sections: Any) -> Scene:
        """A copy with some sections replaced by keyword (``render=...``)."""
        return dataclasses.replace(self, **sections)

    def with_values(self, values: Mapping[str, Any]) -> Scene:
        """A validated copy with scene-file values replaced, by dotted key and Python value.

        ``scene.with_values({"camera.position_m": [0, 0, 50], "parts.panels.alpha_x": 0.1})``;
        the keys are the scene file's (:func:`load_scene` lists the valid ones on a typo).
        """
        if not isinstance(values, Mapping):
            raise InputTypeError(f"`values` must be a mapping of dotted scene keys to values, got {quote(values)}.")
        return scene_from_dict(apply_overrides(self.to_dict(), values))


def check_scene(scene: object, name: str = "scene") -> Scene:
    """Raise :class:`InputTypeError` unless ``scene`` is a :class:`Scene`."""
    if not isinstance(scene, Scene):
        raise InputTypeError(f"`{name}` must be a spacefit Scene (sf.load_scene(path) reads a file, sf.default_scene() "
                             f"is Table 4-2), got {quote(scene)}.")
    return scene


def check_position(name: str, value: Sequence[float]) -> None:
    """Check a position (m): 3 finite numbers, each within :data:`MAX_COORDINATE_M` of the origin."""
    v = check_vector(name, value)
    if np.abs(v).max() > MAX_COORDINATE_M:
        raise InputError(f"`{name}` must lie within {MAX_COORDINATE_M:g} m of the origin on each axis (float32 "
                         f"tracing), got {quote(list(value))}; render far targets near and rescale, or lengthen the focal length.")


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _check_int(name: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"`{name}` must be an integer in [{lo}, {hi}], got {quote(value)}.")
    return int(check_range(name, value, lo, hi))


_SECTIONS = {
    "render": RenderSettings,
    "camera": CameraSettings,
    "sun": SunSettings,
    "target": TargetSettings,
    "wrinkles": WrinkleSettings,
}


def _unknown(where: str, key: str, valid: Sequence[str]) -> InputError:
    close = difflib.get_close_matches(key, list(valid), n=1)
    hint = f" Did you mean `{where}{close[0]}`?" if close else ""
    return InputError(f"unknown scene key `{where}{key}`; valid keys here: {', '.join(sorted(valid))}.{hint}")


def _coerce(name: str, value: Any, default: Any) -> Any:
    """Convert a TOML value to the type of the field's default (numbers, vectors, strings)."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InputError(f"`{name}` must be true or false, got {value!r}.")
        return value
    if isinstance(default, int):
        return value  # range and integrality are checked by validate()
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"`{name}` must be a number, got {value!r}.")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise InputError(f"`{name}` must be a string, got {value!r}.")
        return value
    if not isinstance(value, (list, tuple)):
        raise InputError(f"`{name}` must be a list, got {value!r}.")
    if default and isinstance(default[0], str):
        return tuple(str(v) for v in value)
    if default and len(value) != len(default):
        raise InputError(f"`{name}` must have {len(default)} entries, got {list(value)}.")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise InputError(f"`{name}` must hold numbers, got {list(value)}.")
    return tuple(v if isinstance(d, int) and not isinstance(d, bool) else float(v) for v, d in zip(value, default or value))


def _section(cls: type, data: Mapping[str, Any], where: str) -> Any:
    defaults = cls()
    names = [f.name for f in dataclasses.fields(cls)]
    kwargs = {}
    for key, value in data.items():
        if key not in names:
            raise _unknown(f"{where}.", key, names)
        if cls is SunSettings and key == "irradiance_w_m2" and value == "physical":
            value = SOLAR_IRRADIANCE_W_M2
        kwargs[key] = _coerce(f"{where}.{key}", value, getattr(defaults, key))
    return cls(**kwargs)


def _parts(data: Mapping[str, Any], base_dir: Path) -> dict[str, PartSettings]:
    parts = {}
    for name, table in data.items():
        if not isinstance(table, Mapping):
            raise InputError(f"`parts.{name}` must be a table with at least `material`, got {table!r}.")
        if "material" not in table:
            raise InputError(f"`parts.{name}.material` is missing (a preset name).")
        file = str(table.get("file", ""))
        if file and not Path(file).is_absolute():
            file = str((base_dir / file).resolve())
        overrides = {k: v for k, v in table.items() if k not in ("material", "file")}
        parts[name] = PartSettings(str(table["material"]), file, overrides)
    return parts


def scene_from_dict(data: Mapping[str, Any], base_dir: str | Path = ".") -> Scene:
    """Build and validate a :class:`Scene` from nested mappings; missing keys take defaults.

    With the built-in lander, ``parts`` tables merge into the default parts (so
    ``parts.panels.alpha_x = 0.1`` keeps the panels' preset); with a mesh file the parts are
    exactly those given. Relative mesh paths are resolved against ``base_dir`` (the TOML's folder).
    """
    base = Path(base_dir)
    sections: dict[str, Any] = {}
    for key, value in data.items():
        if key == "parts":
            if not isinstance(value, Mapping):
                raise InputError(f"`parts` must be a table of parts, got {value!r}.")
        elif key in _SECTIONS:
            if not isinstance(value, Mapping):
                raise InputError(f"`{key}` must be a table, got {value!r}.")
            sections[key] = _section(_SECTIONS[key], value, key)
        else:
            raise _unknown("", key, [*_SECTIONS, "parts"])
    target = sections.get("target", TargetSettings())
    builtin = target.mesh in ("builtin", "")
    if not builtin and not Path(target.mesh).is_absolute():
        sections["target"] = dataclasses.replace(target, mesh=str((base / target.mesh).resolve()))
    user_parts = data.get("parts", {})
    if not builtin and not user_parts:
        raise InputError("`parts` must list the parts of the mesh file `target.mesh`, each with a `material`.")
    defaults = Scene().to_dict()["parts"] if builtin else {}
    merged = dict(defaults)
    for name, table in user_parts.items():
        merged[name] = {**defaults[name], **table} if name in defaults and isinstance(table, Mapping) else table
    sections["parts"] = _parts(merged, base)
    return Scene(**sections).validate()


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse ``a.b.c=value`` (value in TOML syntax; bare words are strings) into a key path and value."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise InputError(f"override {text!r} must look like `section.key=value`.")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    except RecursionError:
        raise InputError(f"the value of override `{key.strip()}` is nested too deep: {quote(raw)}.") from None
    return [k.strip() for k in key.split(".")], value


Overrides = Mapping[str, Any] | Sequence[str] | str


def _override_items(overrides: Overrides) -> list[tuple[list[str], Any]]:
    """Key paths and values from a mapping ``{"a.b": value}``, ``"a.b=value"`` strings, or one such string."""
    if isinstance(overrides, Mapping):
        for key in overrides:
            if not isinstance(key, str) or not key.strip():
                raise InputError(f"scene value keys must be dotted names like 'camera.position_m', got {key!r}.")
        return [([k.strip() for k in key.split(".")], _plain_value(value)) for key, value in overrides.items()]
    if isinstance(overrides, str):
        overrides = [overrides]
    if not all(isinstance(text, str) for text in overrides):
        raise InputError(f"scene overrides must be a mapping of key -> value or 'key=value' strings, got {overrides!r}.")
    return [parse_override(text) for text in overrides]


def _plain_value(value: Any) -> Any:
    """A Python value as the scene file would hold it: numpy / JAX scalars and arrays as numbers and lists."""
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return value.tolist()
    if isinstance(value, tuple):
        return [_plain_value(v) for v in value]
    return value


def apply_overrides(data: dict[str, Any], overrides: Overrides) -> dict[str, Any]:
    """Return a deep copy of scene ``data`` with overrides applied (see :func:`load_scene`)."""
    import copy

    out = copy.deepcopy(data)
    for path, value in _override_items(overrides):
        node = out
        for k in path[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise InputError(f"scene key {'.'.join(path)!r}: {k!r} is not a table.")
        node[path[-1]] = value
    return out


def read_scene_dict(path: str | Path) -> dict[str, Any]:
    """Read a scene TOML file as a nested dict (no validation yet)."""
    if not isinstance(path, (str, Path)):
        raise InputTypeError(f"the scene file must be a path (str or pathlib.Path), got {quote(path)}.")
    p = Path(path)
    if p.is_dir():
        raise InputError(f"scene file {str(p)!r} is a folder; give the TOML file in it.")
    if not p.is_file():
        raise InputError(f"scene file {str(p)!r} does not exist.")
    try:
        return tomllib.loads(p.read_text(encoding="utf-8-sig"))  # a byte-order mark is not TOML
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise InputError(f"scene file {str(p)!r} is not valid TOML: {err}") from None
    except RecursionError:
        raise InputError(f"scene file {str(p)!r} holds arrays or tables nested too deep to read.") from None


def load_scene(path: str | Path | None = None, overrides: Overrides = ()) -> Scene:
    """Load a scene TOML file (or the defaults when ``path`` is None) and apply overrides.

    ``overrides``: a mapping of dotted scene keys to Python values
    (``{"camera.position_m": [0, 0, 50], "parts.panels.alpha_x": 0.1}``), or ``"key=value"``
    strings with the value in TOML syntax, as on the command line (``--set``).
    """
    data = read_scene_dict(path) if path is not None else {}
    base = Path(path).parent if path is not None else Path.cwd()
    return scene_from_dict(apply_overrides(data, overrides), base)


def default_scene() -> Scene:
    """The default scene: the thesis's Table 4-2 (its lander, camera, sun and wrinkles, G read as micrometres: 1e-5 m)."""
    return Scene().validate()


def deg2rad(values: Sequence[float]) -> tuple[float, ...]:
    """Degrees (user-facing) to radians (everything inside)."""
    return tuple(math.radians(v) for v in values)
