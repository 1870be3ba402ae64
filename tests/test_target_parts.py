"""A target's parts from a mesh file's named groups (OBJ, PLY, STL, glTF through trimesh), and the
errors for every mismatch between the scene's parts and the mesh's groups."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import spacefit as sf
from spacefit.geometry.mesh import load_grouped
from spacefit.scene.toml import scene_from_dict

BODY = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
PANELS = trimesh.creation.box(extents=(3.0, 1.0, 0.05)).apply_translation((0.0, 0.0, 0.6))


def write_grouped(path: Path) -> Path:
    """``body`` and ``panels`` as named groups in the file's format (PLY has none: one mesh)."""
    if path.suffix == ".stl":  # ASCII STL: one named `solid` per part
        path.write_text("\n".join(trimesh.exchange.stl.export_stl_ascii(m).replace("solid ", f"solid {name}", 1)
                                  for name, m in (("body", BODY), ("panels", PANELS))))
    elif path.suffix == ".ply":
        trimesh.util.concatenate([BODY, PANELS]).export(path)
    else:
        scene = trimesh.Scene()
        for name, mesh in (("body", BODY), ("panels", PANELS)):
            scene.add_geometry(mesh, geom_name=name, node_name=name)
        scene.export(path)
    return path


def scene(mesh: Path, parts: dict) -> sf.Scene:
    return scene_from_dict({
        "render": {"resolution": [32, 32], "spp": 4, "depth": 1, "seed": 1},
        "camera": {"position_m": [0.0, 0.0, 10.0], "look_at_m": [0.0, 0.0, 0.0], "focal_length_mm": 50.0,
                   "pixel_pitch_mm": 0.2},
        "sun": {"irradiance_w_m2": 5.0, "direction": [0.3, 0.2, -1.0]},
        "target": {"attitude_deg": [0.0, 0.0, 0.0], "mesh": str(mesh)},
        "wrinkles": {"enabled": False},
        "parts": parts,
    })


TWO = {"body": {"material": "white_paint"}, "panels": {"material": "white_paint"}}


@pytest.mark.parametrize("suffix", [".obj", ".glb", ".gltf", ".stl"])
def test_groups_are_the_parts_in_every_format(tmp_path, suffix):
    """Each named group becomes the part of its name, with the group's triangles (areas kept), and
    renders as the same parts given one file each."""
    path = write_grouped(tmp_path / f"target{suffix}")
    groups = load_grouped(path)
    assert sorted(groups) == ["body", "panels"]
    for name, mesh in (("body", BODY), ("panels", PANELS)):
        tri = groups[name].vertices[groups[name].faces]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
        assert area == pytest.approx(mesh.area, rel=1e-6)
    image = sf.render(scene(path, TWO))
    files = {}
    for name, mesh in (("body", BODY), ("panels", PANELS)):
        mesh.export(tmp_path / f"{name}.ply")
        files[name] = {"material": "white_paint", "file": str(tmp_path / f"{name}.ply")}
    apart = sf.render(scene(tmp_path / "body.ply", files))
    assert image.mean() > 0 and np.allclose(image, apart, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("suffix", [".obj", ".glb", ".gltf", ".stl"])
def test_unknown_part_names_groups_and_parts(tmp_path, suffix):
    path = write_grouped(tmp_path / f"target{suffix}")
    bad = {**TWO, "antenna": {"material": "white_paint"}}
    with pytest.raises(sf.InputError) as err:
        sf.render(scene(path, bad))
    message = str(err.value)
    assert "'antenna'" in message and "its groups: " in message and "body" in message and "panels" in message
    assert "the scene's parts: body, panels, antenna" in message
    if suffix == ".obj":  # the file's own order
        assert "its groups: body, panels;" in message


@pytest.mark.parametrize("suffix", [".obj", ".glb", ".gltf", ".stl"])
def test_missing_part_names_the_group_without_one(tmp_path, suffix):
    path = write_grouped(tmp_path / f"target{suffix}")
    with pytest.raises(sf.InputError) as err:
        sf.render(scene(path, {"body": {"material": "white_paint"}}))
    message = str(err.value)
    assert "group(s) 'panels' that no part names" in message and "the scene's parts: body" in message
    assert "[parts.panels]" in message


@pytest.mark.parametrize("suffix", [".ply", ".stl-binary", ".obj-plain"])
def test_mesh_without_groups(tmp_path, suffix):
    """A PLY, a binary STL or an OBJ without `g` / `o` has no groups: a part needs its own file."""
    path = tmp_path / f"target.{suffix.split('-')[0].lstrip('.')}"
    trimesh.util.concatenate([BODY, PANELS]).export(path)
    assert load_grouped(path) == {}
    with pytest.raises(sf.InputError, match="has no named groups") as err:
        sf.render(scene(path, TWO))
    assert "the scene's parts: body, panels" in str(err.value)
    one = scene(path, {"target": {"material": "white_paint", "file": str(path)}})
    assert sf.render(one).mean() > 0  # the whole file as one part of its own


def test_empty_group_is_named(tmp_path):
    path = tmp_path / "target.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ng body\nf 1 2 3\ng antenna\ng panels\nf 1 2 4\n")
    with pytest.raises(sf.InputError, match=r"group\(s\) 'antenna' hold no triangles; its groups with triangles: body, panels"):
        load_grouped(path)


def test_no_parts_table_names_the_groups(tmp_path):
    """The refusal a new user met: it now names the mesh's groups and the parts found."""
    path = write_grouped(tmp_path / "target.obj")
    with pytest.raises(sf.InputError, match=r"its groups: .*body.*; parts found: none"):
        scene_from_dict({"target": {"mesh": str(path)}})
