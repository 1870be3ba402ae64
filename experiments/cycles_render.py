"""Render a scene exported by ``cycles_peer.py`` with Blender Cycles (bpy 5.0.1), CPU, at a list of spp.

Runs in ``.venv-peers`` (``make peers``), never in spacefit's own environment; it reads the export
with :mod:`spacefit.rendering.cycles` (numpy only; ``cycles_peer.py`` puts the checkout on its
``PYTHONPATH``).

The scene folder holds ``scene.json`` (camera, sun, render settings, parts with their materials) and
one binary PLY per part in world coordinates, flat-shaded (spacefit's Mitsuba meshes have no vertex
normals). Writes ``cycles_<spp>.exr`` (radiance, W m^-2 sr^-1, float32 RGB; the first timed render of
each spp) and ``timings.json`` to ``--out``; ``--window`` renders only spacefit's window (a render border): the scene build, the first (syncing) render and, per spp,
the wall time of every timed ``bpy.ops.render.render`` call alone (the EXR is written after the clock
stops).

Run: ``.venv-peers/bin/python experiments/cycles_render.py SCENE_DIR --out DIR --spp 1 4 16 [--repeats 3] [--seed 0] [--window]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from spacefit.rendering.cycles import cycles_roughness, read_ply

# PLY property types of the files cycles_peer.py writes
def _material(bpy: object, name: str, spec: dict) -> object:
    """A Cycles material: Metallic BSDF (physical conductor Fresnel) or a Lambertian Diffuse BSDF."""
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    if spec["type"] == "conductor":
        bsdf = nodes.new("ShaderNodeBsdfMetallic")
        bsdf.distribution = spec["distribution"].upper()
        bsdf.fresnel_type = "PHYSICAL_CONDUCTOR"
        bsdf.inputs["IOR"].default_value = spec["eta"]
        bsdf.inputs["Extinction"].default_value = spec["k"]
        roughness, anisotropy, rotation = cycles_roughness(spec["alpha_x"], spec["alpha_y"])
        bsdf.inputs["Roughness"].default_value = roughness
        bsdf.inputs["Anisotropy"].default_value = anisotropy
        bsdf.inputs["Rotation"].default_value = rotation
        if spec.get("tangent") == "uv":  # alpha_x along dp/du, as Mitsuba's alpha_u
            tangent = nodes.new("ShaderNodeTangent")
            tangent.direction_type = "UV_MAP"
            tangent.uv_map = "UVMap"
            links.new(tangent.outputs["Tangent"], bsdf.inputs["Tangent"])
    elif spec["type"] == "lambert":
        bsdf = nodes.new("ShaderNodeBsdfDiffuse")
        bsdf.inputs["Color"].default_value = (*spec["kd"], 1.0)
        bsdf.inputs["Roughness"].default_value = 0.0  # Lambert, not Oren-Nayar
    else:
        raise ValueError(f"part {name!r}: no Cycles material for {spec['type']!r}")
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def _mesh_object(bpy: object, name: str, path: Path, material: object) -> object:
    """A flat-shaded Blender mesh object from a PLY in world coordinates (identity transform)."""
    vertices, faces, uv = read_ply(path)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", vertices.ravel())
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3))
    mesh.update()
    mesh.shade_flat()
    if uv is not None:
        mesh.uv_layers.new(name="UVMap").data.foreach_set("uv", uv[faces.ravel()].ravel())
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    obj.cycles.shadow_terminator_geometry_offset = 0.0
    obj.cycles.shadow_terminator_offset = 0.0
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _frame(x: np.ndarray, y: np.ndarray, z: np.ndarray, origin: np.ndarray) -> list[list[float]]:
    """A 4 x 4 object-to-world matrix with columns x, y, z (local axes in world) and the origin."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m.tolist()


