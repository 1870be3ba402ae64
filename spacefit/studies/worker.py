"""One sweep point, rendered in a process that keeps its loaded scene: the in-process sweep and each
dask worker run :func:`run_task` alike, so both give the same numbers for the same seeds.

A point's scene-file values (camera, resolution, sun direction, mesh...) select the loaded scene; its
registered parameters (materials, sun angles, pose, wrinkles) are set in place on it
(:meth:`~spacefit.rendering.renderer.Renderer.set_values`), about 25x faster than loading the scene
again. The process keeps one loaded scene at a time: Mitsuba leaks memory on every load
(mitsuba3#1890), and a sweep visits its points grouped by scene values. It is loaded again when
its mesh files' status (inode, size, modification time) is not what it was before the last load.
"""

from __future__ import annotations

import functools
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.digests import status
from spacefit.errors import InputError
from spacefit.geometry.frames import pixel_solid_angles
from spacefit.rendering.parts import PartImage
from spacefit.scene.parameters import scene_with_values
from spacefit.scene.schema import Scene
from spacefit.scene.toml import scene_from_dict
from spacefit.studies.sensitivity import TARGET, point_summaries, sensitivity

if TYPE_CHECKING:  # types only: Mitsuba takes seconds to import
    from spacefit.rendering.renderer import Renderer


@dataclass(frozen=True)
class Task:
    """A whole render: the scene (TOML text), what to set in place, and what to return.

    Attributes:
        scene_toml: the scene with this point's scene-file values.
        regions: the regions the sweep's store holds, in its order (:func:`regions` of the sweep's
            scene): the results are looked up by these names, and a rendered scene of other parts
            is an error.
        in_place: registered parameter name -> value (its unit), set on the loaded scene.
        crop: render only the target's window (False when the swept values move vertices).
        spp, seed: samples per pixel and seed of the render (None: the scene's).
        images: return the radiance image.
        derivatives: parameters whose derivatives to return (:func:`spacefit.studies.sensitivity.sensitivity`).
        derivative_seeds: independent seeds of each derivative.
    """

    scene_toml: str
    regions: tuple[str, ...]
    in_place: tuple[tuple[str, float], ...] = ()
    crop: bool = True
    spp: int | None = None
    seed: int | None = None
    images: bool = False
    derivatives: tuple[str, ...] = ()
    derivative_seeds: int = 4


class _Loaded:
    """The process's loaded scene: (scene TOML, crop) -> renderer, its rendered window's pixels' solid
    angles and part image (outside the window the image is black and sees no part), and the values last
    set in place."""

    key: tuple[Any, ...] | None = None
    renderer = None
    solid_angles: np.ndarray | None = None
    part_image = None
    in_place: tuple[tuple[str, float], ...] = ()
    renders = 0


@functools.lru_cache(maxsize=4)
def scene_of(toml: str) -> Scene:
    """The scene a task's TOML text describes (mesh paths in it are absolute)."""
    return scene_from_dict(tomllib.loads(toml))


def regions(scene: Scene) -> list[str]:
    """The regions a sweep summarises: each part, then the whole target."""
    return [*scene.parts, TARGET]


def summaries(radiance: np.ndarray, part_image: object, solid_angles: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
    """Per region: ``mean_radiance`` (W m^-2 sr^-1, mean over the pixels whose centre sees it, NaN if
    none), ``pixels`` and ``irradiance`` (W m^-2: the sum of radiance times pixel solid angle over
    its pixels, at the camera's pinhole; for the target, over the whole image, edges included).
    Radiance is the mean of the RGB channels (the sun's irradiance is the same in each)."""
    pixels, means = part_image.means(radiance)
    order = _columns(part_image.regions, names)
    grey = np.asarray(radiance, dtype=float).mean(axis=-1) * solid_angles
    ids = part_image.ids
    irradiance = [grey.sum() if n == TARGET else grey[ids == part_image.names.index(n)].sum() for n in names]
    return {"mean_radiance": means[order], "pixels": pixels[order].astype(np.int32), "irradiance": np.array(irradiance)}


def loaded(task: Task) -> type[_Loaded]:
    """The process's renderer for the task's scene, loaded if the scene changed."""
    from spacefit.rendering.renderer import Renderer  # here: Mitsuba takes seconds to import; a sweep's planning never renders

    scene = scene_of(task.scene_toml)
    key = (task.scene_toml, task.crop, status(scene.mesh_files()))
    if _Loaded.key != key:
        _Loaded.key, _Loaded.renderer = None, None  # drop the old scene before loading the new one
        renderer = Renderer(scene, crop=task.crop)
        _Loaded.key, _Loaded.renderer, _Loaded.in_place = key, renderer, ()
        _Loaded.solid_angles = renderer.to_window(pixel_solid_angles(renderer.assembly.intrinsics))
        _Loaded.part_image = window_parts(renderer)
    return _Loaded


def window_parts(renderer: Renderer) -> PartImage:
    """The renderer's part image over its rendered window (:meth:`~spacefit.rendering.renderer.Renderer.to_window`)."""
    parts = renderer.part_image()
    return PartImage(renderer.to_window(parts.ids), parts.names)


def render_count() -> int:
    """Renders this process has made for sweeps (a dask worker is restarted after a bound)."""
    return _Loaded.renders


def run_task(task: Task) -> dict[str, np.ndarray]:
    """Render one point; returns its variables by name (see :func:`summaries`; ``radiance`` (h, w, 3)
    when asked; the derivative summaries of :func:`spacefit.studies.sensitivity.point_summaries`)."""
    state = loaded(task)
    renderer = state.renderer
    if task.in_place and task.in_place != state.in_place:  # a point's seeds follow one another: set once
        renderer.set_values(dict(task.in_place))
        state.in_place = task.in_place
        if not task.crop:  # the swept values move vertices: which part each pixel sees changes
            state.part_image = window_parts(renderer)
    radiance = renderer.render(spp=task.spp, seed=task.seed)
    state.renders += 1
    scene = renderer.assembly.scene
    # summed over the rendered window only: black outside it, where no pixel sees a part
    out = summaries(renderer.to_window(radiance), state.part_image, state.solid_angles, task.regions)
    if task.images:
        out["radiance"] = radiance
    if task.derivatives:
        render = {k: v for k, v in (("render.seed", task.seed), ("render.spp", task.spp)) if v is not None}
        point = scene_with_values(scene.with_values(render), dict(task.in_place))
        sens = sensitivity(point, task.derivatives, seeds=task.derivative_seeds, quiet=True)
        order = _columns(sens.regions, task.regions)
        out.update({k: v[:, order] for k, v in point_summaries(sens).items()})
    return out


def _columns(rendered: Sequence[str], expected: Sequence[str]) -> list[int]:
    """The column of each ``expected`` region (the sweep's store's) in a render's ``rendered`` ones,
    found by name; regions that differ are refused, naming both (their numbers would land in other
    regions' columns)."""
    if sorted(rendered) != sorted(expected):
        raise InputError(f"the rendered scene's regions ({', '.join(rendered)}) are not the sweep's ({', '.join(expected)}): "
                         f"the scene changed on its way through its TOML text (Scene.to_toml).")
    return [list(rendered).index(name) for name in expected]
