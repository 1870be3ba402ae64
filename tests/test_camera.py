"""The renderer's camera agrees with the pinhole model of thesis section 3.2."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj

from spacefit.cases import load_case
from spacefit.geometry.frames import CameraFrame, Intrinsics, attitude_matrix, project
from spacefit.rendering.renderer import render
from spacefit.scene.assembly import assemble


def test_attitude_matrices_are_the_thesis_matrices():
    a = np.radians(30.0)
    r1 = attitude_matrix([a, 0.0, 0.0])
    assert np.allclose(r1, [[1, 0, 0], [0, np.cos(a), np.sin(a)], [0, -np.sin(a), np.cos(a)]])
    r = attitude_matrix(np.radians([20.0, -35.0, 110.0]))
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    # Table 4-2's target attitude [90, 0, 0] turns a +z-up lander's top to world +y (image up).
    assert np.allclose(attitude_matrix(np.radians([90.0, 0.0, 0.0])) @ [0, 0, 1], [0, 1, 0])


def test_look_at_and_attitude_agree():
    by_att = CameraFrame.from_attitude(np.array([0.0, 0.0, 70.0]), np.zeros(3))
    by_look = CameraFrame.look_at(np.array([0.0, 0.0, 70.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]))
    for a, b in [(by_att.right, by_look.right), (by_att.up, by_look.up), (by_att.forward, by_look.forward)]:
        assert np.allclose(a, b)


def test_roll_turns_either_camera_mode_about_its_optical_axis():
    """``camera.roll_deg`` acts alike with an attitude and with look_at + up: right-handed about the
    viewing direction, image up turns towards image right; a point right of centre moves up in the image."""
    scene = load_case("panels").scene().with_values({"camera.position_m": [0.0, 0.0, 70.0], "camera.roll_deg": 30.0})
    by_att = assemble(scene.with_values({"camera.look_at_m": [], "camera.attitude_deg": [0.0, 0.0, 0.0]})).camera
    by_look = assemble(scene.with_values({"camera.look_at_m": [0.0, 0.0, 0.0], "camera.up": [0.0, 1.0, 0.0]})).camera
    r = np.radians(30.0)
    for frame in (by_att, by_look):
        assert np.allclose(frame.up, [np.sin(r), np.cos(r), 0.0]) and np.allclose(frame.right, [np.cos(r), -np.sin(r), 0.0])
        assert np.allclose(frame.forward, [0.0, 0.0, -1.0])
    intr = Intrinsics(7.0, 4e-3, 600, 600)
    uv, _ = project(np.array([[1.0, 0.0, 0.0]]), by_look, intr)
    assert np.allclose(uv[0], [300.0 + 25.0 * np.cos(r), 300.0 - 25.0 * np.sin(r)])  # anticlockwise in the image


def test_projection_of_thesis_camera():
    intr = Intrinsics(7.0, 4e-3, 600, 600)
    cam = CameraFrame.from_attitude(np.array([0.0, 0.0, 70.0]), np.zeros(3))
    uv, depth = project(np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.0]]), cam, intr)
    assert np.allclose(uv[0], [300.0, 300.0]) and depth[0] == pytest.approx(70.0)
    # 1 m at 70 m through f = 7 m is 0.1 m on the sensor, 25 pixels of 4 mm; +y is image up
    assert np.allclose(uv[1], [325.0, 250.0])
    assert np.degrees(intr.fov_x) == pytest.approx(19.455, abs=0.001)  # 2 atan(1.2 m / 7 m)


@pytest.mark.parametrize(
    ("camera", "pixel"),
    [
        ({"position_m": [0.0, 0.0, 10.0], "attitude_deg": [0.0, 0.0, 0.0]}, [52.3, 21.7]),
        ({"position_m": [1.0, -2.0, 9.0], "attitude_deg": [12.0, -5.0, 30.0], "principal_offset_px": [6.0, -4.0]}, [20.2, 40.6]),
        ({"position_m": [6.0, 5.0, 4.0], "look_at_m": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0], "principal_offset_px": [-5.0, 3.0]}, [61.0, 15.4]),
    ],
)
def test_point_projects_to_expected_pixel(tmp_path, camera, pixel):
    """A small sphere placed on the ray through ``pixel`` renders centred on that pixel."""
    sphere = write_sphere_obj(tmp_path / "sphere.obj", radius=0.04, subdivisions=3)
    settings = {"focal_length_mm": 60.0, "pixel_pitch_mm": 0.05, **camera}
    probe = small_scene(sphere, {"material": "white_paint", "kd": 1.0}, render={"resolution": [80, 60]}, camera=settings)
    a = assemble(probe)
    u0, v0 = a.intrinsics.principal_point
    f = a.intrinsics.focal_px
    ray = a.camera.forward + (pixel[0] - u0) / f * a.camera.right - (pixel[1] - v0) / f * a.camera.up
    point = a.camera.position + 9.0 * ray
    assert np.allclose(project(point[None], a.camera, a.intrinsics)[0][0], pixel)
    # lit from the camera's side, so the sphere's image is symmetric about its centre
    scene = small_scene(
        sphere,
        {"material": "white_paint", "kd": 1.0},
        render={"resolution": [80, 60], "spp": 64},
        camera=settings,
        target={"position_m": point.tolist()},
        sun={"direction": ray.tolist()},
    )
    img = render(scene).sum(axis=-1)
    v, u = np.nonzero(img > 0)
    w = img[v, u]
    centroid = np.array([np.sum((u + 0.5) * w), np.sum((v + 0.5) * w)]) / w.sum()
    assert np.allclose(centroid, pixel, atol=0.25)
