"""A loaded scene's renders recorded once and replayed: Dr.Jit's ``@dr.freeze`` over each pass's samples.

Tracing a render in Python (the sampler, the camera's rays, the integrator's loop: hundreds of Dr.Jit
operations) cost about as much as its kernels took to run on a small film: 8 ms of a 25 ms primal
render and 30 ms of an 85 ms forward-mode derivative render at 128 x 128 px, 32 spp
(docs/measurements/performance.md). :class:`FrozenPasses` records the first call of each kind of pass and, for new
scene values, seeds and tangents, launches the recorded kernels again without tracing.

What a pass's samples are a function of:

- the scene's Dr.Jit variables (BSDF values, vertex positions, the sun's and the camera's frames) and,
  in a derivative pass, the gradients set on them: inputs of the recording, replayed with their new
  values. A value that was a literal at the first call is baked into its kernel; when it changes,
  Dr.Jit records again with it opaque (``auto_opaque``), so it is never replayed stale.
- the seed: an opaque ``mi.UInt32`` operand, replayed (made as a literal, a derivative render's passes recorded again,
  opaque, at their second seed: 7 of the 8-parameter fit's 18 recordings; the camera's pass replays either way).
- the sample count, the pixel range and the set of values differentiated (their AD status): each a
  key of its own recording (Python integers are compared, AD status is part of Dr.Jit's key), made at
  its first call and replayed at the next with the same key.
- the film (resolution, window) and the integrator: fixed for a loaded scene; each
  :class:`FrozenPasses` belongs to one loaded scene, so a new film or integrator is a new object with
  recordings of its own.
- the scene's ray-tracing acceleration structure: not an operand; rebuilt when vertices move, which
  drops the recordings (:meth:`FrozenPasses.functions`). A rigid pose of the target moves the camera and
  the sun instead where a chain can (:func:`~spacefit.rendering.values.pose_by_view`): its renders replay.

Only the samples are frozen: each sample's value is computed on all of Dr.Jit's threads, the same
whichever thread computes it, and its splatting into the film, where neighbours' samples add into
the same pixels, is left to the caller, on one thread when the render is deterministic
(:func:`~spacefit.rendering.sample_passes.render_threads`: Dr.Jit does not record a change of its
thread count, so a frozen splat could not be made to run on one).

Dr.Jit also keys a recording on the calling thread's flags, the kernel history's among them
(:func:`~spacefit.rendering.logs.kernel_log` switches it on): a pass is called with the history off,
so that a render counted records and replays as one not counted, and records with the history as its
caller had it, its samples evaluated inside, so that the kernels compiled for it are counted.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

from spacefit.rendering.backend import dr, mi

# Distinct keys a loaded scene records before Dr.Jit warns: a fit's passes (at most a few sample counts
# and pixel ranges) times its differentiated sets (one per forward-mode column); more means a caller
# keeps changing a Python value it should pass as a Dr.Jit one.
WARN_AFTER = 64
# The kernel history's flag of the thread that called a frozen pass, which it records with.
_caller = threading.local()


def camera_samples(scene: "mi.Scene", pixels: "mi.UInt32", seed: "mi.UInt32", spp: int, start: int, count: int,
                   width: int) -> tuple["mi.Vector2f", "mi.Color3f"]:
    """Film positions (px) and radiance times the camera's importance weight (W m^-2 sr^-1) of ``spp``
    samples in each of the traced pixels ``start`` to ``start + count`` of ``pixels`` (indices into the
    film window of ``width`` px), as Mitsuba's own render loop traces them (positions uniform in each
    pixel, or stratified by the sampler), with the scene's integrator."""
    sensor = scene.sensors()[0]
    film, sampler = sensor.film(), sensor.sampler().clone()
    sampler.set_sample_count(spp)
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, count * spp)
    # sample k of the wavefront belongs to traced pixel k // spp, as in Mitsuba's loop (the samplers stratify by it)
    index = dr.gather(mi.UInt32, pixels, start + dr.arange(mi.UInt32, count * spp) // spp)
    offset = mi.ScalarVector2f(film.crop_offset())
    position = mi.Vector2f(mi.Float(index % width), mi.Float(index // width)) + offset + sampler.next_2d()
    ray, weight = sensor.sample_ray_differential(sensor.shutter_open(), 0.0, (position - offset) / mi.ScalarVector2f(film.crop_size()),
                                                 mi.Point2f(0.5))
    radiance, _, _ = scene.integrator().sample(scene, sampler, ray)
    return position, radiance * weight


def _wavefront(scene: "mi.Scene", integrator: "mi.SamplingIntegrator", seed: "mi.UInt32",
               spp: int) -> tuple["mi.Sampler", dict, "mi.Spectrum", "mi.Point2f"]:
    """``spp`` samples in every pixel of the film window as Mitsuba's ``RBIntegrator.render_forward`` starts them
    (Mitsuba 3.9, ``python/ad/integrators/common.py``): the sampler after the camera's rays, the keywords of the
    integrator's passes, the camera's weights and the film positions (px). The same for the same seed."""
    sensor = scene.sensors()[0]
    sampler, spp = integrator.prepare(sensor, seed, spp, integrator.aov_names())
    ray, weight, position = integrator.sample_rays(scene, sensor, sampler)
    return sampler, {"scene": scene, "ray": ray, "depth": mi.UInt32(0), "δL": None, "active": mi.Bool(True)}, weight, position


def primal_state(scene: "mi.Scene", integrator: "mi.SamplingIntegrator", seed: "mi.UInt32", spp: int) -> tuple[object]:
    """The primal pass of ``render_forward`` (its samples as :func:`_wavefront` starts them), as the one-tuple of its
    state, which the forward pass replays from (PRB's radiance; Vicini et al. 2021, "Path replay backpropagation"):
    computed with the gradients suspended, so the same whatever gradients are set, and a Jacobian's columns share one
    (:meth:`~spacefit.rendering.drjit_scene.DrJitScene.forward_columns`)."""
    with dr.suspend_grad():
        sampler, common, _, _ = _wavefront(scene, integrator, seed, spp)
        _, _, _, state = integrator.sample(mode=dr.ADMode.Primal, sampler=sampler, state_in=None, **common)
        return (state,)


def derivative_samples(scene: "mi.Scene", integrator: "mi.SamplingIntegrator", seed: "mi.UInt32", spp: int,
                       state: object) -> tuple["mi.Point2f", "mi.Color3f"]:
    """Film positions (px) and forward-mode derivatives of radiance times the camera's weight of ``spp``
    samples in every pixel of the film window, along the gradients set on the scene's values: the forward pass of
    ``render_forward`` from ``state``, its primal pass's (:func:`primal_state` of the same seed and count), before
    the samples are splatted. ``render_forward`` runs the primal pass on a clone of the sampler after the rays and
    the forward pass on the sampler: both from the state :func:`_wavefront` leaves, as here."""
    with dr.suspend_grad():
        sampler, common, weight, position = _wavefront(scene, integrator, seed, spp)
        derivative, _, _, _ = integrator.sample(mode=dr.ADMode.Forward, sampler=sampler, state_in=state, δaovs=None, **common)
        return position, derivative * weight


def _recorded(samples: Callable[..., tuple]) -> Callable[..., tuple]:
    """``samples`` as a pass records it: with its caller's kernel history flag, its samples evaluated."""

    @functools.wraps(samples)
    def record(*args: object) -> tuple:
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, getattr(_caller, "history", False)):
            out = samples(*args)
            dr.eval(out)
            return out

    return record


def _history_off(frozen: Callable[..., tuple]) -> Callable[..., tuple]:
    """``frozen`` called with the kernel history off, its caller's flag kept for :func:`_recorded`."""

    def call(*args: object) -> tuple:
        _caller.history = bool(dr.flag(dr.JitFlag.KernelHistory))
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, False):
            return frozen(*args)

    return call


class FrozenPasses:
    """One loaded scene's frozen passes: :func:`camera_samples`, :func:`primal_state` and :func:`derivative_samples`,
    each recorded per key and replayed after (see the module's notes), for one geometry at a time.

    A recording holds the scene's ray-tracing acceleration structure as it was: after vertices move
    (the pose, W-M wrinkles), which rebuilds it, a replay traced the old one (an image of half the
    light at 2 deg of attitude). :meth:`functions` is therefore asked with the scene's geometry
    (:attr:`~spacefit.rendering.renderer.Renderer.geometry`, counted up at each rebuild): a new one drops
    the recordings, and its first render runs unfrozen (a fit that moves vertices at every render, its
    wrinkles free, renders as before: a recording costs about a trace), its later ones record and replay.
    """

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled  # False: every pass traced, as with no freezing (a reference for tests)
        self.geometry: int | None = None
        self._drop()

    def _drop(self) -> None:
        self.camera, self.state, self.derivative = (dr.freeze(_recorded(f), warn_after=WARN_AFTER, enabled=self.enabled)
                                                    for f in (camera_samples, primal_state, derivative_samples))
        self._calls = tuple(_history_off(f) for f in (self.camera, self.state, self.derivative))

    def functions(self, geometry: int) -> tuple[Callable[..., tuple], ...]:
        """The (camera, primal state, derivative) pass functions for the scene's ``geometry``: the frozen ones while it
        is the one of the last call, the plain ones at the first call of a new one."""
        if geometry == self.geometry:
            return self._calls
        self.geometry = geometry
        self._drop()
        return camera_samples, primal_state, derivative_samples

    @property
    def recordings(self) -> int:
        """How many recordings the three hold: one more means a render was traced anew, not replayed."""
        return self.camera.n_recordings + self.state.n_recordings + self.derivative.n_recordings


def splat(block: "mi.ImageBlock", position: "mi.Point2f", value: "mi.Color3f") -> None:
    """Add samples of unit weight at film ``position`` (px) into ``block`` through its filter, in the
    samples' order on the current thread count, and evaluate it (the caller sets the thread count)."""
    block.put(position, [value.x, value.y, value.z, mi.Float(1.0)])
    dr.eval(block.tensor())
