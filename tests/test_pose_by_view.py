"""A rigid pose of the target rendered by moving the camera and the sun the other way
(spacefit.rendering.values.pose_by_view): the image and the material columns of the vertices moved, to
float32 round-off but for samples that graze an edge; a fit's renders, a pass's frames of other poses
among them, replay after the first; and what the swap cannot serve (the wrinkles, a pose
differentiated by AD, a renderer's set_values) still moves the vertices."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import spacefit as sf
from spacefit.fitting.frames import FrameSpec, Loaded, frame_jacobian, frame_primal
from spacefit.precision import float64
from spacefit.rendering.backend import variant_scope
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.frozen import FrozenPasses
from spacefit.rendering.values import pose_by_view
from spacefit.scene.parameters import fd_step, scene_value

# The fit's panels case at 48 x 48 px (the 128 px field of view), 32 spp.
BASE = {"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50.0, "render.spp": 32}
MATERIALS = ["parts.panels.alpha_x", "parts.legs.kd"]
POSE = ["target.attitude_x_deg", "target.attitude_z_deg", "target.position_x_m", "target.position_y_m"]
# Pose changes: 2 deg about each axis, 0.3 m along each, and all at once.
MOVES = [(2, 0, 0, 0), (-2, 0, 0, 0), (0, 2, 0, 0), (0, 0, 0.3, 0), (0, 0, 0, -0.3), (1.5, -2, 0.2, 0.1)]
# The two renders' samples are the same rays in two frames, rounded to float32 apart (about 1e-6 m at 25 m):
# a pixel differs by more than round-off only where a sample grazes an edge and hits on one side only.
ROUND_OFF = 1e-5
EDGE_PIXELS = 0.01


@pytest.fixture(scope="module")
def scene():
    return sf.load_scene("spacefit/synthetic/panels.toml", BASE)


def vertex_chain(scene, names):
    """A chain whose pose moves the vertices (its columns forward-mode AD, which the swap cannot serve),
    every pass traced: the reference."""
    chain = render_chain(scene, names, fd_steps=np.zeros(len(names)))
    chain.renderer.frozen = FrozenPasses(enabled=False)
    return chain


@float64
def values(chain, x):
    """The Mitsuba values of the chain's parameters at ``x``, in float64 as a fit makes them."""
    return {k: np.asarray(v) for k, v in chain.values_of(jnp.asarray(x, dtype=jnp.float64)).items()}


def column(chain, vals, key):
    """The forward-mode derivative image along ``key`` (unit tangent)."""
    return chain.drjit.forward(vals, {key: np.ones_like(vals[key])}, 4)


def assert_same_picture(got, want):
    """Equal to float32 round-off but in at most :data:`EDGE_PIXELS` of the target's pixels."""
    top = np.abs(want).max()
    assert top > 0
    off = np.any(np.abs(got - want) > ROUND_OFF * top, axis=-1)
    assert off.sum() <= EDGE_PIXELS * np.any(want != 0, axis=-1).sum()
    assert abs(got.sum() - want.sum()) <= 1e-3 * np.abs(want).sum()


def test_a_rigid_pose_moves_the_camera_and_the_sun_and_renders_the_moved_vertices_picture(scene):
    names = [*MATERIALS, *POSE]
    chain = render_chain(scene, names)
    x0 = np.array([scene_value(scene, n) for n in names])
    set_by_view = values(chain, x0)
    assert not any(k.endswith("vertex_positions") for k in set_by_view)
    assert {"sensor.to_world", "sun.to_world"} <= set(set_by_view)
    material = next(k for k in set_by_view if k.startswith("panels.bsdf"))
    points = [x0 + np.r_[np.zeros(len(MATERIALS)), move] for move in [(0, 0, 0, 0), *MOVES]]
    renderer, got = chain.renderer, []
    for x in points:
        got.append((chain.drjit.render_primal(values(chain, x), 3), column(chain, values(chain, x), material)))
    # the vertices never moved: no rebuild of the acceleration structure, which would drop the recordings (that the
    # later renders replay is the fit's test below: counted here, another test module's scenes left alive in this
    # worker had Dr.Jit record one pass again, mitsuba3#1700)
    assert renderer.geometry == 0
    with variant_scope(renderer.variant):  # the picture is the same only under a light that turns with the frame
        assert [e.class_name() for e in renderer.scene.emitters()] == ["DirectionalEmitter"]
    # after: the reference's moved vertices, another loaded scene's, would have the chain's passes recorded again
    reference = vertex_chain(scene, names)
    for x, (image, derivative) in zip(points, got):
        want = values(reference, x)
        assert_same_picture(image, reference.drjit.render_primal(want, 3))
        assert_same_picture(derivative, column(reference, want, material))


