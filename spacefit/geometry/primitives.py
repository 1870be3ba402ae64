"""Parts built from primitives: a box, a plate, a cylinder, sized in metres and placed in the body frame.

A scene file's part table gives ``shape`` with its sizes (``size_m`` for a box, 3 lengths along x, y, z,
and a plate, 2 lengths along x, y, its normal +z; ``radius_m`` and ``length_m`` for a cylinder, axis +z),
and its placement in the body frame: ``position_m`` and ``attitude_deg``, the convention of the target's
attitude (:func:`spacefit.geometry.frames.attitude_matrix`): body = R part + position.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from spacefit.errors import InputError, check_choice, check_range, check_vector, inside, quote
from spacefit.geometry.frames import attitude_matrix
from spacefit.geometry.mesh import PartMesh, _trimesh

SHAPES = ("box", "plate", "cylinder")
# Sides of a cylinder's polygon: its side-on silhouette is within 1 - cos(pi / 64) = 0.12 % of the circle's.
CYLINDER_SECTIONS = 64


@dataclass(frozen=True)
class Primitive:
    """A primitive part's shape, sizes (m) and placement in the body frame (m, deg), checked on construction.

    Unused sizes stay at their defaults (``size_m`` empty, ``radius_m`` and ``length_m`` 0).
    """

    shape: str
    size_m: tuple[float, ...] = ()
    radius_m: float = 0.0
    length_m: float = 0.0
    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    KEYS: ClassVar[tuple[str, ...]] = ("shape", "size_m", "radius_m", "length_m", "position_m", "attitude_deg")
    SIZES: ClassVar[dict[str, tuple[str, ...]]] = {"box": ("size_m",), "plate": ("size_m",),
                                                   "cylinder": ("radius_m", "length_m")}

    def __post_init__(self) -> None:
        check_choice("shape", self.shape, SHAPES)
        for key, size in (("size_m", None), ("position_m", 3), ("attitude_deg", 3)):
            value = getattr(self, key)
            empty = size is None and isinstance(value, (tuple, list)) and not value  # no size_m given
            object.__setattr__(self, key, () if empty else tuple(check_vector(key, value, size).tolist()))
        for key in ("radius_m", "length_m"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"`{key}` must be a number, got {quote(value)}.")
            object.__setattr__(self, key, float(value))
        unused = [k for k in ("size_m", "radius_m", "length_m") if k not in self.SIZES[self.shape] and getattr(self, k)]
        if unused:
            raise InputError(f"`{unused[0]}` is not a size of a {self.shape} (it takes {' and '.join(self.SIZES[self.shape])}).")
        if self.shape == "cylinder":
            for key in ("radius_m", "length_m"):
                if not getattr(self, key):
                    raise InputError(f"`{key}` is missing: a cylinder takes radius_m and length_m (m, > 0).")
                check_range(key, getattr(self, key), 0.0, lo_open=True, unit="m")
            return
        count = 3 if self.shape == "box" else 2
        if len(self.size_m) != count:
            raise InputError(f"`size_m` must be {count} lengths (m, > 0) for a {self.shape}, got {list(self.size_m)}"
                             f"{' (missing)' if not self.size_m else ''}.")
        for i, length in enumerate(self.size_m):
            check_range(f"size_m ({'xyz'[i]})", length, 0.0, lo_open=True, unit="m")

    def mesh(self) -> PartMesh:
        """The part's triangles in the body frame, each face with its own vertices and uv (u along the
        part's z where the face contains it, else along x), so anisotropic materials have a tangent frame."""
        trimesh = _trimesh()
        if self.shape == "box":
            shape = trimesh.creation.box(extents=self.size_m)
            vertices, faces = np.asarray(shape.vertices), np.asarray(shape.faces)
        elif self.shape == "cylinder":
            shape = trimesh.creation.cylinder(radius=self.radius_m, height=self.length_m, sections=CYLINDER_SECTIONS)
            vertices, faces = np.asarray(shape.vertices), np.asarray(shape.faces)
        else:
            a, b = self.size_m[0] / 2, self.size_m[1] / 2
            vertices = np.array([[-a, -b, 0.0], [a, -b, 0.0], [a, b, 0.0], [-a, b, 0.0]])
            faces = np.array([[0, 1, 2], [0, 2, 3]])
        tri = vertices[faces]  # (m, 3, 3): unshared vertices give each face its own uv chart
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        axis = np.where(np.abs(normals[:, 2:3]) < 0.5, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
        u_axis = axis - np.einsum("mj,mj->m", axis, normals)[:, None] * normals
        u_axis /= np.linalg.norm(u_axis, axis=1, keepdims=True)
        v_axis = np.cross(normals, u_axis)
        uv = np.stack([np.einsum("mkj,mj->mk", tri, u_axis), np.einsum("mkj,mj->mk", tri, v_axis)], axis=-1)
        rotation = attitude_matrix(np.radians(self.attitude_deg))
        placed = tri.reshape(-1, 3) @ rotation.T + np.asarray(self.position_m)
        return PartMesh(placed, np.arange(3 * len(tri)).reshape(-1, 3), uv.reshape(-1, 2))

    def table(self) -> dict[str, object]:
        """The primitive as a scene file's part table states it (its shape's sizes and its placement)."""
        sizes = {key: list(getattr(self, key)) if key == "size_m" else getattr(self, key) for key in self.SIZES[self.shape]}
        return {"shape": self.shape, **sizes, "position_m": list(self.position_m), "attitude_deg": list(self.attitude_deg)}



def pop_primitive(table: dict[str, object], where: str, old: Primitive | None = None) -> Primitive | None:
    """Take a part table's primitive keys (:attr:`Primitive.KEYS`) out of ``table``: the part's primitive
    (keys not given keep ``old``'s values; a new shape keeps only its placement), ``old`` when none is given.

    Raises:
        InputError: for sizes or a placement without a ``shape``, or a value the primitive refuses, naming
            ``where.key``.
    """
    given = {key: table.pop(key) for key in Primitive.KEYS if key in table}
    if not given:
        return old
    if old is not None:
        kept = old.table() if given.get("shape", old.shape) == old.shape else {
            "position_m": old.position_m, "attitude_deg": old.attitude_deg}
        given = {**kept, **given}
    if "shape" not in given:
        raise InputError(f"`{where}.shape` is missing: {', '.join(given)} belong to a primitive part "
                         f"(shape one of {', '.join(SHAPES)}).")
    with inside(where):
        return Primitive(**given)  # type: ignore[arg-type]