def build_scene(bpy: object, description: dict, folder: Path) -> object:
    """An empty Blender scene turned into the exported one; returns bpy's scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    render = description["render"]
    scene.render.engine = "CYCLES"
    scene.render.resolution_x, scene.render.resolution_y = render["width"], render["height"]
    scene.render.resolution_percentage = 100
    scene.render.threads_mode = "FIXED"
    scene.render.threads = render["threads"]
    scene.render.use_persistent_data = True  # a later render reuses the BVH, as a loaded Mitsuba scene does
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGB"
    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.use_light_tree = False
    c.light_sampling_threshold = 0.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.use_guiding = False
    c.use_animated_seed = False
    # spacefit's depth counts bounces after the first hit and includes direct light (depth 1 = direct only);
    # Cycles' bounces count indirect ones only (0 = direct only)
    bounces = render["depth"] - 1
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = bounces
    c.transmission_bounces = c.volume_bounces = c.transparent_max_bounces = 0
    c.min_light_bounces = c.min_transparent_bounces = 0
    c.pixel_filter_type = render["filter_type"]
    c.filter_width = render["filter_width_px"]
    world = bpy.data.worlds.new("black")
    world.color = (0.0, 0.0, 0.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    scene.view_settings.view_transform = "Standard"

    cam = description["camera"]
    data = bpy.data.cameras.new("camera")
    data.type = "PERSP"
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = 36.0
    data.lens = data.sensor_width * cam["focal_px"] / render["width"]
    size = max(render["width"], render["height"])
    data.shift_x = -cam["principal_offset_px"][0] / size  # shift moves the frustum: the principal point goes the other way
    data.shift_y = cam["principal_offset_px"][1] / size
    data.clip_start, data.clip_end = cam["clip_m"]
    camera = bpy.data.objects.new("camera", data)
    # a Blender camera looks along its -z with image up along +y
    camera.matrix_world = _matrix(bpy, _frame(np.array(cam["right"]), np.array(cam["up"]), -np.array(cam["forward"]),
                                              np.array(cam["position_m"])))
    scene.collection.objects.link(camera)
    scene.camera = camera

    sun = description["sun"]
    light = bpy.data.lights.new("sun", "SUN")
    light.energy = sun["irradiance_w_m2"]  # a sun's strength is its irradiance: radiance comes out at scale 1
    light.angle = 0.0
    light.use_shadow = True
    d = np.array(sun["direction"], float)
    d /= np.linalg.norm(d)
    x = np.cross(d, [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    # a sun shines along its -z
    sun_obj = bpy.data.objects.new("sun", light)
    sun_obj.matrix_world = _matrix(bpy, _frame(x, np.cross(-d, x), -d, np.zeros(3)))
    scene.collection.objects.link(sun_obj)

    for name, part in description["parts"].items():
        _mesh_object(bpy, name, folder / part["ply"], _material(bpy, name, part["material"]))
    return scene


def set_border(scene: object, render: dict) -> None:
    """Render only the pixel window (x0, y0, width, height; rows from the top) of ``render["window"]``,
    on a film of full size that stays black outside it (Blender's border counts y from the bottom)."""
    x0, y0, w, h = render["window"]
    r = scene.render
    r.use_border, r.use_crop_to_border = True, False
    r.border_min_x, r.border_max_x = x0 / render["width"], (x0 + w) / render["width"]
    r.border_min_y, r.border_max_y = 1.0 - (y0 + h) / render["height"], 1.0 - y0 / render["height"]


def _matrix(bpy: object, rows: list[list[float]]) -> object:
    import mathutils  # bpy's; only in .venv-peers

    return mathutils.Matrix(rows)


def render_once(bpy: object, scene: object, spp: int, seed: int) -> float:
    """One Cycles render at ``spp`` with ``seed``; the wall time (s) of the render call alone."""
    scene.cycles.samples = spp
    scene.cycles.seed = seed
    # with persistent data a render re-reads only what is tagged: untagged, the new spp and seed were ignored
    scene.update_tag()
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=False)
    return time.perf_counter() - t0


def main() -> None:
    import bpy  # only in .venv-peers (make peers)

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene_dir", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--spp", type=int, nargs="+", required=True)
    p.add_argument("--repeats", type=int, default=3, help="timed renders per spp, after one syncing render")
    p.add_argument("--seed", type=int, default=0, help="seed of the first timed render; later ones count up")
    p.add_argument("--window", action="store_true", help="render only spacefit's window (a render border), the rest black")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    description = json.loads((args.scene_dir / "scene.json").read_text())
    scene = build_scene(bpy, description, args.scene_dir)
    if args.window:
        set_border(scene, description["render"])
    timings = {"build_s": time.perf_counter() - t0, "first_render_s": render_once(bpy, scene, min(args.spp), 10_000 + args.seed),
               "threads": scene.render.threads, "sampling_pattern": scene.cycles.sampling_pattern,
               "blender": bpy.app.version_string, "renders": {}}
    for spp in args.spp:
        times = []
        for k in range(args.repeats):
            times.append(render_once(bpy, scene, spp, args.seed + k))
            if k == 0:
                bpy.data.images["Render Result"].save_render(str(args.out / f"cycles_{spp}.exr"))
        timings["renders"][str(spp)] = times
    (args.out / "timings.json").write_text(json.dumps(timings, indent=1))


if __name__ == "__main__":
    main()
