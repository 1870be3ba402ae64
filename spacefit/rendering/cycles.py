"""The scene as Blender Cycles reads it, for the peer comparison (``experiments/cycles_peer.py``).

spacefit's side writes it (:func:`export_view`): one binary little-endian PLY per part in world
coordinates (the float32 vertices Mitsuba gets, flat-shaded as spacefit renders them) and
``scene.json`` with the camera, sun, materials and render settings. Blender's side
(``experiments/cycles_render.py``, run by bpy's own Python in ``.venv-peers``) reads it back with
:func:`read_ply` and turns GGX alphas into Cycles' inputs with :func:`cycles_roughness`. Blender's
Python has numpy but neither Mitsuba nor JAX, so this module imports only numpy at its top.

Cycles has no tent filter: spacefit's tent (radius 1 px) is matched by Cycles' Gaussian of the same
standard deviation, sqrt(1/6) px (Cycles' filter width is 4 standard deviations).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from spacefit.materials import Material
    from spacefit.scene.assembly import Assembly

# Cycles' render threads: as many as spacefit renders with in the comparison.
THREADS = 2
# spacefit's render.filter -> Cycles' (pixel_filter_type, filter_width px); Cycles' Gaussian of width w has
# standard deviation w / 4: the tent of radius 1 px has sqrt(1/6) px, Mitsuba's Gaussian 0.5 px.
CYCLES_FILTERS = {"tent": ("GAUSSIAN", 4.0 * math.sqrt(1.0 / 6.0)), "gaussian": ("GAUSSIAN", 2.0), "box": ("BOX", 1.0)}


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None) -> None:
    """A binary little-endian triangle PLY: float32 x, y, z (and s, t for uv), int32 vertex indices."""
    names = ["x", "y", "z", *(["s", "t"] if uv is not None else [])]
    vertex = np.empty(len(vertices), dtype=[(n, "<f4") for n in names])
    for i, n in enumerate("xyz"):
        vertex[n] = vertices[:, i]
    if uv is not None:
        vertex["s"], vertex["t"] = uv[:, 0], uv[:, 1]
    face = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    face["n"], face["i"] = 3, faces
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}",
              *(f"property float {n}" for n in names), f"element face {len(faces)}",
              "property list uchar int vertex_indices", "end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vertex.tobytes())
        f.write(face.tobytes())


def _rgb(value: float | tuple[float, ...]) -> list[float]:
    return list(value) if isinstance(value, tuple) else [float(value)] * 3


# A material as ``cycles_render.py`` reads it, by its model's name (a material model's ``name``; this
# module names models rather than importing them: Blender's Python imports it and has no JAX).
# Each takes the material and whether the part has uv.
Describe = Callable[[Any, bool], dict[str, object]]
CYCLES: dict[str, Describe] = {}


def register_cycles(model_name: str, describe: Describe) -> None:
    """Add (or replace) the Cycles description of the material model named ``model_name``."""
    CYCLES[model_name] = describe


register_cycles("conductor", lambda m, has_uv: {
    "type": "conductor", "eta": _rgb(m.eta), "k": _rgb(m.k), "alpha_x": m.alpha_x, "alpha_y": m.alpha_y,
    "distribution": m.distribution, "tangent": "uv" if has_uv else None})
register_cycles("lambert", lambda m, has_uv: {"type": "lambert", "kd": _rgb(m.kd)})


def material_description(material: Material, has_uv: bool) -> dict[str, object]:
    """A material as ``cycles_render.py`` reads it (:data:`CYCLES`); a conductor's alpha_x lies along
    dp/du where the part has uv. Mirrors, diffuse conductors and Oren-Nayar have no entry (Cycles'
    rough diffuse is another Oren-Nayar form, Fujii's)."""
    name = type(material).name
    if name not in CYCLES:
        raise ValueError(f"no Cycles material for {type(material).__name__}")
    return CYCLES[name](material, has_uv)


def export_view(assembly: Assembly, folder: Path) -> dict[str, object]:
    """Write each part's PLY (world coordinates, m; the float32 vertices Mitsuba gets) and ``scene.json``
    (camera, sun, render settings with spacefit's window, materials) to ``folder``; returns the JSON's content."""
    from spacefit.rendering.window import target_window  # deferred: Blender's Python, which imports this module, has no JAX
    from spacefit.scene.sections import FAR_CLIP_M, NEAR_CLIP_M

    folder.mkdir(parents=True, exist_ok=True)
    s, cam, intr = assembly.scene, assembly.camera, assembly.intrinsics
    parts = {}
    for name, part in assembly.parts.items():
        uv = None if name in assembly.refinements else part.uv
        write_ply(folder / f"{name}.ply", assembly.scene_vertices[name], assembly.faces(name), uv)
        parts[name] = {"ply": f"{name}.ply", "material": material_description(assembly.materials[name], uv is not None)}
    filter_type, filter_width = CYCLES_FILTERS[s.render.filter]
    description = {
        "render": {"width": intr.width, "height": intr.height, "depth": s.render.depth, "threads": THREADS,
                   "filter": s.render.filter, "filter_type": filter_type, "filter_width_px": filter_width,
                   "window": list(target_window(assembly, assembly.scene_vertices))},
        "camera": {"position_m": cam.position.tolist(), "right": cam.right.tolist(), "up": cam.up.tolist(),
                   "forward": cam.forward.tolist(), "focal_px": intr.focal_px,
                   "principal_offset_px": list(intr.principal_offset), "clip_m": [NEAR_CLIP_M, FAR_CLIP_M]},
        "sun": {"direction": assembly.sun_direction.tolist(), "irradiance_w_m2": s.sun.irradiance_w_m2},
        "parts": parts,
    }
    (folder / "scene.json").write_text(json.dumps(description, indent=1))
    return description


_PLY_TYPES = {"float": "<f4", "double": "<f8", "int": "<i4", "uint": "<u4", "uchar": "u1"}


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Vertices (n, 3), triangles (m, 3) and per-vertex uv (n, 2) or None of a binary little-endian
    triangle PLY with properties x, y, z[, s, t] and a ``list uchar int vertex_indices`` face list."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    counts, props, element = {}, {"vertex": [], "face": []}, ""
    for line in data[:end].decode("ascii").splitlines():
        words = line.split()
        if words[0] == "format" and words[1] != "binary_little_endian":
            raise ValueError(f"{path}: only binary_little_endian PLY is read, not {words[1]}")
        if words[0] == "element":
            element, counts[words[1]] = words[1], int(words[2])
        elif words[0] == "property":
            props[element].append(words[1:])
    vertex_dtype = np.dtype([(p[1], _PLY_TYPES[p[0]]) for p in props["vertex"]])
    vertices = np.frombuffer(data, vertex_dtype, counts["vertex"], end)
    face_dtype = np.dtype([("n", "u1"), ("i", _PLY_TYPES[props["face"][0][2]], 3)])
    faces = np.frombuffer(data, face_dtype, counts["face"], end + vertex_dtype.itemsize * counts["vertex"])
    if np.any(faces["n"] != 3):
        raise ValueError(f"{path}: only triangles are read")
    xyz = np.stack([vertices[c] for c in "xyz"], axis=-1).astype(float)
    uv = np.stack([vertices["s"], vertices["t"]], axis=-1).astype(float) if "s" in vertex_dtype.names else None
    return xyz, faces["i"].astype(np.int64), uv


def cycles_roughness(alpha_x: float, alpha_y: float) -> tuple[float, float, float]:
    """Cycles' Metallic BSDF (Roughness, Anisotropy, Rotation) inputs for GGX or Beckmann alphas along
    (alpha_x) and across (alpha_y) the tangent.

    Cycles 5.0 (svm closure of the Metallic BSDF) squares Roughness into r, and for Anisotropy a in
    (0, 1] takes aspect = sqrt(1 - 0.9 a), alpha along the tangent r / aspect and across it r aspect:
    the tangent's alpha is the larger one. Rotation 0.25 turns the tangent by 90 deg when alpha_y is.
    """
    hi, lo = max(alpha_x, alpha_y), min(alpha_x, alpha_y)
    aspect2 = lo / hi
    if aspect2 < 0.1:
        raise ValueError(f"Cycles' anisotropy reaches an alpha ratio of 10 at most, not {hi / lo:.3g}")
    return math.sqrt(math.sqrt(hi * lo)), (1.0 - aspect2) / 0.9, 0.0 if alpha_x >= alpha_y else 0.25
