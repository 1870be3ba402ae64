"""The frame conventions of thesis section 3.2, pinned by numbers worked out by hand.

Every scene elsewhere in the suite turns about one axis only (or poses its camera by look_at), so
an Euler product in the wrong order passed; here each attitude turns about all three axes and the
expected values come from the printed matrices, not from :mod:`spacefit.geometry.frames`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import small_scene, write_sphere_obj

from spacefit import render
from spacefit.fitting.params import free_parameters
from spacefit.geometry.frames import CameraFrame, Intrinsics, attitude_matrix, object_to_world, project
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.values import scene_values_fn
from spacefit.scene.assembly import assemble
from spacefit.scene.parameters import scene_value


def r1(a):
    return np.array([[1, 0, 0], [0, np.cos(a), np.sin(a)], [0, -np.sin(a), np.cos(a)]])


def r2(b):
    return np.array([[np.cos(b), 0, -np.sin(b)], [0, 1, 0], [np.sin(b), 0, np.cos(b)]])


def r3(c):
    return np.array([[np.cos(c), np.sin(c), 0], [-np.sin(c), np.cos(c), 0], [0, 0, 1]])


# Three non-zero angles, none a multiple of 90 deg, so every product order gives another matrix.
ANGLES = np.radians([20.0, -35.0, 110.0])


def test_attitude_matrix_is_r1_r2_r3_as_printed():
    a, b, c = ANGLES
    assert np.allclose(attitude_matrix(ANGLES), r1(a) @ r2(b) @ r3(c), atol=1e-12)
    # the reverse product is another matrix at these angles: the check above can tell the order
    assert not np.allclose(r3(c) @ r2(b) @ r1(a), r1(a) @ r2(b) @ r3(c), atol=1e-3)


def test_object_to_world_rotates_then_translates():
    a, b, c = ANGLES
    position = np.array([1.5, -2.0, 4.0])
    p_object = np.array([0.3, -0.2, 0.7])
    m = object_to_world(position, ANGLES)
    assert np.allclose(m @ np.append(p_object, 1.0), np.append(r1(a) @ r2(b) @ r3(c) @ p_object + position, 1.0))


# The hand-worked case: attitude (90, 180, 90) deg, with sines and cosines of 0 and +-1.
#   R1(90)  = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
#   R2(180) = [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]
#   R3(90)  = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]
#   R1 R2 = [[-1, 0, 0], [0, 0, -1], [0, -1, 0]];  R = R1 R2 R3 = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
# The camera's image right is R's first column (0, 0, 1), image up its second (-1, 0, 0), and it
# looks along minus the third, (0, 1, 0). (R3 R2 R1 = [[0, 0, 1], [1, 0, 0], [0, 1, 0]] would look
# along (-1, 0, 0).) A camera at (1, 2, 3) sees the point 10 m ahead, 0.2 m right and 0.1 m up,
# (1 - 0.1, 2 + 10, 3 + 0.2) = (0.9, 12, 3.2), at 1200 px focal length (60 mm / 0.05 mm) and
# principal point (80/2 + 5, 60/2 - 3) = (45, 27) in pixel
#   u = 45 + 1200 * 0.2 / 10 = 69,  v = 27 - 1200 * 0.1 / 10 = 15  (v runs down, so up is smaller v).
HAND = {
    "attitude_deg": [90.0, 180.0, 90.0],
    "position_m": [1.0, 2.0, 3.0],
    "point_m": [0.9, 12.0, 3.2],
    "pixel": [69.0, 15.0],
    "depth_m": 10.0,
}
CAMERA = {"focal_length_mm": 60.0, "pixel_pitch_mm": 0.05, "principal_offset_px": [5.0, -3.0]}


def test_camera_axes_of_a_three_axis_attitude():
    frame = CameraFrame.from_attitude(np.array(HAND["position_m"]), np.radians(HAND["attitude_deg"]))
    assert np.allclose(frame.right, [0, 0, 1], atol=1e-12)
    assert np.allclose(frame.up, [-1, 0, 0], atol=1e-12)
    assert np.allclose(frame.forward, [0, 1, 0], atol=1e-12)


def test_hand_computed_pixel_of_a_three_axis_attitude():
    frame = CameraFrame.from_attitude(np.array(HAND["position_m"]), np.radians(HAND["attitude_deg"]))
    intr = Intrinsics(60e-3, 0.05e-3, 80, 60, (5.0, -3.0))
    uv, depth = project(np.array([HAND["point_m"]]), frame, intr)
    assert np.allclose(uv[0], HAND["pixel"]) and depth[0] == pytest.approx(HAND["depth_m"])


def test_pixel_of_a_generic_attitude_from_the_printed_matrices():
    """At angles with no zero sines, through the literal matrices and the pinhole formula."""
    a, b, c = ANGLES
    r = r1(a) @ r2(b) @ r3(c)
    right, up, forward = r[:, 0], r[:, 1], -r[:, 2]
    position = np.array([0.5, -1.0, 2.0])
    point = position + 8.0 * forward + 0.3 * right - 0.25 * up
    f_px = 60e-3 / 0.05e-3
    expected = [40 + 5 + f_px * 0.3 / 8.0, 30 - 3 + f_px * 0.25 / 8.0]
    uv, depth = project(point[None], CameraFrame.from_attitude(position, ANGLES), Intrinsics(60e-3, 0.05e-3, 80, 60, (5.0, -3.0)))
    assert np.allclose(uv[0], expected) and depth[0] == pytest.approx(8.0)


@pytest.fixture(scope="module")
def hand_scene(tmp_path_factory):
    """The hand-worked camera from a scene file: degrees, millimetres and an attitude (no look_at),
    with a small white sphere at the hand-worked point, lit from the camera's side."""
    sphere = write_sphere_obj(tmp_path_factory.mktemp("conv") / "sphere.obj", radius=0.04, subdivisions=3)
    return small_scene(
        sphere,
        {"material": "white_paint", "kd": 1.0},
        render={"resolution": [80, 60], "spp": 64},
        camera={**CAMERA, "position_m": HAND["position_m"], "attitude_deg": HAND["attitude_deg"], "look_at_m": []},
        target={"position_m": HAND["point_m"]},
        sun={"direction": [0.0, 1.0, 0.0]},
    )


