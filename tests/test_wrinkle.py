"""Refinement and W-M displacement of meshes (thesis section 2.2): closed stays closed, gradients in D and G."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest
import trimesh

import spacefit  # noqa: F401
from spacefit.errors import InputError
from spacefit.geometry.wm import wm_height, wm_n_max, wm_phases
from spacefit.geometry.wrinkle import Refinement, displace, refine

WM = {"gamma": 1.5, "M": 5, "L": 0.1, "Ls": 5e-3}
PHASES = wm_phases(WM["M"], wm_n_max(WM["L"], WM["Ls"], WM["gamma"]), seed=0)
D, G = 2.3, 1e-4  # heights of a few millimetres


@pytest.fixture(autouse=True)
def float64_mode():
    """jvp traces D and G from the test: float64 tracers, as in spacefit's own scoped callers."""
    with jax.enable_x64(True):
        yield


def box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(1.0, 0.8, 0.6))


def icosphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=1, radius=0.5)


def wrinkled(ref: Refinement, d: float = D, g: float = G) -> np.ndarray:
    return np.asarray(displace(ref, d, g, **WM, phases=PHASES))


@pytest.mark.parametrize("make, spacing", [(box, 0.1), (icosphere, 0.08)])
def test_displaced_mesh_is_closed(make, spacing):
    base = make()
    ref = refine(base.vertices, base.faces, spacing)
    flat = trimesh.Trimesh(ref.vertices, ref.faces, process=False)
    assert np.all(np.einsum("kj,kj->k", flat.face_normals, base.face_normals[ref.source_face]) > 1 - 1e-9)
    assert len(np.unique(ref.vertices, axis=0)) == len(ref.vertices)
    mesh = trimesh.Trimesh(wrinkled(ref), ref.faces, process=False)
    mesh.merge_vertices()
    assert len(mesh.vertices) == len(ref.vertices)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(base.volume, rel=0.05)


def test_fixed_vertices_stay_and_movable_ones_move_by_the_height():
    base = icosphere()
    ref = refine(base.vertices, base.faces, 0.08)
    moved = wrinkled(ref) - ref.vertices
    fixed = ref.movable == 0.0
    assert fixed.any() and (~fixed).any()
    assert np.all(moved[fixed] == 0.0)
    heights = np.asarray(wm_height(ref.uv, D, G, **WM, phases=PHASES))
    np.testing.assert_allclose(moved[~fixed], heights[~fixed, None] * ref.normals[~fixed], rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(ref.normals, axis=1), 1.0)


def test_box_diagonals_move_and_box_edges_stay():
    base = box()
    ref = refine(base.vertices, base.faces, 0.1)
    half = np.array([0.5, 0.4, 0.3])
    on_box_edge = np.sum(np.isclose(np.abs(ref.vertices), half), axis=1) >= 2
    assert np.all(ref.movable[on_box_edge] == 0.0)
    # Every other point of the surface, face diagonals included, moves: only the box edges are fixed.
    assert np.all(ref.movable[~on_box_edge] == 1.0)
    diagonals = [e for e in base.edges_unique if np.sum(base.vertices[e[0]] != base.vertices[e[1]]) == 2]
    assert len(diagonals) == 6
    for a, b in base.vertices[np.array(diagonals)]:
        on_diagonal = np.linalg.norm(np.cross(ref.vertices - a, b - a), axis=1) < 1e-12
        on_diagonal &= ~on_box_edge
        assert on_diagonal.sum() >= 5 and np.all(ref.movable[on_diagonal] == 1.0)


def test_vertex_count_scales_as_inverse_spacing_squared():
    base = box()
    coarse, fine = (len(refine(base.vertices, base.faces, s).vertices) for s in (0.1, 0.05))
    assert 3.0 < fine / coarse < 5.0


@pytest.mark.parametrize("which", ["D", "G"])
def test_displacement_derivatives_match_finite_differences(which):
    base = icosphere()
    ref = refine(base.vertices, base.faces, 0.1)
    point = {"D": 2.5, "G": 3e-3}

    def vertices(value):
        args = {**point, which: value}
        return displace(ref, args["D"], args["G"], **WM, phases=PHASES)

    _, tangent = jax.jvp(vertices, (point[which],), (1.0,))
    h = 1e-6
    central = (np.asarray(vertices(point[which] + h)) - np.asarray(vertices(point[which] - h))) / (2 * h)
    assert np.abs(central).max() > 0
    np.testing.assert_allclose(np.asarray(tangent), central, rtol=1e-6, atol=1e-8 * np.abs(central).max())


@pytest.mark.parametrize("spacing", [0.0, -1.0, math.nan, math.inf])
def test_bad_spacing_is_named(spacing):
    base = box()
    with pytest.raises(InputError, match="wrinkles.spacing"):
        refine(base.vertices, base.faces, spacing)


def test_too_many_vertices_is_refused():
    base = box()
    with pytest.raises(InputError, match="wrinkles.spacing.*larger spacing"):
        refine(base.vertices, base.faces, 0.01, max_vertices=1000)
