"""A joint fit's per-frame renders and Jacobian columns, in this process or on dask.distributed.

A fit of many frames (a pass, :mod:`spacefit.fitting.passes`) renders each frame with its own
loaded scene. Here every frame's render (and, when the solver linearises, its image and Jacobian
columns) of one fit step is one batch: :func:`batched_renders` is the JAX function "free values
-> every frame's image" whose single callback hands the batch to an executor, which runs the
frames one after another in this process (:class:`InProcess`) or at once on dask workers
(:class:`OnDask`). Both run :func:`frame_primal` / :func:`frame_jacobian` on the same inputs, so a
fit gives the same values bit for bit either way (renders are deterministic for a seed).

A process keeps each frame's loaded scene (:class:`Loaded`, keyed by :attr:`FrameSpec.key`)
between steps; on dask each frame goes back to the worker that loaded it (a soft placement: if
that worker is lost, the scheduler runs the frame elsewhere, which loads its scene once; only the
lost worker's frames are recomputed).
"""

from __future__ import annotations

import hashlib
from functools import cached_property
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import jax
import jax.numpy as jnp
import numpy as np

from spacefit.errors import InputError, InputTypeError, check_count, quote
from spacefit.precision import float64
from spacefit.rendering.bridge import seeds_array
from spacefit.rendering.derivatives import RenderChain, render_chain
from spacefit.rendering.renderer import PartImage, render_threads
from spacefit.scene.schema import Scene


@dataclass(frozen=True)
class FrameSpec:
    """What one frame's renders need: its scene and how the fit renders it.

    Attributes:
        scene: the frame's scene (its own sun, camera, attitude).
        names: the registered parameters its renderer sees, in the order of its values.
        fd_steps: each one's central-difference step (0: a forward-mode AD column).
        spp, spp_grad, integrator: as :func:`~spacefit.rendering.derivatives.render_chain` takes them.
    """

    scene: Scene
    names: tuple[str, ...]
    fd_steps: tuple[float, ...]
    spp: int | None
    spp_grad: int | None
    integrator: str

    @cached_property
    def key(self) -> str:
        """A digest of everything that selects the loaded scene: equal specs share one."""
        text = repr((self.scene.to_toml(), self.names, self.fd_steps, self.spp, self.spp_grad, self.integrator))
        return hashlib.sha256(text.encode()).hexdigest()


