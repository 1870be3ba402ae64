"""Triangle meshes of the target's parts: validation, import through trimesh, binary STL export.

A part is a :class:`PartMesh` in the object frame (metres). Files are STL (binary or ASCII), PLY,
OBJ or glTF (``.gltf`` / ``.glb``): either one file per part, or one file whose named groups are the
parts (OBJ ``g`` / ``o``, glTF nodes, ASCII STL ``solid`` names; a PLY has none).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from spacefit.errors import InputError

if TYPE_CHECKING:
    from jaxtyping import Float, Int
    import trimesh

def _trimesh() -> ModuleType:
    """The trimesh module, imported on first use: a render of cached meshes never needs it (0.5 s)."""
    import trimesh

    return trimesh


MESH_SUFFIXES = (".stl", ".ply", ".obj", ".gltf", ".glb")
# A triangle whose area is below this fraction of the squared longest edge of its part is
# degenerate: it has no usable normal for shading or for displacing wrinkles.
DEGENERATE_REL_AREA = 1e-12


@dataclass(frozen=True)
class PartMesh:
    """One part of the target.

    Attributes:
        vertices: (n, 3) float, object frame, metres.
        faces: (m, 3) int, counter-clockwise seen from outside.
        uv: (n, 2) float or None. Texture coordinates define the tangent frame: the microfacet
            roughness ``alpha_x`` runs along dp/du. Without them Mitsuba takes each triangle's first
            edge, so anisotropic materials need them.
    """

    vertices: Float[np.ndarray, "n 3"]
    faces: Int[np.ndarray, "m 3"]
    uv: Float[np.ndarray, "n 2"] | None = None

    def to_trimesh(self) -> trimesh.Trimesh:
        """The part as an unprocessed :class:`trimesh.Trimesh` (vertex order kept)."""
        return _trimesh().Trimesh(self.vertices, self.faces, process=False)


def validate_part(name: str, part: PartMesh) -> PartMesh:
    """Check that a part has faces, finite vertices, valid indices and no degenerate triangles.

    A closed part whose faces wind inward (negative enclosed volume) is reversed, with a warning:
    wrinkles displace along the faces' normals, and spacefit's outward convention is what every
    part's normals follow (its BSDFs shade both sides, so the part is lit either way). Closedness
    is judged after merging vertices at equal positions, for every format: an STL stores each
    triangle's corners apart, so it is never closed before merging. Open parts are kept as given.
    """
    v, f = np.asarray(part.vertices, float), np.asarray(part.faces)
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise InputError(f"part {name!r}: the mesh has no triangles.")
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"part {name!r}: vertices must be an (n, 3) array, got shape {v.shape}.")
    if not np.all(np.isfinite(v)):
        raise InputError(f"part {name!r}: vertex coordinates must be finite (found NaN or inf).")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"part {name!r}: face indices must be in [0, {len(v) - 1}].")
    tri = v[f]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    scale = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)) ** 2
    bad = np.flatnonzero(area2 <= DEGENERATE_REL_AREA * scale)
    if len(bad):
        raise InputError(
            f"part {name!r}: {len(bad)} degenerate (zero-area) triangle(s), first at face index "
            f"{bad[0]}; remove them (e.g. trimesh's `update_faces(nondegenerate_faces())`)."
        )
    if part.uv is not None and np.shape(part.uv) != (len(v), 2):
        raise InputError(f"part {name!r}: uv must have shape ({len(v)}, 2), got {np.shape(part.uv)}.")
    closed = _trimesh().Trimesh(v, f, process=False)
    closed.merge_vertices(merge_tex=True, merge_norm=True)
    if closed.is_watertight and closed.volume < 0:
        warnings.warn(f"part {name!r}: the closed mesh's faces wind inward (negative volume); their order was "
                      "reversed so that its normals point outward (wrinkles displace along them).", stacklevel=2)
        f = f[:, ::-1]
    return PartMesh(v, f.astype(np.int64), None if part.uv is None else np.asarray(part.uv, float))


def _load(path: Path, **kwargs: object) -> trimesh.Trimesh | trimesh.Scene:
    if not path.is_file():
        raise InputError(f"mesh file {str(path)!r} does not exist.")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"mesh file {str(path)!r}: format must be one of {', '.join(MESH_SUFFIXES)}.")
    if path.suffix.lower() == ".stl":
        _check_stl_size(path)
    try:
        return _trimesh().load(path, process=False, **kwargs)
    except Exception as err:  # trimesh raises many types for malformed files
        raise InputError(f"mesh file {str(path)!r} could not be read: {err}") from None


def _check_stl_size(path: Path) -> None:
    """Refuse a truncated binary STL (80-byte header, uint32 count, 50 bytes per triangle) by its size;
    an ASCII STL starts with ``solid``."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(4096)
    if head[:5].lower() == b"solid" and b"facet" in head:
        return
    count = int.from_bytes(head[80:84], "little") if len(head) >= 84 else None
    if count is None or size != 84 + 50 * count:
        expected = f"{84 + 50 * count} bytes for its {count} triangles" if count is not None else "at least 84 bytes"
        raise InputError(f"mesh file {str(path)!r} is not a whole binary STL: {size} bytes where its header needs "
                         f"{expected} (truncated or not STL).")


