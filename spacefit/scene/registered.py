"""The registry's entries: each scene value a fit or a sweep may free, as a
:class:`~spacefit.scene.entries.Parameter`, with how it reads its value from a scene and which
scene-file keys it sets (its getter and setter). :mod:`spacefit.scene.parameters` gathers them
into :data:`~spacefit.scene.parameters.PARAMETERS` (:func:`all_entries`).

The material entries (``parts.P.<field>``) are derived from the registered material models' fields
(:mod:`spacefit.materials.registry`), so a model registered later, by a test's own module, is
fittable by name: :func:`all_entries` reads them each time.

The sun's angles (``sun.elevation_deg``, ``sun.azimuth_deg``) give the direction towards it,
(cos el cos az, cos el sin az, sin el); the light travels the opposite way (the scene's
``sun.direction``). Like the scene file, they are in degrees.

``image.*`` are nuisances of the image formation (an exposure scale, an offset, a Gaussian PSF, a
sub-pixel shift): a fit applies them to the render in JAX (:mod:`spacefit.fitting.nuisance`), so
they are not scene values (their getter gives the default, their setter sets nothing). Without them
free, none is applied.

``wrinkles.rms_m`` is the expected rms height of eq. 2-1 (:func:`spacefit.geometry.wm.wm_rms`). In an
image D and G trade off along a valley of nearly constant rms height; (D, rms) are the better
determined coordinates (:mod:`spacefit.scene.conversions` is the one place the two are converted).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from spacefit.materials import MODELS, Field
from spacefit.scene.conversions import G_of, rms_of, sun_angles_deg, sun_direction
from spacefit.scene.entries import POSITIVE, WHOLE_LINE, Bounds, Getter, Parameter
from spacefit.scene.sections import SceneLike

# The widest Gaussian PSF (sigma, px) a fit may try; its kernel reaches out to 5 sigma.
PSF_SIGMA_MAX_PX = 4.0
# Default start of the PSF width (px): 0, no blur, is outside its open range, and its derivative vanishes there.
PSF_SIGMA_START_PX = 0.5


# Getters and setters shared by several entries.
def _scene_field(scene: SceneLike, name: str) -> float:
    section, field = name.split(".")
    return getattr(getattr(scene, section), field)


def _own_key(scene: SceneLike, name: str, values: Mapping[str, float]) -> dict[str, Any]:
    return {name: values[name]}


def _material_value(scene: SceneLike, name: str) -> float:
    _, part, field = name.split(".")
    m = scene.parts[part].material
    return getattr(m, type(m).field(field).name)


def _constant(value: float) -> Getter:
    return lambda scene, name: value


def _not_a_scene_value(scene: SceneLike, name: str, values: Mapping[str, float]) -> dict[str, Any]:
    return {}


def _get_rms(scene: SceneLike, name: str) -> float:
    return rms_of(scene.wrinkles, scene.wrinkles.D, scene.wrinkles.G)


def _set_rms(scene: SceneLike, name: str, values: Mapping[str, float]) -> dict[str, Any]:
    """G at the scene's (or the given) D."""
    w = scene.wrinkles
    return {"wrinkles.G": float(G_of(w, values.get("wrinkles.D", w.D), values[name]))}


def _sun_angles(names: tuple[str, str], docs: tuple[str, str], bounds: tuple[Bounds, Bounds],
                labels: tuple[str, str]) -> tuple[Parameter, ...]:
    """The sun's elevation and azimuth: both set ``sun.direction``."""

    def get(scene: SceneLike, name: str) -> float:
        return sun_angles_deg(scene.sun.direction)[names.index(name)]

    def set_(scene: SceneLike, name: str, values: Mapping[str, float]) -> dict[str, Any]:
        angles = (values.get(n, get(scene, n)) for n in names)
        return {"sun.direction": sun_direction(*angles).tolist()}

    return tuple(Parameter(n, "deg", b, doc, get, set_, frozenset({"sun-angles", "joint"}), fd_step=0.5,
                           scene_fields=("direction",), scale=0.1, label=label)
                 for n, doc, b, label in zip(names, docs, bounds, labels))


def _components(
    key: str, unit: str, group: str, docs: Mapping[str, str], fd_step: float, scale: float, label: str,
) -> tuple[Parameter, ...]:
    """The x, y, z components of the scene vector ``key`` (``target.attitude_deg``), each a
    per-observation nuisance that moves every vertex: ``target.attitude_x_deg``; ``label`` is each
    one's with ``{axis}`` for its axis."""
    head, unit_suffix = key.rsplit("_", 1)
    names = tuple(f"{head}_{axis}_{unit_suffix}" for axis in "xyz")
    section, field = key.split(".")

    def get(scene: SceneLike, name: str) -> float:
        return getattr(getattr(scene, section), field)[names.index(name)]

    def set_(scene: SceneLike, name: str, values: Mapping[str, float]) -> dict[str, Any]:
        return {key: [values.get(n, get(scene, n)) for n in names]}

    groups = frozenset({group, "joint", "moves-vertices", "nuisance", "per-observation"})
    return tuple(Parameter(n, unit, WHOLE_LINE, docs[axis], get, set_, groups, fd_step=fd_step, scene_fields=(field,),
                           scale=scale, label=label.format(axis=axis))
                 for n, axis in zip(names, "xyz"))


