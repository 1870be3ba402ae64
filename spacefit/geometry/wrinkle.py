"""Wrinkled surfaces: refine a triangle mesh once (NumPy), displace it by W-M heights (JAX).

Thesis section 2.2: each base triangle is projected on the best of the xoy / yoz / xoz planes (the
coordinate axis along which its normal is largest is dropped), sampled on a grid, re-triangulated
by Delaunay, and every sample is displaced along the triangle's normal by the W-M height
z(u, v) of eq. 2-1 at its two kept coordinates (u, v).

Points on a base edge are generated once per edge and shared by both neighbouring triangles, and a
shared point moves only where both triangles lie in one plane (then both see the same height
field and the same normal). Points on bent or boundary edges stay put, so a closed mesh stays
closed after displacement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from typing import TYPE_CHECKING

import numpy as np

from spacefit.errors import InputError, check_range
from spacefit.precision import float64
from spacefit.geometry.wm import wm_height

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s), which a render does not need
    from jaxtyping import Array, Float, Int

# Two faces are coplanar when their unit normals differ by less than this and their plane offsets
# by less than this times the mesh size: tight, so only truly flat neighbours share heights.
COPLANAR_TOL = 1e-9
# Normal components are rounded to this many decimals before picking the projection plane, so
# that near-ties (e.g. a normal along x + y) pick the same plane on coplanar neighbours.
_AXIS_DECIMALS = 9
# Which base edges (corner i to corner i + 1) each corner of a triangle lies on.
_CORNER_SIDES = np.array([[True, False, True], [True, True, False], [False, True, True]])
#: The rms slope (per axis, dimensionless, :func:`wm_rms_slope`) of wrinkles that look like
#: crumpled MLI foil, (low, high): from about 11 deg (gentler reads as a flat sheet with a ripple)
#: to 45 deg (steeper starts to fold the body over itself: the default body's fold fraction is
#: 0.45 % at rms slope 2.3, 7.6 % at the thesis's literal 37). A stated modelling choice: no
#: published slope statistics of crumpled MLI or foil were found (docs/explanation/wrinkles.md).
#:
#: Example:
#:     >>> import spacefit as sf
#:     >>> sf.MLI_SLOPE_RANGE
#:     (0.2, 1.0)
MLI_SLOPE_RANGE = (0.2, 1.0)
# Fraction of a wrinkled part's faces folded over (:func:`fold_fraction`) above which assembly warns.
FOLD_WARN_FRACTION = 0.01


@dataclass(frozen=True)
class Refinement:
    """A refined mesh ready for W-M displacement; N vertices, K triangles.

    Attributes:
        vertices: (N, 3) undisplaced positions on the base surface, metres.
        faces: (K, 3) triangles, wound like the base triangles they came from.
        normals: (N, 3) unit displacement directions (the base triangle's normal).
        uv: (N, 2) W-M plane coordinates: the two kept coordinates of the vertex, metres.
        movable: (N,) 1.0 where the vertex is displaced, 0.0 where it is fixed.
        source_face: (K,) index of the base triangle each triangle came from.
    """

    vertices: Float[np.ndarray, "N 3"]
    faces: Int[np.ndarray, "K 3"]
    normals: Float[np.ndarray, "N 3"]
    uv: Float[np.ndarray, "N 2"]
    movable: Float[np.ndarray, " N"]
    source_face: Int[np.ndarray, " K"]


def _kept_axes(normals: Float[np.ndarray, "m 3"]) -> Int[np.ndarray, "m 2"]:
    """The two coordinate axes kept by the thesis's projection: drop the axis of largest |normal|."""
    dropped = np.argmax(np.round(np.abs(normals), _AXIS_DECIMALS), axis=1)
    return np.array([[1, 2], [0, 2], [0, 1]])[dropped]


def _signed_area2(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Twice the signed area of 2-D triangles (a, b, c), each (..., 2)."""
    ab, ac = b - a, c - a
    return ab[..., 0] * ac[..., 1] - ab[..., 1] * ac[..., 0]


def _lattice_points(corners: Float[np.ndarray, "3 2"], spacing: float) -> Float[np.ndarray, "p 2"]:
    """Points of the global lattice ``spacing * Z^2`` inside a 2-D triangle, half a spacing from its edges."""
    lo = np.ceil(corners.min(axis=0) / spacing)
    hi = np.floor(corners.max(axis=0) / spacing)
    iu, iv = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    points = np.stack([iu.ravel(), iv.ravel()], axis=1) * spacing
    orientation = np.sign(_signed_area2(*corners))
    keep = np.ones(len(points), dtype=bool)
    for a, b in [(0, 1), (1, 2), (2, 0)]:
        edge = corners[b] - corners[a]
        # Signed distance to the edge's line, positive inside.
        distance = orientation * _signed_area2(corners[a], corners[b], points) / np.linalg.norm(edge)
        keep &= distance >= 0.5 * spacing
    return points[keep]


def _flat_edges(
    faces: Int[np.ndarray, "m 3"], face_normals: Float[np.ndarray, "m 3"], offsets: Float[np.ndarray, " m"], size: float
) -> tuple[Int[np.ndarray, "e 2"], Int[np.ndarray, "m 3"], Int[np.ndarray, " e"], np.ndarray]:
    """Unique edges (sorted vertex ids), each face's edges, each edge's first face, flat-edge mask.

    ``face_edges[f, i]`` is the edge from corner i to corner i + 1 of face f. An edge is flat when
    exactly two faces share it and they lie in one plane with the same orientation.
    """
    corner_pairs = np.sort(faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    edges, face_edges, counts = np.unique(corner_pairs, axis=0, return_inverse=True, return_counts=True)
    face_edges = face_edges.reshape(-1, 3)
    by_edge = np.argsort(face_edges.ravel(), kind="stable") // 3
    starts = np.cumsum(counts) - counts
    f1, f2 = by_edge[starts], by_edge[np.minimum(starts + 1, len(by_edge) - 1)]
    flat = (
        (counts == 2)
        & (np.linalg.norm(face_normals[f1] - face_normals[f2], axis=1) < COPLANAR_TOL)
        & (np.abs(offsets[f1] - offsets[f2]) < COPLANAR_TOL * size)
    )
    return edges, face_edges, f1, flat


def _triangulate(points2d: Float[np.ndarray, "p 2"], sides: np.ndarray, area2: float) -> Int[np.ndarray, "k 3"]:
    """Delaunay triangles of one base triangle's samples, wound like the base.

    Args:
        points2d: (p, 2) samples in the projection plane.
        sides: (p, 3) bool, whether each sample lies on each base edge.
        area2: twice the base triangle's signed area in the projection plane.
    """
    from scipy.spatial import Delaunay  # here: a render of a cached refinement never needs SciPy (0.4 s)

    simplices = Delaunay(points2d).simplices
    # Points on one base edge are collinear only up to rounding, and Delaunay may join them into
    # zero-area triangles; every such triangle has all three corners on one base edge.
    simplices = simplices[~np.any(np.all(sides[simplices], axis=1), axis=1)]
    signed = _signed_area2(*points2d[simplices].transpose(1, 0, 2))
    return np.where((np.sign(signed) == np.sign(area2))[:, None], simplices, simplices[:, ::-1])


def refine(
    vertices: Float[np.ndarray, "n 3"],
    faces: Int[np.ndarray, "m 3"],
    spacing: float,
    *,
    max_vertices: int = 5_000_000,
) -> Refinement:
    """Refine a mesh for W-M wrinkles (thesis section 2.2) at sample spacing ``spacing`` (m).

    Interior samples lie on a global lattice of pitch ``spacing`` in each triangle's projection
    plane, at least half a spacing from its edges; each base edge is cut into
    ceil(length / spacing) equal segments. Each base triangle's samples are triangulated by 2-D
    Delaunay in its projection plane.

    Args:
        vertices: (n, 3) base vertices, metres (a mesh checked by ``validate_part``: no degenerate
            triangles).
        faces: (m, 3) base triangles.
        spacing: sample spacing, metres, > 0.
        max_vertices: refusal threshold on the (estimated) refined vertex count.

    Raises:
        InputError: naming ``wrinkles.spacing_m`` if ``spacing`` is not a positive number or would
            give more than ``max_vertices`` vertices.
    """
    spacing = check_range("wrinkles.spacing_m", spacing, 0.0, lo_open=True, unit="m")
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    tri = vertices[faces]  # (m, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_normals = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    offsets = np.einsum("mj,mj->m", face_normals, tri[:, 0])
    kept = _kept_axes(face_normals)
    tri2d = np.take_along_axis(tri, kept[:, None, :], axis=2)  # (m, 3, 2)
    area2 = _signed_area2(tri2d[:, 0], tri2d[:, 1], tri2d[:, 2])
    edges, face_edges, edge_face, flat = _flat_edges(faces, face_normals, offsets, np.ptp(vertices, axis=0).max())

    segments = np.maximum(np.ceil(np.linalg.norm(vertices[edges[:, 1]] - vertices[edges[:, 0]], axis=1) / spacing), 1)
    per_edge = (segments - 1).astype(np.int64)
    estimate = len(vertices) + per_edge.sum() + np.abs(area2).sum() / 2 / spacing**2
    if estimate > max_vertices:
        raise InputError(
            f"`wrinkles.spacing_m` = {spacing:g} m would refine the mesh to about {estimate:.3g} vertices, "
            f"more than the maximum {max_vertices}; use a larger spacing "
            f"(about {spacing * math.sqrt(estimate / max_vertices):.3g} m or more)."
        )

    # Edge points, generated once per edge from its canonical orientation, follow the base vertices.
    edge_start = np.cumsum(per_edge) - per_edge
    point_edge = np.repeat(np.arange(len(edges)), per_edge)
    t = (np.arange(per_edge.sum()) - edge_start[point_edge] + 1) / segments[point_edge]
    a, b = vertices[edges[point_edge, 0]], vertices[edges[point_edge, 1]]
    edge_points = a + t[:, None] * (b - a)

    interiors, new_faces = [], []
    next_id = len(vertices) + len(edge_points)
    for f in range(len(faces)):
        i, j = kept[f]
        interior = _lattice_points(tri2d[f], spacing)
        # Lift the samples onto the triangle's plane along the dropped axis.
        n, k = face_normals[f], 3 - i - j
        lifted = np.empty((len(interior), 3))
        lifted[:, [i, j]] = interior
        lifted[:, k] = (offsets[f] - interior @ n[[i, j]]) / n[k]
        interiors.append(lifted)
        on_edges = np.concatenate([np.arange(edge_start[e], edge_start[e] + per_edge[e]) for e in face_edges[f]])
        local = np.concatenate([tri2d[f], edge_points[on_edges][:, [i, j]], interior])
        sides = np.concatenate(
            [
                _CORNER_SIDES,
                np.repeat(np.eye(3, dtype=bool), per_edge[face_edges[f]], axis=0),
                np.zeros((len(interior), 3), dtype=bool),
            ]
        )
        ids = np.concatenate([faces[f], len(vertices) + on_edges, np.arange(next_id, next_id + len(interior))])
        next_id += len(interior)
        new_faces.append(ids[_triangulate(local, sides, area2[f])])

    # Each vertex takes its normal and projection plane from one owning face: any incident face
    # for a base vertex, the first face of its edge for an edge point, its own face otherwise.
    referenced, first_use = np.unique(faces.ravel(), return_index=True)
    base_owner = np.zeros(len(vertices), dtype=np.int64)
    base_owner[referenced] = first_use // 3
    base_movable = np.zeros(len(vertices))
    base_movable[referenced] = 1.0
    base_movable[edges[~flat].ravel()] = 0.0
    per_face = np.arange(len(faces))
    interior_owner = np.repeat(per_face, [len(p) for p in interiors])
    owner = np.concatenate([base_owner, edge_face[point_edge], interior_owner])
    movable = np.concatenate([base_movable, flat[point_edge].astype(float), np.ones(len(interior_owner))])
    points = np.concatenate([vertices, edge_points, *interiors])
    uv = np.take_along_axis(points, kept[owner], axis=1)
    source_face = np.repeat(per_face, [len(t) for t in new_faces])
    return Refinement(points, np.concatenate(new_faces), face_normals[owner], uv, movable, source_face)


@float64
def displace(
    ref: Refinement,
    D: float | Array,
    G: float | Array,
    *,
    gamma: float,
    M: int,
    L: float,
    Ls: float,
    phases: Float[np.ndarray, "M K"],
) -> Float[Array, "N 3"]:
    """Wrinkled vertices (N, 3), metres: ``vertices + movable * z(uv) * normals`` (thesis eq. 2-1).

    Differentiable in the fractal dimension ``D`` and height scale ``G`` (metres); the other W-M
    parameters are as in :func:`spacefit.geometry.wm.wm_height`.
    """
    import jax.numpy as jnp  # here: a render of cached vertices never needs JAX (0.6 s)

    heights = wm_height(ref.uv, D, G, gamma=gamma, M=M, L=L, Ls=Ls, phases=phases)
    return jnp.asarray(ref.vertices) + (jnp.asarray(ref.movable) * heights)[:, None] * jnp.asarray(ref.normals)


def fold_fraction(ref: Refinement, vertices: Float[np.ndarray, "N 3"]) -> float:
    """Fraction of the displaced faces folded over: turned more than 90 deg from the base surface under them.

    Inside one base face the wrinkles are a height field along its normal (thesis section 2.2), so
    no face turns over its own base face; a body folds over itself where wrinkles taller than
    their distance to an edge of the base mesh push a face across into a neighbour's side (the
    "hair" at the silhouette of the thesis's literal G = 10 m). A face counts as folded when its
    normal points against the normal of the nearest undisplaced movable sample to its centroid:
    seen from outside there, it shows its back. ``vertices`` (N, 3, metres) are the displaced
    positions of ``ref`` (:func:`displace`); 0 for no faces.
    """
    from scipy.spatial import cKDTree  # here: a render of a cached displaced part never needs SciPy (0.4 s)

    movable = ref.movable > 0
    if not np.any(movable) or len(ref.faces) == 0:
        return 0.0
    tri = np.asarray(vertices, float)[ref.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    _, nearest = cKDTree(ref.vertices[movable]).query(tri.mean(axis=1))
    return float(np.mean(np.einsum("ij,ij->i", normals, ref.normals[movable][nearest]) < 0.0))