def _from_trimesh(mesh: trimesh.Trimesh) -> PartMesh:
    uv = getattr(mesh.visual, "uv", None)
    return PartMesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces), None if uv is None else np.asarray(uv, float))


def load_part(name: str, path: str | Path) -> PartMesh:
    """Load one file (STL / PLY / OBJ) as the whole of part ``name``; all its groups are merged."""
    loaded = _load(Path(path), force="mesh")
    if not isinstance(loaded, _trimesh().Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"part {name!r}: mesh file {str(path)!r} holds no triangles.")
    return validate_part(name, _from_trimesh(loaded))


def _declared_groups(path: Path) -> list[str]:
    """The group and object names an OBJ file declares (``g`` / ``o`` lines), with or without faces."""
    if path.suffix.lower() != ".obj":
        return []
    names = []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if line[:2] in ("g ", "o ") and line[2:].strip():
                names.append(line[2:].strip())
    return list(dict.fromkeys(names))


def load_grouped(path: str | Path) -> dict[str, PartMesh]:
    """Load one file whose named groups are the parts (OBJ ``g`` / ``o``, glTF nodes, ASCII STL
    ``solid`` names); empty for a file without named groups (a PLY, a binary STL, an OBJ without
    ``g`` / ``o``), whose whole mesh trimesh names after the file.

    Raises:
        InputError: for a file without triangles, or a named group without triangles (naming the
            file's groups).
    """
    path = Path(path)
    scene = _load(path, force="scene", split_groups=True, split_objects=True)
    parts: dict[str, PartMesh] = {}
    empty: list[str] = []
    for node in scene.graph.nodes_geometry:
        transform, geom_name = scene.graph[node]
        mesh = scene.geometry[geom_name]
        if not isinstance(mesh, _trimesh().Trimesh) or len(mesh.faces) == 0:
            empty.append(str(geom_name))
            continue
        mesh = mesh.copy()
        mesh.apply_transform(transform)
        parts[str(geom_name)] = validate_part(str(geom_name), _from_trimesh(mesh))
    if not parts:
        raise InputError(f"mesh file {str(path)!r} holds no triangles.")
    if list(parts) == [path.name]:  # no named groups: trimesh names the whole mesh after the file
        return {}
    declared = _declared_groups(path)
    empty += [name for name in declared if name not in parts and name not in empty]
    if empty:
        raise InputError(f"mesh file {str(path)!r}: group(s) {', '.join(map(repr, empty))} hold no triangles; "
                         f"its groups with triangles: {', '.join(sorted(parts))}. Remove the empty group(s) or give them faces.")
    return {name: parts[name] for name in sorted(parts, key=lambda n: declared.index(n) if n in declared else len(declared))}  # the file's order


def export_stl(path: str | Path, vertices: Float[np.ndarray, "n 3"], faces: Int[np.ndarray, "m 3"]) -> None:
    """Write a binary STL (80-byte header, uint32 count, 50 bytes per triangle), as the thesis did."""
    _trimesh().Trimesh(np.asarray(vertices, float), np.asarray(faces), process=False).export(path, file_type="stl")

