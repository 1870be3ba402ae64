"""Frozen renders (spacefit.rendering.frozen): a replayed pass equals a freshly traced one bit for bit,
whatever it cannot replay (sample count, differentiated set, moved vertices, another film) is traced
anew, the derivative render traced on every thread equals the one-thread render, and a render that
kernel_log counts records and replays as one it does not."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from spacefit.rendering.backend import dr, mi, on_drjit_thread, variant_scope
from spacefit.rendering.derivatives import render_chain
from spacefit.rendering.drjit_values import to_value
from spacefit.rendering.frozen import FrozenPasses
from spacefit.rendering.logs import errors_only, kernel_log
from spacefit.rendering.renderer import Renderer
from spacefit.rendering.sample_passes import render_threads
from spacefit.scene.parameters import scene_value
from spacefit.scene.toml import load_scene

# 48 x 48 px of the default lander, direct light; 32 spp is two multijitter passes (30 + 2).
CASE = ["render.resolution=[48, 48]", "camera.pixel_pitch_mm=80.0", "render.depth=1", "render.spp=32"]
MATERIALS = ["parts.panels.alpha_x", "parts.legs.kd"]


@pytest.fixture(scope="module")
def scene():
    return load_scene(None, CASE)


def unfrozen(scene, names, **kwargs):
    """A chain whose every pass is traced (no recording, no replay): the reference."""
    chain = render_chain(scene, names, **kwargs)
    chain.renderer.frozen = FrozenPasses(enabled=False)
    return chain


def values(chain, x):
    """The Mitsuba values (traverse key -> array) of the chain's parameters at ``x``."""
    return {k: np.asarray(v) for k, v in chain.values_of(jnp.asarray(x, dtype=jnp.float32)).items()}


def column(chain, vals, key, seed_grad):
    """The forward-mode derivative image along ``key`` (unit tangent)."""
    return chain.drjit.forward(vals, {key: np.ones_like(vals[key])}, seed_grad)


def test_replay_equals_fresh_render(scene):
    chain = render_chain(scene, MATERIALS)
    x0 = np.array([scene_value(scene, n) for n in MATERIALS])
    key = next(iter(values(chain, x0)))
    for x in (x0, 1.1 * x0):  # the first call runs unfrozen, the second records
        chain.drjit.render_primal(values(chain, x), 3)
        column(chain, values(chain, x), key, 4)
    recorded = chain.renderer.frozen.recordings
    assert recorded > 0
    x = np.array([0.5, 1.5]) * x0
    replayed = chain.drjit.render_primal(values(chain, x), 5), column(chain, values(chain, x), key, 6)
    assert chain.renderer.frozen.recordings == recorded  # replayed, not traced
    fresh = unfrozen(scene, MATERIALS)
    expected = fresh.drjit.render_primal(values(fresh, x), 5), column(fresh, values(fresh, x), key, 6)
    for got, want in zip(replayed, expected):
        assert np.any(want != 0)
        np.testing.assert_array_equal(got, want)
    assert not np.array_equal(replayed[0], chain.drjit.render_primal(values(chain, x0), 5))  # the new values were used


def test_what_cannot_be_replayed_is_traced_anew(scene):
    chain = render_chain(scene, MATERIALS)
    renderer = chain.renderer
    x0 = np.array([scene_value(scene, n) for n in MATERIALS])
    keys = list(values(chain, x0))
    with variant_scope(renderer.variant):
        for _ in range(2):
            chain.drjit.render_primal(values(chain, x0), 3)
            column(chain, values(chain, x0), keys[0], 4)
        recorded = renderer.frozen.recordings
        other_spp = renderer.radiance(16, 3)  # another sample count: a recording of its own
        assert renderer.frozen.recordings > recorded
        other_key = column(chain, values(chain, x0), keys[-1], 4)  # another differentiated set
        assert renderer.frozen.recordings > recorded + 1
        fresh = unfrozen(scene, MATERIALS)
        with variant_scope(fresh.renderer.variant):
            fresh.drjit.render_primal(values(fresh, x0), 3)  # sets the same values, unfrozen
            np.testing.assert_array_equal(other_spp, fresh.renderer.radiance(16, 3))
        np.testing.assert_array_equal(other_key, column(fresh, values(fresh, x0), keys[-1], 4))
    recorded = renderer.frozen.recordings
    small = render_chain(load_scene(None, [*CASE[1:], "render.resolution=[40, 40]"]), MATERIALS)  # another film: recordings of its own
    got = [small.drjit.render_primal(values(small, x0), 3) for _ in range(3)]  # unfrozen, recorded, replayed
    assert small.renderer.frozen.recordings > 0 and renderer.frozen.recordings == recorded
    small.renderer.frozen = FrozenPasses(enabled=False)
    want = small.drjit.render_primal(values(small, x0), 3)
    assert want.shape == (40, 40, 3) and np.any(want != 0)
    for image in got:
        np.testing.assert_array_equal(image, want)


def test_moved_vertices_are_never_replayed(scene):
    """A recording holds the acceleration structure: after the pose turns the target, a replay traced
    the old one (half the light at 2 deg). The pose differentiated by forward-mode AD moves the vertices
    (a pose by finite differences moves the camera and the sun instead: test_pose_by_view.py)."""
    names, ad = ["target.attitude_x_deg"], {"fd_steps": np.zeros(1)}
    chain = render_chain(scene, names, **ad)
    x0 = scene_value(scene, names[0])
    turns = (0.0, 0.0, 2.0, 4.0)
    got = [chain.drjit.render_primal(values(chain, [x0 + dx]), 3) for dx in turns]
    assert chain.renderer.geometry == len(turns)
    fresh = unfrozen(scene, names, **ad)
    for image, dx in zip(got, turns):
        np.testing.assert_array_equal(image, fresh.drjit.render_primal(values(fresh, [x0 + dx]), 3))


