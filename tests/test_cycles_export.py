"""The scene description spacefit hands to Blender Cycles (spacefit.rendering.cycles, for
experiments/cycles_peer.py) matches the scene spacefit renders (no bpy needed)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from spacefit.rendering.cycles import cycles_roughness, export_view, read_ply
from spacefit.rendering.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene

# the close view of forward_pareto.VIEWS, where a panel is several pixels thick; coarse wrinkles for speed
SMALL = ["camera.position_m=[0, 0, 25]", "wrinkles.spacing_m=0.2"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    assembly = assemble(load_scene(None, SMALL))
    folder = tmp_path_factory.mktemp("cycles_scene")
    description = export_view(assembly, folder)
    return assembly, folder, description


def pinhole(points: np.ndarray, camera: dict, width: int, height: int) -> np.ndarray:
    """Pixel coordinates (u right, v down, origin top-left) of world points through the exported camera."""
    d = points - np.array(camera["position_m"])
    depth = d @ np.array(camera["forward"])
    u = width / 2 + camera["principal_offset_px"][0] + camera["focal_px"] * (d @ np.array(camera["right"])) / depth
    v = height / 2 + camera["principal_offset_px"][1] - camera["focal_px"] * (d @ np.array(camera["up"])) / depth
    return np.stack([u, v], axis=-1)


def test_meshes_round_trip_in_world_coordinates(exported):
    assembly, folder, description = exported
    assert json.loads((folder / "scene.json").read_text()) == description
    for name in assembly.parts:
        vertices, faces, uv = read_ply(folder / description["parts"][name]["ply"])
        np.testing.assert_array_equal(vertices, assembly.scene_vertices[name].astype(np.float32))
        np.testing.assert_array_equal(faces, assembly.faces(name))
        has_uv = name not in assembly.refinements and assembly.parts[name].uv is not None
        assert (uv is not None) == has_uv == (description["parts"][name]["material"].get("tangent") == "uv")
        if has_uv:
            np.testing.assert_allclose(uv, assembly.parts[name].uv, rtol=1e-6)
    assert len(read_ply(folder / "body.ply")[1]) == len(assembly.faces("body")) > len(assembly.parts["body"].faces)


def test_camera_sees_what_spacefit_sees(exported):
    assembly, _, description = exported
    camera, render = description["camera"], description["render"]
    assert (render["width"], render["height"], render["depth"]) == (600, 600, assembly.scene.render.depth)
    # the bounding-box centre of the right panel (a box) lies in it; the pixel it projects to sees the panels
    panels = assembly.scene_vertices["panels"]
    right = panels[panels[:, 0] > 0]
    centre = (right.min(axis=0) + right.max(axis=0)) / 2
    u, v = pinhole(centre[None], camera, render["width"], render["height"])[0]
    renderer = Renderer(assembly)
    assert tuple(render["window"]) == renderer.window  # Cycles' render border is spacefit's window
    ids = renderer.part_image()
    assert ids.names[ids.ids[int(v), int(u)]] == "panels"
    assert v < render["height"] / 2  # the panels are at the top of the default image: v grows downwards
    # and the horizontal field of view agrees with Mitsuba's
    assert 2 * math.atan(render["width"] / 2 / camera["focal_px"]) == pytest.approx(assembly.intrinsics.fov_x, rel=1e-12)


def test_sun_materials_and_filter(exported):
    assembly, _, description = exported
    sun = description["sun"]
    d = np.array(assembly.scene.sun.direction, float)
    np.testing.assert_allclose(sun["direction"], d / np.linalg.norm(d))
    assert sun["irradiance_w_m2"] == assembly.scene.sun.irradiance_w_m2
    panels = description["parts"]["panels"]["material"]
    assert (panels["type"], panels["alpha_x"], panels["alpha_y"]) == ("conductor", 0.08, 0.05)
    assert description["parts"]["legs"]["material"] == {"type": "lambert", "kd": [0.2, 0.2, 0.2]}
    assert description["render"]["filter_type"] == "GAUSSIAN"
    assert (description["render"]["filter_width_px"] / 4) ** 2 == pytest.approx(1 / 6)  # the tent's variance


@pytest.mark.parametrize("alpha_x, alpha_y", [(0.08, 0.05), (0.05, 0.08), (0.14, 0.14)])
def test_cycles_roughness_gives_back_the_alphas(alpha_x, alpha_y):
    roughness, anisotropy, rotation = cycles_roughness(alpha_x, alpha_y)
    # Cycles' Metallic BSDF: r = Roughness^2, aspect = sqrt(1 - 0.9 a); r / aspect along the tangent turned by Rotation turns
    r, aspect = roughness**2, math.sqrt(1 - 0.9 * anisotropy)
    along, across = (r / aspect, r * aspect) if rotation == 0.0 else (r * aspect, r / aspect)
    assert (along, across) == pytest.approx((alpha_x, alpha_y), rel=1e-12)
    assert 0.0 <= anisotropy <= 1.0 and rotation in (0.0, 0.25)
