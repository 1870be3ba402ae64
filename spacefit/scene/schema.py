"""The whole scene: the sections of :mod:`spacefit.scene.sections` joined and checked together.

What :func:`load_scene` reads and the sidecar of every render records. Changing
values by name is the override language's (:mod:`spacefit.scene.overrides`, which
:meth:`Scene.with_values` calls). A scene shows itself: one short line (its repr) and, in Jupyter, a table of its values.
"""

from __future__ import annotations

import dataclasses
import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from spacefit.errors import InputError, InputTypeError, check_choice, check_direction, quote
from spacefit.html_tables import html_table
from spacefit.materials import Material, make_material, material_table
from spacefit.scene.overrides import with_values
from spacefit.scene.checks import plain
from spacefit.scene.sections import SECTIONS, CameraSettings, RenderSettings, SunSettings, WrinkleSettings
from spacefit.scene.target import BUILTIN, DEFAULT_PRESETS, MESHLESS, PartSettings, TargetSettings, default_parts
from spacefit.scene.optics import check_optics, fov_pitch_mm


@dataclass(frozen=True)
class Scene:
    """A whole scene: what :func:`load_scene` reads and the sidecar of every render
    records. Checked on construction, each section by itself and here what joins them.

    The built-in lander's parts may be any of its own (body, panels, legs),
    and parts of their own (a ``file`` or a ``shape``); they are held in the order a scene file
    reads them: the lander's, in its order, then the others, in theirs. Files (``target.mesh``,
    ``target.quaternions``, a part's ``file``, a measured table's ``source``) are held as absolute paths, a relative one
    resolved against the working folder, as a scene file's against its folder: ``to_toml()``
    names the same files wherever it is read.

    Attributes:
        render, camera, sun, target, wrinkles: the scene file's sections (:class:`RenderSettings`,
            :class:`CameraSettings`, :class:`SunSettings`, :class:`TargetSettings`, :class:`WrinkleSettings`).
        parts: the parts by name (:class:`PartSettings`).

    Raises:
        InputError: a value out of range (naming it as a scene-file key), a part the target does not
            have, or sections that contradict each other.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.Scene(render=sf.RenderSettings(resolution=(64, 64)))
        >>> scene.with_values({"sun.elevation_deg": 30, "parts.legs.kd": 0.5}).parts["legs"].material
        Lambert(kd=0.5)
        >>> sf.load_scene(None) == sf.Scene()
        True
    """

    render: RenderSettings = field(default_factory=RenderSettings)
    camera: CameraSettings = field(default_factory=CameraSettings)
    sun: SunSettings = field(default_factory=SunSettings)
    target: TargetSettings = field(default_factory=TargetSettings)
    wrinkles: WrinkleSettings = field(default_factory=WrinkleSettings)
    parts: Mapping[str, PartSettings] = field(default_factory=default_parts)

    def __post_init__(self) -> None:
        for name, cls in SECTIONS.items():
            if not isinstance(getattr(self, name), cls):
                raise InputTypeError(f"`{name}` must be a {cls.__name__}, got {quote(getattr(self, name))}.")
        if not isinstance(self.parts, Mapping) or not self.parts:
            raise InputError(f"`parts` must name at least one part, got {quote(self.parts)}.")
        for name, part in self.parts.items():
            if not isinstance(part, PartSettings):
                raise InputTypeError(f"`parts.{name}` must be a PartSettings, got {quote(part)}.")
        parts = {name: _absolute(part) for name, part in self.parts.items()}
        files = {key: str(Path(value).resolve()) for key in ("mesh", "quaternions")
                 if (value := getattr(self.target, key)) not in MESHLESS and not Path(value).is_absolute()}
        if files:
            object.__setattr__(self, "target", dataclasses.replace(self.target, **files))
        if self.target.mesh in BUILTIN:
            parts = {**{name: parts[name] for name in DEFAULT_PRESETS if name in parts}, **parts}
        object.__setattr__(self, "parts", parts)
        if self.wrinkles.enabled:
            for name in self.wrinkles.parts:
                check_choice("wrinkles.parts", name, self.parts)
        if self.camera.fov_deg > 0.0:
            object.__setattr__(self, "camera", dataclasses.replace(self.camera, pixel_pitch_mm=fov_pitch_mm(self.camera, self.render)))
        check_optics(self.camera, self.render)
        if self.target.attitude in ("nadir_sun", "sun"):  # the sun along nadir leaves the attitude undefined
            self.target.rotation(-check_direction("sun.direction", self.sun.direction))

    def __repr__(self) -> str:
        """One short line: the film, the camera, the sun, the parts and their materials, the wrinkles; ``to_toml()``
        gives every value."""
        r, c, w = self.render, self.camera, self.wrinkles
        parts = ", ".join(f"{name} ({p.material.__class__.__name__.lower()})" for name, p in self.parts.items())
        wrinkles = f"wrinkles D {w.D:g} G {w.G:g} m on {', '.join(w.parts)}" if w.enabled else "no wrinkles"
        return (f"Scene({r.resolution[0]}x{r.resolution[1]} px, {r.spp} spp; camera at {_vector(c.position_m)} m; "
                f"sun {self.sun.irradiance_w_m2:g} W m^-2; parts {parts}; {wrinkles})")

    def _repr_html_(self) -> str:
        """The repr line, then each section's values (:meth:`to_dict`) in a table."""
        rows = []
        for section, values in self.to_dict().items():
            items = values.items() if section != "parts" else (  # a lander's part it lacks is `parts.NAME = false`
                row for part, t in values.items() for row in (((f"{part}.{k}", v) for k, v in t.items()) if isinstance(t, dict) else [(part, t)]))
            rows += [(section, key, _vector(v) if isinstance(v, list) and all(isinstance(x, float) for x in v) else v)
                     for key, v in items]
        return f"<p>{html.escape(repr(self))}</p>" + html_table(("section", "key", "value"), rows)

    def mesh_files(self) -> list[str]:
        """The mesh files the scene reads (none for the built-in lander)."""
        paths = (self.target.mesh, *(part.file for part in self.parts.values()))
        return list(dict.fromkeys(str(p) for p in paths if p not in MESHLESS))

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (TOML-ready): every value, defaults included, of the camera's field the
        one that sets it (``camera.fov_deg`` when > 0, else ``camera.pixel_pitch_mm``); each material in
        full; each part of the built-in lander that the scene lacks as ``parts.NAME = false``."""
        out: dict[str, Any] = {name: {k: plain(v) for k, v in dataclasses.asdict(getattr(self, name)).items()}
                               for name in SECTIONS}
        # One of the two sets the field: the pitch follows from a field of view and the resolution.
        del out["camera"]["pixel_pitch_mm" if self.camera.fov_deg > 0.0 else "fov_deg"]
        out["parts"] = {name: {**material_table(p.material), **({"file": p.file} if p.file else {}),
                               **(p.shape.table() if p.shape is not None else {}), **p.articulation.table()}
                        for name, p in self.parts.items()}
        if self.target.mesh in BUILTIN:  # a scene file's lander has all its parts but those removed
            out["parts"] = {**{name: False for name in DEFAULT_PRESETS if name not in self.parts}, **out["parts"]}
        return out

    def to_toml(self) -> str:
        """The scene as TOML text, loadable by :func:`load_scene` to an equal scene.
        A material that its written values do not give again is refused, naming its part: a measured
        table (whose file states its ``source`` and ``scale``) read with a ``floor`` or made from arrays."""
        for name, part in self.parts.items():
            _check_written(f"parts.{name}", part.material)
        return tomli_w.dumps(self.to_dict())

    def replace(self, **sections: Any) -> Scene:
        """A checked copy with some sections replaced by keyword (``render=...``)."""
        return dataclasses.replace(self, **sections)

    def with_values(self, values: Mapping[str, Any]) -> Scene:
        """A checked copy with values replaced by name: scene-file keys (``camera.position_m``,
        ``parts.panels.alpha_x``) or parameter names (``sun.elevation_deg``) (:func:`available_parameters`)."""
        return with_values(self, values)


def _absolute(part: PartSettings) -> PartSettings:
    """``part`` with its ``file`` and its material's files (a measured table's ``source``, where it
    names a file) as absolute paths, relative ones resolved against the working folder."""
    material = part.material
    files = {key: str(Path(value).resolve()) for key in type(material).paths
             if isinstance(value := getattr(material, key), str) and value and not Path(value).is_absolute() and Path(value).is_file()}
    if not files and (not part.file or Path(part.file).is_absolute()):
        return part
    return dataclasses.replace(part, material=dataclasses.replace(material, **files) if files else material,
                               file=str(Path(part.file).resolve()) if part.file else "")


def _check_written(where: str, material: Material) -> None:
    """Refuse a material with values derived from others (a measured table's arrays) that its
    written values (:func:`~spacefit.materials.material_table`) do not give again."""
    if not any(f.metadata.get("derived") for f in dataclasses.fields(material)):
        return
    table = material_table(material)
    try:
        again: object = make_material(str(table.pop("material")), table, where=where)
    except InputError as err:
        again = err
    if again != material:
        states = ", ".join(f"{key} = {value!r}" for key, value in table.items())
        found = f"cannot be read ({again})" if isinstance(again, InputError) else "give another table"
        raise InputError(f"`{where}` cannot be written to a scene file, which states its {states}: these {found} (a table "
                         f"read with a floor, or made from arrays); write the table it renders to a file and give that file as `source`.")


def _vector(v: Sequence[float]) -> str:
    """A vector as a scene's repr shows it: ``(x, y, z)``."""
    return "(" + ", ".join(f"{x:g}" for x in v) + ")"
