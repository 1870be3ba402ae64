"""Mitsuba 3 scene built from an :class:`~spacefit.scene.assembly.Assembly`, loaded once.

Radiance is in W m^-2 sr^-1 per RGB channel: the sun's irradiance is the same in each channel, so a
Lambert part with kd 0.2 facing a sun of 5 W m^-2 reads 0.2 * 5 / pi in every channel.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

import numpy as np

from spacefit.geometry.frames import project
from spacefit.materials import Conductor, Lambert, Material, Mirror
from spacefit.progress import ProgressCallback
from spacefit.render.backend import dr, mi, select_variant
from spacefit.scene.assembly import Assembly, assemble
from spacefit.scene.config import Scene

# Samples traced per pass: bounds the wavefront's memory (about 1 GB on the CPU) on big renders.
MAX_SAMPLES_PER_PASS = 1 << 24
# Pixels around the target's projected box that its light can still reach: the tent filter's
# radius (1 px) and one for rounding.
CROP_MARGIN_PX = 2


def _spectrum(value: float | tuple[float, ...]) -> dict | float:
    return {"type": "rgb", "value": list(value)} if isinstance(value, tuple) else float(value)


def bsdf_dict(material: Material) -> dict:
    """Mitsuba BSDF for a material; the microfacet distribution is always named (Mitsuba's default is Beckmann)."""
    if isinstance(material, Conductor):
        return {
            "type": "roughconductor",
            "distribution": material.distribution,
            "alpha_u": material.alpha_x,
            "alpha_v": material.alpha_y,
            "eta": _spectrum(material.eta),
            "k": _spectrum(material.k),
        }
    if isinstance(material, Mirror):
        return {"type": "conductor", "eta": _spectrum(material.eta), "k": _spectrum(material.k)}
    if isinstance(material, Lambert):
        kd = material.kd if isinstance(material.kd, tuple) else (material.kd,) * 3
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(kd)}}
    raise TypeError(f"no Mitsuba BSDF for {type(material).__name__}")