@dataclass
class Loaded:
    """Loaded scenes by :attr:`FrameSpec.key`, their compiled image functions by (key, kind), and each
    frame's last image and Jacobian: a process (a dask worker) keeps them between a fit's steps."""

    chains: dict[str, RenderChain] = field(default_factory=dict)
    compiled: dict[tuple[str, str], Callable[[jax.Array, jax.Array], Any]] = field(default_factory=dict)
    jacobians: dict[str, tuple[bytes, tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)

    def chain(self, spec: FrameSpec, key: str) -> RenderChain:
        """The frame's loaded scene, loaded on first use."""
        if key not in self.chains:
            self.chains[key] = render_chain(spec.scene, spec.names, spp=spec.spp, spp_grad=spec.spp_grad,
                                            integrator=spec.integrator, fd_steps=np.asarray(spec.fd_steps, dtype=float))
        return self.chains[key]

    def function(self, spec: FrameSpec, key: str, kind: str) -> Callable[[jax.Array, jax.Array], Any]:
        """The frame's image (``kind`` "primal") or its Jacobian and image ("jacobian") as a function
        of its values and seeds (:func:`~spacefit.rendering.bridge.seeds_array`), jitted once per
        scene (a new closure each step would compile each step; seeds as constants, each seed pair)."""
        name = (key, kind)
        if name not in self.compiled:
            image = self.chain(spec, key).seeded()

            def twice(y: jax.Array, seeds: jax.Array) -> tuple[jax.Array, jax.Array]:
                out = image(y, seeds)
                return out, out

            self.compiled[name] = jax.jit(image if kind == "primal" else jax.jacfwd(twice, has_aux=True))
        return self.compiled[name]


# This process's loaded scenes: a dask worker keeps its frames' between tasks.
_LOADED = Loaded()


def loaded_count() -> int:
    """How many frames' scenes this process (a worker) holds."""
    return len(_LOADED.chains)


def frame_part_image(spec: FrameSpec, key: str, loaded: Loaded | None = None) -> PartImage:
    """Which part each pixel of the frame sees (loading its scene)."""
    return (loaded or _LOADED).chain(spec, key).renderer.part_image()


@float64
def frame_primal(spec: FrameSpec, key: str, x: np.ndarray, seed: int, loaded: Loaded | None = None) -> np.ndarray:
    """The frame's radiance image (h, w, 3) float32 at its values ``x`` for ``seed``."""
    image = (loaded or _LOADED).function(spec, key, "primal")
    # a primal render uses no derivative seed
    return np.asarray(image(jnp.asarray(x, dtype=jnp.float64), seeds_array(seed, seed + 1)), dtype=np.float32)


@float64
def frame_jacobian(spec: FrameSpec, key: str, x: np.ndarray, seed: int, seed_grad: int,
                   loaded: Loaded | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The frame's image and Jacobian (h, w, 3, n) at ``x``: one call of the bridge's Jacobian
    callback (:func:`~spacefit.rendering.bridge.render_params`), as a fit's linearisation makes it."""
    if not spec.names:  # the frame's renderer sees no free value (its image nuisances act in JAX): no column
        img = frame_primal(spec, key, x, seed, loaded)
        return img, np.zeros((*img.shape, 0), np.float32)
    loaded = loaded or _LOADED
    point = np.asarray([seed, seed_grad], dtype=np.float64).tobytes() + np.asarray(x, dtype=np.float64).tobytes()
    last = loaded.jacobians.get(key)
    if last is not None and last[0] == point:  # a solver's last linearisation, asked again by the standard errors
        return last[1]
    J, img = loaded.function(spec, key, "jacobian")(jnp.asarray(x, dtype=jnp.float64), seeds_array(seed, seed_grad))
    out = np.asarray(img, dtype=np.float32), np.asarray(J, dtype=np.float32)
    loaded.jacobians[key] = (point, out)
    return out


class Executor(Protocol):
    """Runs one function per frame and returns the results in frame order."""

    def map(self, fn: Callable[..., Any], specs: Sequence[FrameSpec], *per_frame: Sequence[Any]) -> list[Any]:
        """``[fn(spec_k, key_k, *args_k) for each frame k]``."""
        ...

    def close(self) -> None:
        """Release what this executor opened."""
        ...


class InProcess:
    """Every frame in this process, one after another; the loaded scenes live as long as the executor."""

    def __init__(self) -> None:
        self.loaded = Loaded()

    def chain(self, spec: FrameSpec) -> RenderChain:
        """The frame's loaded scene."""
        return self.loaded.chain(spec, spec.key)

    def map(self, fn: Callable[..., Any], specs: Sequence[FrameSpec], *per_frame: Sequence[Any]) -> list[Any]:
        """``[fn(spec_k, key_k, *args_k)]`` in frame order. Deterministic scenes render on one thread
        anyway: the batch sets that once (resizing Dr.Jit's pool for each render cost 40 % of a step)."""
        keys = _keys(specs)
        with render_threads(all(spec.scene.render.deterministic for spec in specs)):
            return [fn(spec, keys[k], *(args[k] for args in per_frame), loaded=self.loaded) for k, spec in enumerate(specs)]

    def close(self) -> None:
        """Drop the loaded scenes."""
        self.loaded = Loaded()


def _keys(specs: Sequence[FrameSpec]) -> list[str]:
    return [spec.key for spec in specs]


def _on_worker(fn: Callable[..., Any], spec: FrameSpec, key: str, *args: Any) -> tuple[Any, str]:
    """Run ``fn`` for one frame on a dask worker: its result and the worker's address."""
    from distributed import get_worker  # here: only a worker runs it

    with render_threads(spec.scene.render.deterministic):  # once per task, not per render (see InProcess.map)
        return fn(spec, key, *args), get_worker().address


class OnDask:
    """Every frame as one dask task, all at once; each frame goes back to the worker that holds its
    loaded scene (``allow_other_workers``: a lost worker's frames run elsewhere)."""

    def __init__(self, client: Any, close: Callable[[], None] | None = None) -> None:
        self.client = client
        self._close = close
        self.home: dict[str, str] = {}  # frame key -> the worker that holds its scene
        self.keys: list[str] = []

    def _placement(self, keys: Sequence[str]) -> list[str]:
        """Each frame's worker: its home if alive, else the live worker with the fewest frames."""
        alive = list(self.client.scheduler_info(n_workers=-1)["workers"])
        if not alive:
            raise InputError("the dask cluster has no workers.")
        load = {w: 0 for w in alive}
        for key in keys:
            if self.home.get(key) in load:
                load[self.home[key]] += 1
        out = []
        for key in keys:
            if self.home.get(key) not in load:
                self.home[key] = min(alive, key=lambda w: load[w])
                load[self.home[key]] += 1
            out.append(self.home[key])
        return out

    def map(self, fn: Callable[..., Any], specs: Sequence[FrameSpec], *per_frame: Sequence[Any]) -> list[Any]:
        """``[fn(spec_k, key_k, *args_k)]`` in frame order, on the workers."""
        keys = _keys(specs)
        places = self._placement(keys)
        futures = [self.client.submit(_on_worker, fn, spec, keys[k], *(args[k] for args in per_frame), workers=[places[k]],
                                      allow_other_workers=True, pure=False)
                   for k, spec in enumerate(specs)]
        out = []
        for key, (result, address) in zip(keys, self.client.gather(futures)):
            self.home[key] = address  # where its scene is loaded now
            out.append(result)
        return out

    def close(self) -> None:
        """Close the client and cluster this executor opened (not a client it was given)."""
        if self._close is not None:
            self._close()


Cluster = int | str | Any


def executor_of(cluster: Cluster | None) -> Executor:
    """The executor of ``fit``'s ``cluster`` argument: None, this process (:class:`InProcess`); an int N, a new local
    dask cluster of N single-threaded worker processes; a string, the dask scheduler at that
    address (``tcp://host:8786``); a ``distributed.Client``, its cluster (left open)."""
    if cluster is None:
        return InProcess()
    if isinstance(cluster, bool):
        raise InputTypeError(f"`cluster` must be None, a number of local workers, a scheduler address or a dask Client, got {cluster!r}.")
    if isinstance(cluster, (int, np.integer)):
        check_count("cluster", int(cluster))
        from spacefit.studies.cluster import connect  # here: dask.distributed takes seconds to import

        logging.getLogger("distributed").setLevel(logging.ERROR)
        client, close = connect(int(cluster), None)
        return OnDask(client, close)
    if isinstance(cluster, str):
        from spacefit.studies.cluster import connect

        client, close = connect(None, cluster)
        return OnDask(client, close)
    if type(cluster).__name__ == "Client" and hasattr(cluster, "submit"):
        return OnDask(cluster)
    raise InputTypeError(f"`cluster` must be None, a number of local workers, a scheduler address or a dask Client, "
                         f"got {quote(cluster)}.")


def batched_renders(executor: Executor, specs: Sequence[FrameSpec], indices: Sequence[np.ndarray],
                    shapes: Sequence[tuple[int, int, int]]) -> Callable[[jax.Array, jax.Array], tuple[jax.Array, ...]]:
    """Every frame's image as one JAX function of the fit's free values x and the seeds
    (:func:`~spacefit.rendering.bridge.seeds_array`; an operand, so that one compiled program serves
    the fit's seeds and the independent ones): frame k renders ``x[indices[k]]``. Its derivative is
    each frame's materialised Jacobian times the tangent, as
    :func:`~spacefit.rendering.bridge.render_params`'s, with all frames' Jacobians in one batch."""
    images = tuple(jax.ShapeDtypeStruct(shape, jnp.float32) for shape in shapes)
    columns = tuple(jax.ShapeDtypeStruct((*shape, len(idx)), jnp.float32) for shape, idx in zip(shapes, indices))

    def primal_cb(x: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, ...]:
        x = np.asarray(x)  # JAX may hand a callback its own array type
        return tuple(executor.map(frame_primal, specs, [x[idx] for idx in indices], [int(seeds[0])] * len(specs)))

    def jacobian_cb(x: np.ndarray, seeds: np.ndarray) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        x = np.asarray(x)
        out = executor.map(frame_jacobian, specs, [x[idx] for idx in indices], [int(seeds[0])] * len(specs),
                           [int(seeds[1])] * len(specs))
        return tuple(img for img, _ in out), tuple(J for _, J in out)

    @jax.custom_jvp
    def render(x: jax.Array, seeds: jax.Array) -> tuple[jax.Array, ...]:
        return jax.pure_callback(primal_cb, images, x, seeds, vmap_method="sequential")

    @render.defjvp
    def render_jvp(primals: tuple[jax.Array, jax.Array], tangents: tuple[jax.Array, jax.Array]) -> tuple[Any, Any]:
        (x, seeds), (t, _) = primals, tangents
        imgs, Js = jax.pure_callback(jacobian_cb, (images, columns), x, seeds, vmap_method="sequential")
        return imgs, tuple(J @ t[idx].astype(jnp.float32) for J, idx in zip(Js, indices))

    return render
