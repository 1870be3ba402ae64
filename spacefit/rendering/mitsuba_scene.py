"""The Mitsuba scene dictionary of an :class:`~spacefit.scene.assembly.Assembly`: path tracer, pinhole
camera, tent-filtered film over a window of the image, the sun, and each part a flat-shaded mesh with its BSDF.

Radiance is in W m^-2 sr^-1 per RGB channel: the sun's irradiance is the same in each channel, so a
Lambert part with kd 0.2 facing a sun of 5 W m^-2 reads 0.2 * 5 / pi in every channel.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from spacefit.materials import Material
from spacefit.rendering.backend import mi, variant_scope
from spacefit.rendering.materials import bsdf_dict
from spacefit.scene.assembly import Assembly, assemble
from spacefit.scene.sampling import split_sample_count
from spacefit.scene.schema import Scene
from spacefit.scene.sections import FAR_CLIP_M, NEAR_CLIP_M, check_scene


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
        "near_clip": NEAR_CLIP_M,
        "far_clip": FAR_CLIP_M,
        "principal_point_offset_x": -intr.principal_offset[0] / intr.width,
        "principal_point_offset_y": -intr.principal_offset[1] / intr.height,
        "to_world": mi.ScalarTransform4f(cam.mitsuba_to_world()),
        "sampler": {"type": s.render.sampler, "sample_count": split_sample_count(s.render.sampler, s.render.spp)[0]},
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


def mitsuba_scene_dict(scene: Scene) -> dict:
    """The Mitsuba scene dictionary of ``scene`` (the whole film): the integrator, camera, film and
    sun as dictionaries, each part an ``mi.Mesh`` with its BSDF. The meshes belong to the variant the
    scene renders with (``llvm_ad_rgb``, ``cuda_ad_rgb`` on a GPU): load the dictionary in it,
    ``with mi.variant_context("llvm_ad_rgb"): mi.load_dict(d)``."""
    assembly = assemble(check_scene(scene))
    intr = assembly.intrinsics
    with variant_scope(scene.render.variant):
        return scene_dict(assembly, assembly.scene_vertices, (0, 0, intr.width, intr.height))
