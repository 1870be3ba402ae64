"""Assemble a validated :class:`~spacefit.scene.schema.Scene` into renderer-agnostic quantities.

The assembly holds the parts' meshes in the object frame, the refinement of each wrinkled part
(computed once), materials, the object-to-world matrix, the camera and the sun. World-space
vertices of a wrinkled part are a JAX function of (D, G), so the differentiable renderer can push
tangents in D and G through :func:`spacefit.geometry.wrinkle.displace` into vertex positions.

The built-in lander, each refinement, its triangles alone and the displaced vertices at the scene's
(D, G) come from the disk cache (:mod:`spacefit.geometry.cache`), so that a render needs neither JAX,
SciPy nor trimesh once they are cached: those imports alone take about 1.5 s, and refining the
default body 2 s. A refinement is read only when something asks for it (:class:`Refinements`): a
render of cached displaced vertices needs only their triangles.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import InputError, check_direction
from spacefit.geometry.articulation import Fixed
from spacefit.geometry.cache import cached
from spacefit.geometry.frames import CameraFrame, Intrinsics, object_to_world, project
from spacefit.geometry.mesh import PartMesh, load_grouped, load_part, validate_part
from spacefit.geometry.wm import wm_n_max, wm_phases
from spacefit.geometry.wrinkle import FOLD_WARN_FRACTION, Refinement, displace, fold_fraction, refine
from spacefit.materials import Material
from spacefit.scene.schema import Scene
from spacefit.scene.checks import deg2rad
from spacefit.scene.sections import NEAR_CLIP_M, WrinkleSettings, check_scene
from spacefit.scene.target import NO_MESH, PartSettings
from spacefit.scene.lod import LodChoice, choose_model

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s), which a render does not need
    from jaxtyping import Array, Float


@dataclass(frozen=True)
class Assembly:
    """Everything a renderer needs, in SI units and radians, world frame unless stated.

    ``scene_vertices`` are the world-frame vertices (m) of every part at the scene's D and G,
    evaluated once (the view check and the renderer both need them); ``cache`` says what the disk
    cache did for each cached mesh (``"hit"``, ``"miss"``, ``"off"``, or ``"memory"`` for a refinement
    this process already holds), e.g. ``{"lander": "hit", "body.displaced": "hit", "body.faces": "hit"}`` (a
    refinement's status appears once something reads it, :class:`Refinements`);
    ``folds`` is the fraction of each displaced part's faces folded over at the scene's D and G
    (:func:`spacefit.geometry.wrinkle.fold_fraction`).
    """

    scene: Scene
    parts: Mapping[str, PartMesh]
    materials: Mapping[str, Material]
    refinements: Refinements
    phases: np.ndarray
    to_world: Float[np.ndarray, "4 4"]
    camera: CameraFrame
    intrinsics: Intrinsics
    sun_direction: Float[np.ndarray, "3"]
    lod: Mapping[str, LodChoice]
    scene_vertices: Mapping[str, Float[np.ndarray, "n 3"]]
    cache: Mapping[str, str]
    folds: Mapping[str, float]

    def object_vertices(self, name: str, D: float | Array | None = None, G: float | Array | None = None) -> Array:
        """Object-frame vertices (m) of part ``name``; wrinkled parts at (D, G), scene values by default."""
        import jax.numpy as jnp  # here, not at the top: a plain render never needs JAX (0.6 s to import)

        if name not in self.refinements:
            return jnp.asarray(self.parts[name].vertices)
        w = self.scene.wrinkles
        return displace(
            self.refinements[name],
            w.D if D is None else D,
            w.G if G is None else G,
            gamma=w.gamma,
            M=w.M,
            L=w.L,
            Ls=w.Ls,
            phases=self.phases,
        )

    def world_vertices(self, name: str, D: float | Array | None = None, G: float | Array | None = None) -> Array:
        """World-frame vertices (m) of part ``name``, differentiable in D and G."""
        import jax.numpy as jnp  # here: a plain render never needs JAX (0.6 s to import)

        m = jnp.asarray(self.to_world)
        return self.object_vertices(name, D, G) @ m[:3, :3].T + m[:3, 3]

    def faces(self, name: str) -> np.ndarray:
        """Triangles of part ``name`` (refined for wrinkled parts)."""
        return self.refinements.faces(name) if name in self.refinements else self.parts[name].faces

    def triangle_count(self) -> int:
        """Number of triangles in the rendered scene."""
        return int(sum(len(self.faces(n)) for n in self.parts))


@functools.lru_cache(maxsize=8)
def _refinement(vertices: bytes, faces: bytes, spacing: float) -> tuple[Refinement, str]:
    """Refinement of a part and the disk cache's status; also kept in memory: sweeps and fits
    re-assemble one geometry many times."""
    v, f = np.frombuffer(vertices).reshape(-1, 3), np.frombuffer(faces, dtype=np.int64).reshape(-1, 3)
    arrays, status = cached("refinement", (v, f, float(spacing)), lambda: dataclasses.asdict(refine(v, f, spacing)))
    return Refinement(**arrays), status


@functools.lru_cache(maxsize=8)
def _refined_faces(vertices: bytes, faces: bytes, spacing: float) -> tuple[np.ndarray, str]:
    """The triangles of a part's refinement alone, and the disk cache's status: their own entry (3.4 MB of
    the default body's 9.5 MB refinement), built from the refinement on a miss."""
    v, f = np.frombuffer(vertices).reshape(-1, 3), np.frombuffer(faces, dtype=np.int64).reshape(-1, 3)
    arrays, status = cached("faces", (v, f, float(spacing)), lambda: {"faces": _refinement(vertices, faces, spacing)[0].faces})
    return arrays["faces"], status


def _remembered(fn: functools._lru_cache_wrapper, *args: object) -> tuple[Any, bool]:
    """``fn(*args)`` of an lru-cached ``fn``, and whether it came from its memory."""
    hits = fn.cache_info().hits
    value = fn(*args)
    return value, fn.cache_info().hits > hits


class Refinements(Mapping[str, Refinement]):
    """The wrinkled parts' refinements (:func:`~spacefit.geometry.wrinkle.refine`) by part name, each
    read from the disk cache or built the first time it is asked for, its status then added to the
    assembly's ``cache`` (``"<part>.refinement"``). A render of cached displaced vertices asks for none:
    it needs only their triangles (:meth:`faces`), whose entry is a third of the default body's
    refinement (reading and checking that took 0.015 to 0.023 s of every render)."""

    def __init__(self, sources: Mapping[str, tuple[bytes, bytes, float]], cache: dict[str, str]) -> None:
        self._sources = dict(sources)  # part -> (base vertices, base faces, spacing): _refinement's arguments
        self._cache = cache
        self._loaded: dict[str, Refinement] = {}

    def __getitem__(self, name: str) -> Refinement:
        if name not in self._loaded:
            (refinement, status), memory = _remembered(_refinement, *self._sources[name])
            self._loaded[name] = refinement
            self._cache[f"{name}.refinement"] = "memory" if memory else status
        return self._loaded[name]

    def __contains__(self, name: object) -> bool:  # Mapping's own would read the refinement
        return name in self._sources

    def __iter__(self) -> Iterator[str]:
        return iter(self._sources)

    def __len__(self) -> int:
        return len(self._sources)

    def faces(self, name: str) -> np.ndarray:
        """The triangles of part ``name``'s refinement, without reading the rest of it (their entry is
        written from the refinement, read or built, the first time)."""
        (faces, status), memory = _remembered(_refined_faces, *self._sources[name])
        self._cache.setdefault(f"{name}.faces", "memory" if memory else status)
        return faces


def _displaced(part: PartMesh, refinements: Refinements, name: str, w: WrinkleSettings,
               phases: np.ndarray) -> tuple[np.ndarray, float, str]:
    """Object-frame vertices (m) of wrinkled part ``name`` at the scene's (D, G), their fold fraction and
    the disk cache's status (its refinement is read only to build them)."""
    key = (np.asarray(part.vertices, float), np.asarray(part.faces, np.int64), float(w.spacing_m), float(w.D),
           float(w.G), float(w.gamma), int(w.M), float(w.L), float(w.Ls), phases)

    def build() -> dict[str, np.ndarray]:
        refinement = refinements[name]
        vertices = np.asarray(displace(refinement, w.D, w.G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls, phases=phases))
        return {"vertices": vertices, "fold_fraction": np.array(fold_fraction(refinement, vertices))}

    arrays, status = cached("displaced", key, build)
    return arrays["vertices"], float(arrays["fold_fraction"]), status


def fold_notes(folds: Mapping[str, float], w: WrinkleSettings) -> list[str]:
    """A note for each part whose fold fraction exceeds :data:`~spacefit.geometry.wrinkle.FOLD_WARN_FRACTION`."""
    return [f"part {name!r}: {100 * fraction:.1f} % of its wrinkled faces fold over (turned more than 90 deg from "
            f"the surface under them; wrinkles.G = {w.G:g} m, D = {w.D:g}): wrinkles this steep fold the part over "
            "itself at its edges, unlike crumpled MLI foil (docs/explanation/wrinkles.md)."
            for name, fraction in folds.items() if fraction > FOLD_WARN_FRACTION]


def _builtin_lander() -> tuple[dict[str, PartMesh], str]:
    """The built-in lander's parts and the disk cache's status (building it imports trimesh, 0.5 s)."""

    def build() -> dict[str, np.ndarray]:
        from spacefit.geometry.lander import builtin_lander  # here: it imports trimesh (0.5 s), only to build the cache

        return {f"{name}.{field}": value for name, part in builtin_lander().items()
                for field, value in (("vertices", part.vertices), ("faces", part.faces), ("uv", part.uv))
                if value is not None}

    arrays, status = cached("lander", (), build)
    names = dict.fromkeys(key.split(".")[0] for key in arrays)
    return {n: PartMesh(arrays[f"{n}.vertices"], arrays[f"{n}.faces"], arrays.get(f"{n}.uv")) for n in names}, status


def _load_parts(scene: Scene, cache: dict[str, str]) -> dict[str, PartMesh]:
    source: dict[str, PartMesh] = {}
    if scene.target.mesh in ("builtin", ""):
        source, cache["lander"] = _builtin_lander()
    elif scene.target.mesh != NO_MESH:
        source = load_grouped(scene.target.mesh)
    check_part_names(scene.target.mesh if scene.target.mesh not in ("builtin", "") else "", source, scene.parts)
    return {name: load_part(name, spec.file) if spec.file else validate_part(name, spec.shape.mesh())
            if spec.shape is not None else source[name] for name, spec in scene.parts.items()}


def check_part_names(mesh: str, groups: Mapping[str, PartMesh], parts: Mapping[str, PartSettings]) -> None:
    """Refuse a scene whose parts and mesh groups differ: a part without its own ``file`` that the mesh
    lacks (unknown), or a group of a mesh file (``mesh``; ``""`` for the built-in lander) that no part
    names (missing: it would have no material); with no mesh (``"none"``), a part without a ``file`` or a
    ``shape``. The error names the mesh's groups and the parts found."""
    where = ("no mesh file (`target.mesh` = \"none\")" if mesh == NO_MESH else f"the mesh file {mesh!r}" if mesh
             else "the built-in lander")
    found = f"the scene's parts: {', '.join(parts) or 'none'}"
    unknown = [name for name, spec in parts.items() if not spec.file and spec.shape is None and name not in groups]
    if unknown and mesh == NO_MESH:
        raise InputError(f"part(s) {', '.join(map(repr, unknown))} have no `file` and no `shape` and there is {where}; "
                         f"{found}. Give each part a `shape` (box, plate, cylinder) or a `file`.")
    if unknown and not groups:
        raise InputError(f"part(s) {', '.join(map(repr, unknown))} have no `file` and {where} has no named groups "
                         f"(OBJ `g` / `o`, glTF nodes, ASCII STL `solid` names; a PLY or binary STL has none); "
                         f"{found}. Name the groups in the mesh, or give each part its own file (`parts.<part>.file`).")
    if unknown:
        raise InputError(f"part(s) {', '.join(map(repr, unknown))} have no `file` and {where} has no group of that name; "
                         f"its groups: {', '.join(groups)}; {found}.")
    missing = [name for name in groups if name not in parts] if mesh not in ("", NO_MESH) else []
    if missing:
        raise InputError(f"{where} has group(s) {', '.join(map(repr, missing))} that no part names; its groups: "
                         f"{', '.join(groups)}; {found}. Add a table per group, e.g. `[parts.{missing[0]}] "
                         f'material = "white_paint"`.')


def body_to_world(scene: Scene) -> Float[np.ndarray, "4 4"]:
    """The homogeneous body-to-world matrix of the scene's target: its position and the rotation of its
    attitude law (``target.attitude``, :meth:`~spacefit.scene.target.TargetSettings.rotation`) for the
    scene's sun."""
    target = scene.target
    if target.attitude == "fixed":
        return object_to_world(np.array(target.position_m), np.array(deg2rad(target.attitude_deg)))
    m = np.eye(4)
    m[:3, :3] = target.rotation(-check_direction("sun.direction", scene.sun.direction))
    m[:3, 3] = target.position_m
    return m


def articulated(parts: Mapping[str, PartMesh], specs: Mapping[str, PartSettings],
                sun: Float[np.ndarray, "3"]) -> dict[str, PartMesh]:
    """The parts with each articulated part turned about its pivot by its law (body frame), ``sun`` the
    unit direction towards the sun in the body frame; fixed parts are the same objects."""
    out = dict(parts)
    for name, spec in specs.items():
        law = spec.articulation
        if isinstance(law, Fixed):
            continue
        turn, pivot = law.rotation(spec.reference_normal(), sun), np.asarray(law.pivot_m)
        part = parts[name]
        out[name] = PartMesh((part.vertices - pivot) @ turn.T + pivot, part.faces, part.uv)
    return out


def _camera(scene: Scene) -> tuple[CameraFrame, Intrinsics]:
    c = scene.camera
    if c.look_at_m:
        frame = CameraFrame.look_at(np.array(c.position_m), np.array(c.look_at_m), check_direction("camera.up", c.up))  # unit: [0, 1e300, 0] overflowed
    else:
        frame = CameraFrame.from_attitude(np.array(c.position_m), np.array(deg2rad(c.attitude_deg)))
    frame = frame.rolled(math.radians(c.roll_deg))
    return frame, Intrinsics.from_scene(scene)


def winding_number(point: Float[np.ndarray, "3"], vertices: Float[np.ndarray, "n 3"], faces: np.ndarray) -> float:
    """Generalised winding number of a closed mesh about a point: 1 inside, 0 outside.

    Sum of the triangles' signed solid angles over 4 pi (Van Oosterom & Strackee 1983).
    """
    a, b, c = (vertices[faces[:, i]] - point for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la + np.einsum("ij,ij->i", c, a) * lb
    return float(np.sum(2.0 * np.arctan2(det, den)) / (4.0 * np.pi))


def check_view(parts: Mapping[str, PartMesh], camera: CameraFrame, intrinsics: Intrinsics) -> None:
    """Reject a camera inside a part, looking away from the target, nearer to it than the near
    clipping plane (:data:`~spacefit.scene.schema.NEAR_CLIP_M`), or seeing none of it.

    ``parts`` hold world-frame vertices (m). A camera inside a part's bounding box counts as inside
    unless the part is closed and its winding number says outside. The field-of-view test is
    conservative: it only rejects views whose projected target box misses the image.
    """
    for name, part in parts.items():
        lo, hi = np.array([x.min() for x in part.vertices.T]), np.array([x.max() for x in part.vertices.T])  # by column: 50x faster
        if np.all(camera.position >= lo) and np.all(camera.position <= hi):
            closed = part.to_trimesh().is_watertight
            if not closed or abs(winding_number(camera.position, part.vertices, part.faces)) > 0.5:
                raise InputError(
                    f"`camera.position_m` {camera.position.tolist()} is inside the target's part {name!r} "
                    f"(bounds {lo.round(3).tolist()} to {hi.round(3).tolist()} m)."
                )
    vertices = np.concatenate([p.vertices for p in parts.values()])
    uv, depth = project(vertices, camera, intrinsics)
    if not np.any(depth > 0):
        raise InputError("the camera looks away from the target: the whole target is behind it.")
    nearest = float(depth[depth > 0].min())
    if nearest < NEAR_CLIP_M:
        raise InputError(f"the target comes {nearest:.3g} m in front of the camera (`camera.position_m`), nearer than its "
                         f"near clipping plane at {NEAR_CLIP_M:g} m, which would cut it away: move the camera back.")
    if np.all(depth > 0):
        lo, hi = np.array([u.min() for u in uv.T]), np.array([u.max() for u in uv.T])
        if hi[0] < 0 or hi[1] < 0 or lo[0] > intrinsics.width or lo[1] > intrinsics.height:
            raise InputError(
                "the target is outside the camera's field of view; check `camera.attitude_deg` / "
                "`camera.look_at_m` and `target.position_m`."
            )


# Refined triangles a wrinkled part may have: each costs its W-M terms at its vertices in JAX and
# its share of Mitsuba's BVH (the thesis's body at 2 cm spacing has 141,216).
MAX_REFINED_TRIANGLES = 5_000_000


def check_refinement_size(name: str, part: PartMesh, spacing_m: float) -> None:
    """Refuse a refinement of ``part`` at ``spacing_m`` that would exceed :data:`MAX_REFINED_TRIANGLES`
    (estimated as twice the part's area over spacing^2: a lattice of right triangles)."""
    v = part.vertices[part.faces]
    area = 0.5 * float(np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum())
    estimate = 2.0 * area / spacing_m**2
    if estimate > MAX_REFINED_TRIANGLES:
        smallest = math.sqrt(2.0 * area / MAX_REFINED_TRIANGLES)
        raise InputError(f"`wrinkles.spacing_m` = {spacing_m:g} m refines part {name!r} ({area:.3g} m^2) into about "
                         f"{estimate:.3g} triangles; at most {MAX_REFINED_TRIANGLES:,}: use a spacing of at least "
                         f"{smallest:.3g} m.")


def assemble(scene: Scene) -> Assembly:
    """Load and check geometry, refine wrinkled parts, resolve materials, camera and sun.

    Raises:
        InputError: before any rendering, for any bad mesh, material or view.
    """
    check_scene(scene)
    cache: dict[str, str] = {}
    parts = _load_parts(scene, cache)
    w = scene.wrinkles
    materials = {name: p.material for name, p in scene.parts.items()}
    to_world = body_to_world(scene)
    parts = articulated(parts, scene.parts, to_world[:3, :3].T @ -check_direction("sun.direction", scene.sun.direction))
    camera, intrinsics = _camera(scene)
    sources, lod = {}, {}
    for name in w.parts if w.enabled else ():
        centroid = to_world[:3, :3] @ parts[name].vertices.mean(axis=0) + to_world[:3, 3]
        lod[name], effective = choose_model(name, materials[name], centroid, camera, intrinsics, w)
        if effective is not None:
            materials[name] = effective
        else:
            check_refinement_size(name, parts[name], w.spacing_m)
            vertices, faces = parts[name].vertices.astype(float), parts[name].faces.astype(np.int64)
            sources[name] = (vertices.tobytes(), faces.tobytes(), float(w.spacing_m))
    refinements = Refinements(sources, cache)
    phases = wm_phases(w.M, wm_n_max(w.L, w.Ls, w.gamma), w.seed)
    object_vertices, folds = {}, {}
    for name, part in parts.items():
        if name in refinements:
            object_vertices[name], folds[name], cache[f"{name}.displaced"] = _displaced(part, refinements, name, w, phases)
        else:
            object_vertices[name] = part.vertices
    world = {name: v @ to_world[:3, :3].T + to_world[:3, 3] for name, v in object_vertices.items()}
    assembly = Assembly(scene, parts, materials, refinements, phases, to_world, camera, intrinsics,
                        check_direction("sun.direction", scene.sun.direction), lod, world, cache, folds)
    for note in fold_notes(folds, w):
        warnings.warn(note, stacklevel=2)
    check_view({n: PartMesh(v, assembly.faces(n)) for n, v in world.items()}, camera, intrinsics)
    return assembly
