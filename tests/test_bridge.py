"""The JAX / Dr.Jit seam: bijections, Jacobian columns against finite differences, reverse mode."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from spacefit.errors import InputError
from spacefit.fitting.params import bijection, free_parameters
from spacefit.rendering.derivatives import render_chain
from spacefit.scene.parameters import PARAMETERS, scene_value
from spacefit.scene.toml import load_scene

# 32 x 32 px of the wrinkles case: panels, legs and the wrinkled body all in view, direct light.
CASE = [
    "render.resolution=[32, 32]", "camera.pixel_pitch_mm=94.0", "camera.position_m=[3, -4, 10]",
    "camera.look_at_m=[0, 0, 0]", "target.attitude_deg=[0, 0, 0]", "sun.direction=[0.4, 0.3, -1]",
    "render.depth=1", "wrinkles.L=0.4", "wrinkles.Ls=0.1", "wrinkles.spacing_m=0.03",
    "wrinkles.D=2.4", "wrinkles.G=0.04",
]
NAMES = [
    "parts.panels.alpha_x", "parts.panels.alpha_y", "parts.panels.eta", "parts.panels.k", "parts.legs.kd",
    "sun.irradiance_w_m2", "parts.body.alpha", "wrinkles.D", "wrinkles.rms_m", "sun.elevation_deg", "sun.azimuth_deg",
    "target.attitude_x_deg", "target.position_y_m",
]


@pytest.fixture(autouse=True)
def x64():
    """The bridge is used as the fit uses it, in JAX's 64-bit mode (scoped, as spacefit scopes it)."""
    with jax.enable_x64(True):
        yield


@pytest.mark.parametrize("name", sorted(PARAMETERS))
def test_bijection_round_trip(name):
    b = bijection(name)
    u = jnp.linspace(-8.0, 8.0, 33)
    x = b.forward(u)
    assert jnp.all((x > b.lo) & (x < b.hi))
    assert jnp.allclose(b.inverse(x), u, atol=1e-9)
    assert jnp.allclose(jax.vmap(jax.grad(b.forward))(u) * jax.vmap(jax.grad(b.inverse))(x), 1.0)


@pytest.fixture(scope="module")
def case():
    scene = load_scene(None, CASE)
    assert scene.render.sampler == "multijitter"  # the default sampler's derivatives are what these tests check
    free = free_parameters(scene, NAMES)
    chain = render_chain(scene, NAMES, spp=1024, spp_grad=1024)
    assert chain.renderer.window[2:] == (32, 32)  # D, G and the pose move vertices: the whole film
    np.testing.assert_array_equal(chain.fd_steps, free.fd_steps)
    return free, chain, jnp.array([scene_value(scene, n) for n in NAMES])


def cosine(a, b):
    a, b = np.ravel(a), np.ravel(b)
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_jacobian_columns_match_finite_differences(case):
    """AD columns (BSDF, sun irradiance) and finite-difference columns (D, rms height, sun angles) against central
    differences with common random numbers, at another step (1 % for AD columns, twice the
    column's own step for finite-difference columns)."""
    free, chain, x0 = case
    J = np.asarray(jax.jacfwd(chain.forward(seed=1, seed_grad=2))(x0))
    assert J.shape == (32, 32, 3, len(NAMES))
    for j, name in enumerate(NAMES):
        step = 2 * free.fd_steps[j] if free.fd_steps[j] > 0 else 1e-2 * float(x0[j])
        e = np.zeros(len(NAMES))
        e[j] = step
        fd = (chain.primal(x0 + e, 1) - chain.primal(x0 - e, 1)) / (2 * step)
        assert cosine(J[..., j], fd) >= 0.98, name
        assert np.linalg.norm(J[..., j]) == pytest.approx(np.linalg.norm(fd), rel=0.1), name


def test_reverse_mode_gradient_equals_forward_jacobian_gradient(case):
    _, chain, x0 = case
    bsdf = slice(0, 7)  # reverse mode carries AD derivatives only
    chain = render_chain(chain.renderer.assembly, NAMES[bsdf], spp=1024, spp_grad=1024)
    target = jnp.asarray(chain.primal(x0[bsdf], 9))
    forward, reverse = chain.forward(seed=1, seed_grad=2), chain.reverse(seed=1, seed_grad=2)
    g_fwd = jax.grad(lambda x: jnp.sum((forward(x) - target) ** 2))(x0[bsdf])
    g_rev = jax.grad(lambda x: jnp.sum((reverse(x) - target) ** 2))(x0[bsdf])
    assert np.allclose(g_rev, g_fwd, rtol=1e-3, atol=1e-6 * float(jnp.max(jnp.abs(g_fwd))))


def test_same_seed_same_render(case):
    _, chain, x0 = case
    assert np.array_equal(chain.primal(x0, 3), chain.primal(x0, 3))


@pytest.mark.parametrize(
    ("names", "message"),
    [
        (["parts.panels.alpha_z"], "alpha_x"),
        (["parts.legs.alpha_x"], "free"),
        (["parts.body.alpha", "parts.body.alpha_x"], "same scene value"),
        (["wrinkles.G", "wrinkles.rms_m"], "same scene value"),
        (["wrinkles.D", "wrinkles.D"], "twice"),
        ([], "at least one"),
    ],
)
def test_bad_free_names(names, message):
    with pytest.raises(InputError, match=message):
        free_parameters(load_scene(None, CASE), names)


def test_start_outside_range_is_refused():
    free = free_parameters(load_scene(None, CASE), ["wrinkles.D", "parts.legs.kd"])
    with pytest.raises(InputError, match=r"wrinkles\.D.*\(2, 3\)"):
        free.check_start([3.0, 0.5])
    with pytest.raises(InputError, match=r"parts\.legs\.kd"):
        free.check_start([2.5, 1.0])
