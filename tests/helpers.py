"""Small test scenes: meshes written to files and scenes that render them with few pixels."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from spacefit.precision import float64
from spacefit.scene.parameters import scene_value
from spacefit.scene.schema import Scene
from spacefit.scene.toml import scene_from_dict


def write_plate_obj(path: Path, size: float = 2.0) -> Path:
    """A square plate in the object xy plane facing +z, with uv = (x, y) so alpha_x runs along x."""
    h = size / 2
    path.write_text(
        "o plate\n"
        f"v {-h} {-h} 0\nv {h} {-h} 0\nv {h} {h} 0\nv {-h} {h} 0\n"
        f"vt {-h} {-h}\nvt {h} {-h}\nvt {h} {h}\nvt {-h} {h}\n"
        "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
    )
    return path


def write_sphere_obj(path: Path, radius: float = 1.0, subdivisions: int = 4) -> Path:
    """An icosphere of the given radius centred at the object origin."""
    trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius).export(path)
    return path


def small_scene(mesh: Path, material: dict[str, Any], **sections: dict[str, Any]) -> Scene:
    """A scene of one part ``plate`` / ``sphere`` from ``mesh`` with no wrinkles; sections override."""
    data: dict[str, Any] = {
        "render": {"resolution": [32, 32], "spp": 16, "depth": 1, "seed": 1},
        "camera": {"position_m": [0.0, 0.0, 10.0], "look_at_m": [0.0, 0.0, 0.0], "focal_length_mm": 50.0, "pixel_pitch_mm": 0.05},
        "sun": {"irradiance_w_m2": 5.0, "direction": [0.0, 0.0, -1.0]},
        "target": {"attitude_deg": [0.0, 0.0, 0.0], "mesh": str(mesh)},
        "wrinkles": {"enabled": False},
        "parts": {mesh.stem: {"file": str(mesh), **material}},
    }
    for key, value in sections.items():
        data[key] = {**data.get(key, {}), **value}
    return scene_from_dict(data)


def write_sphere_fit_case(folder: Path, subdivisions: int, size: int, spp: int) -> Path:
    """A Lambert sphere fit in ``folder``: ``ref.exr`` rendered at kd 0.5 (seed 7) and ``scene.toml``
    starting at kd 0.2, ``size`` x ``size`` px at ``spp`` (Levenberg-Marquardt converges in a few steps)."""
    import spacefit as sf

    mesh = write_sphere_obj(folder / "sphere.obj", subdivisions=subdivisions)
    truth = small_scene(mesh, {"material": "white_paint", "kd": 0.5}, camera={"pixel_pitch_mm": 0.5},
                        render={"resolution": [size, size], "spp": spp, "seed": 7})
    sf.write_exr(folder / "ref.exr", sf.render(truth))
    start = small_scene(mesh, {"material": "white_paint", "kd": 0.2}, camera={"pixel_pitch_mm": 0.5},
                        render={"resolution": [size, size], "spp": spp})
    (folder / "scene.toml").write_text(start.to_toml())
    return folder


def pixel_directions(scene: Scene) -> np.ndarray:
    """World directions from the camera through each pixel centre, (h, w, 3), unit length."""
    from spacefit.scene.assembly import assemble

    a = assemble(scene)
    intr, cam = a.intrinsics, a.camera
    u0, v0 = intr.principal_point
    jj, ii = np.meshgrid(np.arange(intr.height) + 0.5, np.arange(intr.width) + 0.5, indexing="ij")
    x = (ii - u0) / intr.focal_px
    y = -(jj - v0) / intr.focal_px
    d = x[..., None] * cam.right + y[..., None] * cam.up + cam.forward
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def lander(size: int, spp: int) -> Scene:
    """The default lander, unwrinkled, ``size`` x ``size`` px over the default field of view at ``spp``."""
    return Scene().with_values({"render.resolution": [size, size], "camera.pixel_pitch_mm": 2400.0 / size,
                                "render.spp": spp, "wrinkles.enabled": False})


def turning(count: int) -> list[dict[str, float]]:
    """``count`` points of the lander turned about z once, the sun's elevation swinging 10 to 50 deg."""
    angles = np.linspace(0.0, 360.0, count, endpoint=False)
    return [{"target.attitude_z_deg": float(a), "sun.elevation_deg": 30.0 + 20.0 * math.sin(math.radians(a))} for a in angles]


@float64
def irradiances(scene: Scene, free: tuple[str, ...], points: list[dict[str, Any]], x: list[float], seed: int = 1,
                observer_range_m: float | None = None, film_px: int | None = None, j: int = 0) -> np.ndarray:
    """The light-curve model's irradiance (W m^-2) of ``points`` at the free values ``x`` (seed index ``j``;
    ``film_px``: the points' film, :class:`~spacefit.studies.lightcurve_fit.RenderedLightCurve`'s)."""
    # here: the fitting stack (JAX), which the other helpers' tests never need
    import jax.numpy as jnp

    from spacefit.studies.lightcurve_fit import RenderedLightCurve

    curve = RenderedLightCurve(scene, points, np.zeros(len(points)), 0.05, observer_range_m=observer_range_m, seed=seed, film_px=film_px)
    return np.asarray(curve.block(free).model(jnp.asarray(x, dtype=jnp.float64), j))


def observed(scene: Scene, free: tuple[str, ...], points: list[dict[str, Any]], sigma: float) -> np.ndarray:
    """Magnitudes of ``points`` at the scene's values, rendered at 8 x its samples with another seed, plus
    normal noise of ``sigma`` mag."""
    from spacefit.studies.lightcurve import SUN_MAGNITUDES  # here: with the fitting stack, as irradiances

    truth = irradiances(scene.with_values({"render.spp": 8 * scene.render.spp}), free, points,
                        [scene_value(scene, n) for n in free], seed=77)
    magnitude = SUN_MAGNITUDES["V"] - 2.5 * np.log10(truth / scene.sun.irradiance_w_m2)
    return magnitude + sigma * np.random.default_rng(0).standard_normal(len(points))