def fit_frames(scenes, names):
    return [FrameSpec(s, tuple(names), tuple(fd_step(s, n) for n in names), 16, 16, "prb", shared_view=len(scenes) > 1)
            for s in scenes]


def test_a_pose_free_fit_s_renders_replay_after_the_first(scene):
    """A fit's Jacobians (materials by forward-mode AD, the attitude by finite differences) and primals at
    new points: none rebuilds the scene's acceleration structure, none records after the first of its kind."""
    names = [*MATERIALS, "target.attitude_x_deg", "target.attitude_z_deg"]
    spec = fit_frames([scene], names)[0]
    loaded = Loaded()
    x0 = np.array([scene_value(scene, n) for n in names])
    points = [x0 + d for d in np.linspace(0.0, 1.0, 4)[:, None] * [0.02, 0.05, 0.7, -0.4]]
    for x in points[:2]:  # the first of each kind runs unfrozen, the next record
        frame_jacobian(spec, spec.key, x, 3, 4, loaded)
        frame_primal(spec, spec.key, x, 5, loaded)
    renderer = loaded.chain(spec, spec.key).renderer
    recorded = renderer.frozen.recordings
    for x in points[2:]:
        frame_jacobian(spec, spec.key, x, 3, 4, loaded)
        frame_primal(spec, spec.key, x, 5, loaded)
    assert renderer.geometry == 0 and renderer.frozen.recordings == recorded > 0


def test_a_pass_s_frames_of_other_poses_take_their_camera_and_sun_from_their_view(scene):
    """Three frames (own camera, sun and attitude) on one scene loaded at the first frame's pose: each
    frame's image and material column are those of its own vertices moved."""
    frames = sf.arc_pass(3)
    scenes = [scene.with_values({**f, "target.attitude_deg": [a, 0.0, 0.0]}) for f, a in zip(frames, (0.0, 3.0, -2.0))]
    names = ["parts.legs.kd", "target.attitude_z_deg"]
    by_view, moved = fit_frames(scenes, names), [FrameSpec(s, tuple(names), (0.0, 0.0), 16, 16, "prb", shared_view=True) for s in scenes]
    x = np.array([0.4, 1.0])
    shared, reference = Loaded(), Loaded()
    for a, b in zip(by_view, moved):
        (image, J), (want, J_want) = frame_jacobian(a, a.key, x, 3, 4, shared), frame_jacobian(b, b.key, x, 3, 4, reference)
        assert_same_picture(image, want)
        assert_same_picture(J[..., 0], J_want[..., 0])
    assert len(shared.stages) == 1 and loaded_geometry(shared) == 0


def loaded_geometry(loaded):
    (stage,) = loaded.stages.values()
    return stage.chain.renderer.geometry


def test_what_the_view_cannot_serve_moves_the_vertices(scene):
    """The wrinkles free (they move the vertices anyway), the pose's column by forward-mode AD (which follows
    the vertices, not a frame), a renderer's set_values (its earlier roll and sun stay set)."""
    assert pose_by_view(POSE, ()) and not pose_by_view(MATERIALS, ())
    assert not pose_by_view(["wrinkles.D", *POSE], ())
    assert not pose_by_view(POSE, POSE[:1])
    chain = render_chain(scene, POSE[:1], fd_steps=np.zeros(1))
    assert "panels.vertex_positions" in values(chain, [1.0]) and "sensor.to_world" not in values(chain, [1.0])
    renderer = sf.Renderer(scene, crop=False)
    renderer.set_values({"target.attitude_x_deg": 1.0})
    assert renderer.geometry == 1