@pytest.mark.slow  # 23 s: the slow set (test_render keeps the primal's)
def test_derivative_render_on_every_thread_equals_one_thread(scene):
    """Traced on all threads and splatted on one, the forward-mode render is Mitsuba's own
    (``mi.render`` and ``dr.forward_to``) wholly on one thread, bit for bit."""
    if dr.thread_count() < 2:
        pytest.skip("one Dr.Jit thread: nothing to compare")
    chain = render_chain(scene, MATERIALS)
    ds = chain.drjit
    x0 = np.array([scene_value(scene, n) for n in MATERIALS])
    vals = values(chain, x0)
    for key in vals:
        tangent = {key: np.full_like(vals[key], 0.7)}
        threads = [ds.forward(vals, tangent, 9) for _ in range(2)]  # unfrozen, then recorded
        with variant_scope(ds.variant):
            ds.renderer.set_params(vals, grad=tangent)
            try:
                dr.set_grad(ds.params[key], to_value(ds.params[key], tangent[key]))
                with render_threads(True), errors_only():
                    image = sum(mi.render(ds.renderer.scene, ds.params, integrator=ds._integrator, seed=s + 1, seed_grad=s, spp=count)
                                * weight for s, count, weight in ds._passes(ds.spp_grad, 9))
                    dr.forward_to(image)
                    one = ds.renderer.to_film(np.asarray(dr.grad(image), dtype=np.float32))
            finally:
                ds.renderer.set_params(vals)
        assert np.any(one != 0)
        for image in threads:
            np.testing.assert_array_equal(image, one)



def test_kernel_log_counts_the_drjit_threads_kernels_and_leaves_the_recordings_as_they_are():
    """A render on the process's Dr.Jit thread inside kernel_log is counted, the kernels its pass
    compiles as it records among them, and a frozen pass records and replays inside the block as
    outside it, on either thread (Dr.Jit keys a recording on the calling thread's flags, the kernel
    history's among them: switched on, a render on this thread recorded its pass again)."""
    scene = load_scene(None, ["render.resolution=[32, 32]", "camera.pixel_pitch_mm=75.0", "render.depth=1", "render.spp=4"])
    with variant_scope(scene.render.variant):
        renderer = Renderer(scene)
        on_thread = on_drjit_thread(renderer.render)
        on_thread(seed=1)  # a new geometry's first render: traced, not recorded
        with kernel_log() as recording:
            first = on_thread(seed=2)  # records its pass
        on_thread(seed=3)  # records it again, the seed opaque
        recordings = renderer.frozen.recordings
        with kernel_log() as replay:
            on_thread(seed=4)
        with kernel_log():
            here = renderer.render(seed=2)
        on_thread(seed=5)
    assert renderer.frozen.recordings == recordings
    assert np.array_equal(here, first)
    assert recording["generated"] > replay["generated"] > 0 and recording["compile_s"] > 0


def test_a_jacobians_columns_share_one_primal_pass_and_are_each_columns_own_render(scene, monkeypatch):
    """The forward-mode columns of one call (``forward_columns``) replay one primal pass per pass of the render (two
    here: 30 + 2 multijitter samples), not one per column, and each is the column rendered alone, bit for bit; a
    column whose tangent moves nothing renders nothing."""
    from spacefit.rendering import frozen

    chain = render_chain(scene, MATERIALS)
    vals = values(chain, np.array([scene_value(scene, n) for n in MATERIALS]))
    tangents = [{key: np.full_like(vals[key], 0.7)} for key in vals] + [{key: np.zeros_like(v) for key, v in vals.items()}]
    alone = [chain.drjit.forward(vals, tangent, 9) for tangent in tangents]
    states = []
    primal_state = frozen.primal_state
    monkeypatch.setattr(frozen, "primal_state", lambda *args: states.append(args) or primal_state(*args))
    chain.renderer.frozen = FrozenPasses(enabled=False)  # every pass traced in Python: each primal pass counted
    shared = chain.drjit.forward_columns(vals, tangents, 9)
    assert len(states) == 2 and len(tangents) == 3
    assert np.any(shared[0] != 0) and np.any(shared[1] != 0) and not np.any(shared[2])
    for a, b in zip(shared, alone, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_new_seed_is_replayed_not_recorded_again(scene):
    """The seed is an operand of every pass from its first recording (opaque): a render with another seed replays it. A
    seed passed as a literal was baked into the first recording, and the next seed recorded each pass again (Dr.Jit's
    ``auto_opaque``): 7 of the 8-parameter fit's 18 recordings."""
    chain = render_chain(scene, MATERIALS)
    vals = values(chain, np.array([scene_value(scene, n) for n in MATERIALS]))
    key = next(iter(vals))
    chain.drjit.render_primal(vals, 3)  # the first call runs unfrozen; each pass's next call records
    chain.drjit.render_primal(vals, 5)
    column(chain, vals, key, 6)
    recorded = chain.renderer.frozen.recordings
    for seed in (7, 9):
        chain.drjit.render_primal(vals, seed)
        column(chain, vals, key, seed + 1)
    assert chain.renderer.frozen.recordings == recorded
