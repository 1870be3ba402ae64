"""Mesh import (STL binary / ASCII, PLY, OBJ, grouped OBJ), binary STL export, bad meshes."""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest
import trimesh
from helpers import small_scene, write_sphere_obj

from spacefit.errors import InputError
from spacefit.geometry.lander import builtin_lander
from spacefit.geometry.mesh import PartMesh, export_stl, load_grouped, load_part, validate_part
from spacefit.rendering.renderer import render


def same_triangles(a: PartMesh, b: PartMesh) -> bool:
    ta = np.sort(a.vertices[a.faces].reshape(len(a.faces), -1), axis=0)
    tb = np.sort(b.vertices[b.faces].reshape(len(b.faces), -1), axis=0)
    return ta.shape == tb.shape and np.allclose(ta, tb, atol=1e-5)


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".obj", "ascii.stl"])
def test_round_trip(tmp_path, suffix):
    legs = builtin_lander()["legs"]
    path = tmp_path / f"legs{suffix}"
    if suffix == "ascii.stl":
        path.write_text(trimesh.exchange.stl.export_stl_ascii(legs.to_trimesh()))
    else:
        legs.to_trimesh().export(path)
    assert same_triangles(load_part("legs", path), legs)


def test_binary_stl_export_layout(tmp_path):
    body = builtin_lander()["body"]
    path = tmp_path / "body.stl"
    export_stl(path, body.vertices, body.faces)
    raw = path.read_bytes()
    (count,) = struct.unpack("<I", raw[80:84])
    assert count == len(body.faces) and len(raw) == 84 + 50 * count
    assert same_triangles(load_part("body", path), body)


def test_grouped_obj_gives_one_part_per_group(tmp_path):
    parts = builtin_lander()
    scene = trimesh.Scene({name: p.to_trimesh() for name, p in parts.items()})
    path = tmp_path / "lander.obj"
    scene.export(path)
    loaded = load_grouped(path)
    assert set(loaded) == set(parts)
    for name in parts:
        assert same_triangles(loaded[name], parts[name])


def test_obj_uv_is_kept(tmp_path):
    path = tmp_path / "plate.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nf 1/1 2/2 3/3\n")
    part = load_part("plate", path)
    assert part.uv is not None and np.allclose(part.uv[:, 0], part.vertices[:, 0])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "does not exist"),
        (b"solid x\nthis is not an stl\n", "plate"),
        (b"", "plate"),
    ],
)
def test_bad_files(tmp_path, content, message):
    path = tmp_path / "plate.stl"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(InputError, match=message):
        load_part("plate", path)


def test_unsupported_format(tmp_path):
    path = tmp_path / "plate.fbx"
    path.write_text("x")
    with pytest.raises(InputError, match="format must be one of"):
        load_part("plate", path)


def test_degenerate_and_empty_meshes():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    with pytest.raises(InputError, match="degenerate"):
        validate_part("p", PartMesh(v, np.array([[0, 1, 3], [0, 1, 2]])))
    with pytest.raises(InputError, match="no triangles"):
        validate_part("p", PartMesh(v, np.zeros((0, 3), int)))
    with pytest.raises(InputError, match="finite"):
        validate_part("p", PartMesh(np.where(v == 2, np.nan, v), np.array([[0, 1, 3]])))
    with pytest.raises(InputError, match="face indices"):
        validate_part("p", PartMesh(v, np.array([[0, 1, 7]])))


def test_inside_out_closed_part_is_turned_and_renders_as_the_right_one(tmp_path):
    """A closed mesh wound inward is reversed, with a warning, so its normals point outward."""
    right = write_sphere_obj(tmp_path / "sphere.obj", subdivisions=2)
    mesh = trimesh.load(right, process=False)
    inverted = tmp_path / "inverted" / "sphere.obj"
    inverted.parent.mkdir()
    trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False).export(inverted)
    with pytest.warns(UserWarning, match="wind inward"):
        part = load_part("sphere", inverted)
    assert trimesh.Trimesh(part.vertices, part.faces, process=False).volume > 0
    image = render(small_scene(right, {"material": "white_paint"}))
    with pytest.warns(UserWarning, match="wind inward"):
        turned = render(small_scene(inverted, {"material": "white_paint"}))
    images = [image, turned]
    assert images[1].mean() > 0 and np.allclose(images[0], images[1], rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("suffix", [".stl", "ascii.stl", ".ply", ".obj"])
def test_inward_closed_mesh_is_detected_in_every_format(tmp_path, suffix):
    """STL stores each triangle's corners apart: vertices are merged before the closed check, so an
    inward STL is turned like an OBJ or PLY; an outward one gives no warning."""
    sphere = trimesh.creation.icosphere(subdivisions=1)
    inward = trimesh.Trimesh(sphere.vertices, sphere.faces[:, ::-1], process=False)
    for mesh, name in [(inward, "inward"), (sphere, "outward")]:
        path = tmp_path / f"{name}{suffix}"
        if suffix == "ascii.stl":
            path.write_text(trimesh.exchange.stl.export_stl_ascii(mesh))
        else:
            mesh.export(path)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            part = load_part(name, path)
        assert any("wind inward" in str(w.message) for w in caught) == (name == "inward")
        assert trimesh.Trimesh(part.vertices, part.faces, process=False).volume > 0