def mesh_object(name: str, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None, material: Material) -> "mi.Mesh":
    """A flat-shaded Mitsuba mesh with its BSDF; uv (if any) fixes the tangent along dp/du."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf_dict(material))
    mesh = mi.Mesh(name, len(vertices), len(faces), props, has_vertex_normals=False, has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.ravel(vertices).astype(np.float32))
    params["faces"] = mi.UInt32(np.ravel(faces).astype(np.uint32))
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(np.ravel(uv).astype(np.float32))
    params.update()
    return mesh


def target_window(assembly: Assembly, vertices: Mapping[str, np.ndarray]) -> tuple[int, int, int, int]:
    """The film window (x0, y0, width, height), px, outside which the image is black: the projected
    box of every vertex of the target (world ``vertices`` per part, m), widened by
    :data:`CROP_MARGIN_PX` and clipped to the film. In black space nothing else is lit. The whole
    film when a vertex lies behind the camera, where the projected box means nothing."""
    intr = assembly.intrinsics
    uv, depth = project(np.concatenate(list(vertices.values())), assembly.camera, intr)
    size = np.array([intr.width, intr.height])
    if not np.all(depth > 0):
        return 0, 0, intr.width, intr.height
    lo = np.clip(np.floor(uv.min(axis=0)) - CROP_MARGIN_PX, 0, size - 1).astype(int)
    hi = np.clip(np.ceil(uv.max(axis=0)) + CROP_MARGIN_PX, lo + 1, size).astype(int)
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


def scene_dict(assembly: Assembly, vertices: Mapping[str, np.ndarray], window: tuple[int, int, int, int]) -> dict:
    """The Mitsuba scene dictionary: path tracer, pinhole camera, tent-filtered film rendering the
    pixel ``window`` (x0, y0, width, height) of the image, sun, and the parts at world ``vertices`` (m)."""
    s = assembly.scene
    cam, intr = assembly.camera, assembly.intrinsics
    # Mitsuba's principal point offset is a fraction of the film, positive towards -u / -v.
    sensor = {
        "type": "perspective",
        "fov": math.degrees(intr.fov_x),
        "fov_axis": "x",
        "principal_point_offset_x": -intr.principal_offset[0] / intr.width,
        "principal_point_offset_y": -intr.principal_offset[1] / intr.height,
        "to_world": mi.ScalarTransform4f().look_at(
            origin=cam.position.tolist(), target=(cam.position + cam.forward).tolist(), up=cam.up.tolist()
        ),
        "film": {
            "type": "hdrfilm",
            "width": intr.width,
            "height": intr.height,
            "pixel_format": "rgb",
            "rfilter": {"type": s.render.filter},
            "crop_offset_x": window[0],
            "crop_offset_y": window[1],
            "crop_width": window[2],
            "crop_height": window[3],
        },
    }
    max_depth = s.render.depth + 1
    d = {
        "type": "scene",
        # Russian roulette off: every path runs to the stated depth, as in the thesis's tracer.
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": max_depth + 1},
        "sensor": sensor,
        "sun": {"type": "directional", "direction": assembly.sun_direction.tolist(), "irradiance": s.sun.irradiance_w_m2},
    }
    for name, part in assembly.parts.items():
        uv = None if name in assembly.refinements else part.uv
        d[name] = mesh_object(name, vertices[name], assembly.faces(name), uv, assembly.materials[name])
    return d


def pass_seeds(seed: int, spp: int, pixels: int) -> list[tuple[int, int]]:
    """Split ``spp`` into passes of at most :data:`MAX_SAMPLES_PER_PASS` samples: (seed, spp) each."""
    per_pass = max(1, MAX_SAMPLES_PER_PASS // max(pixels, 1))
    n = math.ceil(spp / per_pass)
    counts = [spp // n + (i < spp % n) for i in range(n)]
    return [((seed + i * 0x9E3779B1) % (1 << 32), c) for i, c in enumerate(counts)]


@contextmanager
def render_threads(deterministic: bool) -> Iterator[None]:
    """Render on one thread when ``deterministic``: the film then adds samples in a fixed order.

    Parallel renders differ by float32 rounding (about 1e-7 relative) from call to call, which
    also breaks common random numbers for finite differences of small effects.
    """
    threads = dr.thread_count()
    if deterministic:
        dr.set_thread_count(1)
    try:
        yield
    finally:
        dr.set_thread_count(threads)


class Renderer:
    """A scene loaded into Mitsuba once; renders deterministic radiance images (h, w, 3).

    Only the film window around the target is rendered (:func:`target_window`), the rest of the
    image is black; ``crop=False`` renders the whole film, for vertices that will move (the
    window is fixed when the scene is loaded). Load once and render many times: reloading scenes
    leaks memory in Mitsuba (mitsuba3#1890).
    """

    def __init__(self, assembly: Assembly, variant: str | None = None, crop: bool = True) -> None:
        self.variant = select_variant(variant or assembly.scene.render.variant)
        self.assembly = assembly
        intr = assembly.intrinsics
        vertices = assembly.scene_vertices
        self.window = target_window(assembly, vertices) if crop else (0, 0, intr.width, intr.height)
        self.scene = mi.load_dict(scene_dict(assembly, vertices, self.window))
        self.params = mi.traverse(self.scene)

    def to_film(self, window_image: np.ndarray) -> np.ndarray:
        """The whole film (height, width, ...) from an image of the rendered window, black outside it."""
        x0, y0, w, h = self.window
        intr = self.assembly.intrinsics
        film = np.zeros((intr.height, intr.width, *window_image.shape[2:]), dtype=np.float32)
        film[y0:y0 + h, x0:x0 + w] = window_image
        return film

    def to_window(self, film_image: np.ndarray) -> np.ndarray:
        """The rendered window's part of a whole-film image (a cotangent, say)."""
        x0, y0, w, h = self.window
        return np.ascontiguousarray(film_image[y0:y0 + h, x0:x0 + w])

    def render(self, spp: int | None = None, seed: int | None = None, progress: ProgressCallback | None = None) -> np.ndarray:
        """Radiance (W m^-2 sr^-1) as a float32 (height, width, 3) array; same seed, same image."""
        r = self.assembly.scene.render
        spp = r.spp if spp is None else spp
        seed = r.seed if seed is None else seed
        passes = pass_seeds(seed, spp, self.window[2] * self.window[3])
        total = None
        with render_threads(r.deterministic):
            for i, (pass_seed, count) in enumerate(passes):
                img = mi.render(self.scene, seed=pass_seed, spp=count) * (count / spp)
                total = img if total is None else total + img
                dr.eval(total)
                if progress is not None:
                    progress(i + 1, len(passes))
        return self.to_film(np.array(total, dtype=np.float32))


def render(scene: Scene, progress: ProgressCallback | None = None) -> np.ndarray:
    """Render a scene's radiance image (W m^-2 sr^-1, (height, width, 3) float32)."""
    return Renderer(assemble(scene)).render(progress=progress)