def _material_entry(name: str, f: Field, doc: str, label: str, tied: tuple[str, ...]) -> Parameter:
    """The entry ``parts.P.<name>`` of a field (or a tie of ``tied`` fields) of the registered models."""
    models = tuple(m for m in MODELS.values() if name in m.ties or any(g.name == name for g in m.fields))
    grey = " (grey)" if f.spectral else ""
    return Parameter(f"parts.P.{name}", f.unit, Bounds(f.lo, f.hi), doc + grey, _material_value, _own_key, materials=models,
                     scene_fields=tied, label=label)


def material_entries() -> dict[str, Parameter]:
    """The ``parts.P.<field>`` entries of the registered material models' fields and ties, in
    registration order (one entry per name: models sharing a field agree on it, as
    :func:`spacefit.materials.register_material` checks)."""
    out: dict[str, Parameter] = {}
    for m in MODELS.values():
        for f in m.fields:
            out.setdefault(f"parts.P.{f.name}", _material_entry(f.name, f, f.doc, f.label, ()))
        for tie, (tied, doc, label) in m.ties.items():
            out.setdefault(f"parts.P.{tie}", _material_entry(tie, m.field(tie), doc, label, tied))
    return out


_WRINKLES = frozenset({"wrinkles", "moves-vertices"})
_IMAGE = frozenset({"image", "nuisance", "per-observation"})
_SCENE = (
    Parameter("wrinkles.D", "1", Bounds(2.0, 3.0), "W-M fractal dimension (eq. 2-1): vertex positions of every wrinkled part",
              _scene_field, _own_key, _WRINKLES, fd_step=0.02, label="fractal dimension D"),
    Parameter("wrinkles.G", "m", POSITIVE, "W-M height scale (eq. 2-1): vertex positions of every wrinkled part",
              _scene_field, _own_key, _WRINKLES, fd_step=0.01, relative_step=True, label="height scale G"),
    Parameter("wrinkles.rms_m", "m", POSITIVE, "rms height of the wrinkles: sets G at the current D",
              _get_rms, _set_rms, _WRINKLES, fd_step=0.03, relative_step=True, scene_fields=("G",), label="rms height"),
)
_OTHERS = (
    Parameter("sun.irradiance_w_m2", "W m^-2", POSITIVE, "the sun's irradiance on a surface facing it", _scene_field, _own_key,
              label="sun's irradiance"),
    *_sun_angles(("sun.elevation_deg", "sun.azimuth_deg"),
                 ("elevation of the direction towards the sun above world xy", "azimuth of the direction towards the sun, world +x to +y (reads 0 at the zenith, the default sun)"),
                 (Bounds(-90.0, 90.0), WHOLE_LINE), ("sun elevation", "sun azimuth")),
    *_components("target.attitude_deg", "deg", "attitude",
                 {axis: f"the target's attitude angle {angle} (about object {axis}, thesis 3.2): every vertex"
                  for axis, angle in zip("xyz", ("alpha", "beta", "gamma"))}, fd_step=0.5, scale=0.1,
                 label="target attitude about {axis}"),
    *_components("target.position_m", "m", "position", {axis: f"the target's world {axis} position: every vertex" for axis in "xyz"},
                 fd_step=0.02, scale=0.01, label="target position {axis}"),
    Parameter("camera.roll_deg", "deg", WHOLE_LINE,
              "the camera's turn about its optical axis (image up towards image right), either camera mode", _scene_field, _own_key,
              frozenset({"roll", "moves-vertices", "nuisance", "per-observation"}), fd_step=0.5, scale=0.1, label="camera roll"),
    Parameter("image.scale", "1", POSITIVE, "exposure scale: the render times it (fit only, after the render; default 1)",
              _constant(1.0), _not_a_scene_value, _IMAGE, label="exposure scale"),
    Parameter("image.offset_w_m2_sr", "W m^-2 sr^-1", WHOLE_LINE, "offset added to every pixel (fit only; default 0)",
              _constant(0.0), _not_a_scene_value, _IMAGE, scale=0.01, label="image offset"),
    Parameter("image.blur_sigma_px", "px", Bounds(0.0, PSF_SIGMA_MAX_PX),
              "sigma of a continuous Gaussian blur, before the pixel (fit only; no blur unless free; start 0.5)",
              _constant(PSF_SIGMA_START_PX), _not_a_scene_value, _IMAGE, scale=0.1, label="blur sigma"),
    *(Parameter(f"image.shift_{axis}_px", "px", WHOLE_LINE,
                f"sub-pixel shift of the image towards +{axis} ({where}), by a Fourier phase (fit only; default 0)",
                _constant(0.0), _not_a_scene_value, _IMAGE, scale=0.1, label=f"image shift {axis}")
      for axis, where in (("x", "columns, rightwards"), ("y", "rows, downwards"))),
)


def all_entries() -> tuple[Parameter, ...]:
    """Every entry of the registry, in its order: the wrinkles', the registered material models'
    (:func:`material_entries`, read now), then the sun's, the pose's, the camera's roll and the image nuisances."""
    return (*_SCENE, *material_entries().values(), *_OTHERS)
