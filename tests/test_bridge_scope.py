"""Forward-mode Jacobian columns under a stack-sampling profiler, and the AD state a failed render leaves.

A pass on dask died in a forward-mode column with Dr.Jit's "tried to forward-propagate derivatives
across edge a1 -> a252, which lies outside of the current dr.isolate_grad() scope", now and then.
dask's worker profiler samples the task thread's stack every 10 ms and holds the frames while it
reads them; a frame of Mitsuba PRB's first trace of its symbolic branch (``if depth >= 1``) held
past its return keeps that trace's AD variables, made from the vertex positions, alive, and Dr.Jit's
forward mode then follows the positions' edges to them. :class:`KeepFrames` holds such frames on
purpose (a profile hook instead of a sampling thread, on the thread where the bridge renders), so
that the failure happens every time.
"""

from __future__ import annotations

import sys

import jax
import numpy as np
import pytest

from spacefit.precision import float64
from spacefit.rendering.backend import dr, on_drjit_thread, variant_scope
from spacefit.rendering.derivatives import render_chain
from spacefit.scene.parameters import scene_value
from spacefit.scene.toml import load_scene

# 16 x 16 px of the wrinkles case (panels, legs and the wrinkled body in view), one bounce.
CASE = [
    "render.resolution=[16, 16]", "camera.pixel_pitch_mm=188.0", "camera.position_m=[3, -4, 10]", "camera.look_at_m=[0, 0, 0]",
    "sun.direction=[0.4, 0.3, -1]", "render.depth=1", "wrinkles.L=0.4", "wrinkles.Ls=0.1", "wrinkles.spacing_m=0.03",
    "wrinkles.D=2.4", "wrinkles.G=0.01",
]
# Every column from a forward-mode render: a material's, and the wrinkles' D (it moves vertices).
NAMES = ["parts.panels.alpha_x", "parts.legs.kd", "wrinkles.D"]


class KeepFrames:
    """A profile hook that keeps the frames of Mitsuba's PRB named ``functions`` as they return (at most
    ``limit``), as a sampling profiler holding them would: their locals outlive the call."""

    def __init__(self, functions: tuple[str, ...], limit: int) -> None:
        self.functions, self.limit, self.kept = functions, limit, []

    def __call__(self, frame, event, arg):
        if (event == "return" and len(self.kept) < self.limit and frame.f_code.co_name in self.functions
                and frame.f_code.co_filename.endswith("prb.py")):
            self.kept.append(frame)

    def __enter__(self) -> KeepFrames:
        on_drjit_thread(sys.setprofile)(self)  # on the thread where the bridge renders
        return self

    def __exit__(self, *exc: object) -> None:
        on_drjit_thread(sys.setprofile)(None)


@pytest.fixture(scope="module")
@float64
def case():
    scene = load_scene(None, CASE)
    chain = render_chain(scene, NAMES, spp=4, spp_grad=4, fd_steps=np.zeros(len(NAMES)))
    x = np.array([scene_value(scene, n) for n in NAMES])
    values = {k: np.asarray(v, np.float32).ravel() for k, v in chain.values_of(x).items()}
    tangents = {k: np.asarray(v, np.float32).reshape(-1, len(NAMES)) for k, v in jax.jacfwd(chain.values_of)(x).items()}
    columns = [{k: t[:, j] for k, t in tangents.items()} for j in range(len(NAMES))]
    return chain.drjit, values, columns


def grads_left(scene) -> list[str]:
    """The scene values still attached to Dr.Jit's AD graph."""
    with variant_scope(scene.variant):
        return [key for key in scene.params.keys() if dr.grad_enabled(scene.params[key])]


@pytest.mark.parametrize("j", [0, 1])
def test_a_material_column_is_the_same_with_prb_frames_held(case, j):
    """Every PRB frame kept alive (its first trace's variables too): the column is the one rendered
    undisturbed, bit for bit (main raised the isolation-scope error here, every time)."""
    scene, values, columns = case
    plain = scene.forward(values, columns[j], 5)
    assert np.any(plain != 0)
    with KeepFrames(("sample", "_loop_body", "_loop_cond", "_if_stmt_true", "_if_stmt_false"), limit=10**6) as keep:
        held = scene.forward(values, columns[j], 5)
    assert "_if_stmt_true" in {f.f_code.co_name for f in keep.kept}  # the frames that broke it are among those held
    np.testing.assert_array_equal(held, plain)
    assert grads_left(scene) == []


def test_a_vertex_column_is_rendered_again_when_a_sample_held_its_branch(case, monkeypatch):
    """The wrinkles' D moves vertices, so its render attaches them: one held frame of PRB's branch
    (one unlucky profiler sample) makes the first render fail; the second gives the undisturbed column."""
    scene, values, columns = case
    plain = scene.forward(values, columns[2], 5)
    assert np.any(plain != 0)
    renders, render = [], scene._render_forward
    monkeypatch.setattr(scene, "_render_forward", lambda seed_grad, states: renders.append(seed_grad) or render(seed_grad, states))
    with KeepFrames(("_if_stmt_true",), limit=1) as keep:
        held = scene.forward(values, columns[2], 5)
    assert len(keep.kept) == 1 and renders == [5, 5]  # the first render met the held frame's variables
    np.testing.assert_array_equal(held, plain)
    assert grads_left(scene) == []


def test_a_tangent_that_moves_nothing_gives_a_zero_column_without_a_render(case, monkeypatch):
    scene, values, _ = case
    monkeypatch.setattr(scene, "_render_forward", lambda *args: pytest.fail("rendered"))
    out = scene.forward(values, {k: np.zeros_like(v) for k, v in values.items()}, 5)
    np.testing.assert_array_equal(out, np.zeros(scene.shape, np.float32))
    assert grads_left(scene) == []


def test_other_render_errors_are_not_repeated_and_leave_the_values_detached(case, monkeypatch):
    """A render that raises something else is not tried again; forward and backward leave no value
    attached to the AD graph behind them (main left every value attached)."""
    scene, values, columns = case
    calls = []

    def broken(seed_grad, *states):
        calls.append(seed_grad)
        raise RuntimeError("the render failed")

    monkeypatch.setattr(scene, "_render_forward", broken)
    monkeypatch.setattr(scene, "_render_ad", broken)
    with pytest.raises(RuntimeError, match="the render failed"):
        scene.forward(values, columns[2], 5)
    assert calls == [5]
    assert grads_left(scene) == []
    with pytest.raises(RuntimeError, match="the render failed"):
        scene.backward(values, np.ones(scene.shape, np.float32), 5)
    assert grads_left(scene) == []
