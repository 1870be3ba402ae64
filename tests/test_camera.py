"""The renderer's camera agrees with the pinhole model of thesis section 3.2."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj

from spacefit.cases import CASES_DIR, load_case
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


def test_a_field_of_view_sets_the_pitch_and_a_new_resolution_keeps_the_field(tmp_path):
    """``camera.fov_deg`` sets the pixel pitch; a resolution change then keeps the field, and the
    target covers the same fraction of the image (without it the pitch is kept and the field narrows)."""
    from spacefit.rendering.renderer import Renderer

    sphere = write_sphere_obj(tmp_path / "sphere.obj", radius=0.8, subdivisions=3)
    base = small_scene(sphere, {"material": "white_paint", "kd": 1.0}, render={"resolution": [48, 48]}, camera={"pixel_pitch_mm": 0.25})
    fov = float(np.degrees(Intrinsics.from_scene(base).fov_x))
    by_field = base.with_values({"camera.fov_deg": fov})
    assert by_field.camera.pixel_pitch_mm == pytest.approx(0.25, rel=1e-12)
    pitch_kept, field_kept = (s.with_values({"render.resolution": [96, 96]}) for s in (base, by_field))
    assert field_kept.camera.pixel_pitch_mm == pytest.approx(0.125, rel=1e-12) and pitch_kept.camera.pixel_pitch_mm == 0.25
    assert np.degrees(Intrinsics.from_scene(field_kept).fov_x) == pytest.approx(fov, rel=1e-12)

    def covered(scene) -> float:
        """The fraction of the image's pixels whose centre ray hits the sphere."""
        return float((Renderer(scene).part_image().ids >= 0).mean())

    small = covered(base)
    assert 0.2 < small < 0.5
    assert covered(field_kept) == pytest.approx(small, rel=0.03)
    assert covered(pitch_kept) == pytest.approx(small / 4, rel=0.05)  # the pitch kept: a field twice as wide each way
    text = by_field.to_toml()
    assert "pixel_pitch_mm" not in text and load_scene_text(tmp_path, text) == by_field


def load_scene_text(tmp_path, text: str):
    from spacefit.scene.toml import load_scene

    (tmp_path / "scene.toml").write_text(text)
    return load_scene(tmp_path / "scene.toml")


def test_a_pitch_given_with_a_field_of_view_is_refused_and_one_set_later_replaces_the_other(tmp_path):
    """One table (a scene file's [camera], one with_values call, one set of overrides) gives the pitch
    or the field of view; one set later (with_values, --set over a file) replaces the other."""
    from spacefit.errors import InputError
    from spacefit.scene.toml import load_scene

    scene = load_case("panels").scene()
    with pytest.raises(InputError, match=r"`camera.pixel_pitch_mm` = 0.01 was given while `camera.fov_deg` = 10 sets"):
        scene.with_values({"camera.fov_deg": 10.0, "camera.pixel_pitch_mm": 0.01})
    with pytest.raises(InputError, match=r"`camera.fov_deg` must be in \[0, 179\] deg, got 200"):
        scene.with_values({"camera.fov_deg": 200.0})
    (tmp_path / "both.toml").write_text("[camera]\nfov_deg = 10.0\npixel_pitch_mm = 4.0\n")
    with pytest.raises(InputError, match="give one of them"):
        load_scene(tmp_path / "both.toml")
    by_field = scene.with_values({"camera.fov_deg": 10.0})
    assert by_field.camera.pixel_pitch_mm == pytest.approx(2 * 7000.0 * np.tan(np.radians(5.0)) / 128, rel=1e-12)
    assert by_field.with_values({"camera.pixel_pitch_mm": 0.01}).camera == scene.with_values({"camera.pixel_pitch_mm": 0.01}).camera
    panels = CASES_DIR / "panels.toml"  # its [camera] gives the pitch
    assert load_scene(panels, {"camera.fov_deg": 10.0}).camera == by_field.camera
    with pytest.raises(InputError, match="give one of them"):
        load_scene(panels, {"camera.fov_deg": 10.0, "camera.pixel_pitch_mm": 0.01})
    (tmp_path / "field.toml").write_text("[camera]\nfov_deg = 10.0\n")
    assert load_scene(tmp_path / "field.toml", {"camera.pixel_pitch_mm": 0.01}).camera.fov_deg == 0.0


def test_intrinsics_from_a_scene_are_its_camera_in_metres():
    scene = load_case("panels").scene().with_values({"camera.principal_offset_px": [2.0, -1.0]})
    intr = Intrinsics.from_scene(scene)
    assert intr == Intrinsics(7.0, 18.75e-3, 128, 128, (2.0, -1.0)) == assemble(scene).intrinsics
    with pytest.raises(TypeError, match="`scene` must be a spacefit Scene"):  # InputTypeError: an InputError and a TypeError
        Intrinsics.from_scene("scene.toml")