def test_scene_file_camera_projects_the_point_to_the_hand_computed_pixel(hand_scene):
    a = assemble(hand_scene)
    uv, depth = project(np.array([HAND["point_m"]]), a.camera, a.intrinsics)
    assert np.allclose(uv[0], HAND["pixel"]) and depth[0] == pytest.approx(HAND["depth_m"])


def test_render_centres_the_point_on_the_hand_computed_pixel(hand_scene):
    """Mitsuba's sensor (its look_at and principal point offset) agrees with the hand numbers."""
    img = render(hand_scene).sum(axis=-1)
    v, u = np.nonzero(img > 0)
    w = img[v, u]
    centroid = np.array([np.sum((u + 0.5) * w), np.sum((v + 0.5) * w)]) / w.sum()
    # the sphere is lit along the view direction, so its image is symmetric about the point's pixel
    assert np.allclose(centroid, HAND["pixel"], atol=0.25)


# The seeds' convention at the JAX / Dr.Jit seam: the primal image uses `seed`, derivative renders
# `seed_grad` only, so that a Jacobian's Monte Carlo noise does not correlate with the residual's.
@pytest.fixture(scope="module")
def rough_sphere(tmp_path_factory):
    """A rough conductor sphere 10 px across at 4 spp: its rim and highlight make derivative renders noisy."""
    sphere = write_sphere_obj(tmp_path_factory.mktemp("seeds") / "sphere.obj", radius=1.0, subdivisions=3)
    scene = small_scene(sphere, {"material": "panel_thesis", "alpha": 0.2}, render={"resolution": [16, 16], "spp": 4},
                        camera={"pixel_pitch_mm": 1.0}, sun={"direction": [0.3, 0.1, -1.0]})
    names = ["parts.sphere.alpha", "parts.sphere.eta"]
    return render_chain(scene, names, spp=4, spp_grad=4), jnp.array([scene_value(scene, n) for n in names])


def relative_difference(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_forward_derivative_renders_use_seed_grad_only(rough_sphere):
    chain, x0 = rough_sphere

    def jacobian(seed, seed_grad):
        return np.asarray(jax.jacfwd(chain.forward(seed, seed_grad))(x0))

    base = jacobian(1, 2)
    # float32 sums in another thread order differ by ~1e-7; other samples by far more (measured 0.15)
    assert relative_difference(jacobian(5, 2), base) < 1e-5
    assert relative_difference(jacobian(1, 3), base) > 0.02


def test_reverse_derivative_renders_use_seed_grad_only(rough_sphere):
    chain, x0 = rough_sphere
    weight = jnp.asarray(np.random.default_rng(8).uniform(size=chain.drjit.shape), dtype=jnp.float32)

    def gradient(seed, seed_grad):
        image = chain.reverse(seed, seed_grad)
        return np.asarray(jax.grad(lambda x: jnp.sum(weight * image(x)))(x0))

    base = gradient(1, 2)
    assert relative_difference(gradient(5, 2), base) < 1e-5
    assert relative_difference(gradient(1, 3), base) > 0.02


def test_free_sun_angles_give_back_the_scenes_light_direction(tmp_path):
    """Fitting the sun's angles: at the scene's own elevation and azimuth the light travels along the
    scene's ``sun.direction`` (away from the sun), as it does when the angles are fixed."""
    direction = np.array([0.3, -0.2, -1.0])
    scene = small_scene(write_sphere_obj(tmp_path / "sphere.obj", subdivisions=1), {"material": "white_paint"},
                        sun={"direction": direction.tolist()})
    free = free_parameters(scene, ["sun.elevation_deg", "sun.azimuth_deg"])
    x0 = jnp.array([scene_value(scene, n) for n in free.names])
    # towards the sun: -(0.3, -0.2, -1) / |.|, elevation asin(1 / 1.0630) = 70.17 deg, azimuth atan2(0.2, -0.3)
    assert np.asarray(x0) == pytest.approx([70.17, 146.31], abs=0.01)
    light = np.asarray(scene_values_fn(assemble(scene), free.names)(x0)["sun.to_world"])
    assert np.allclose(light, direction / np.linalg.norm(direction))
