"""A joint fit's per-frame renders and Jacobian columns, in this process or on dask.distributed.

A fit of many frames (a pass, :mod:`spacefit.fitting.passes`) renders each frame with its own
loaded scene. Every frame's render (and, when the solver linearises, its image and Jacobian
columns) of one fit step is one batch (:mod:`spacefit.fitting.render_batches`: the JAX function "free values
-> every frame's image" whose single callback hands the batch to an executor), which runs the
frames one after another in this process (:class:`InProcess`) or at once on dask workers
(:class:`spacefit.executors.OnDask`). Both run :func:`frame_primal` / :func:`frame_jacobian` on the same inputs, so a
fit gives the same values bit for bit either way (renders are deterministic for a seed).

A process keeps the frames' loaded scene and its compiled functions (:class:`Loaded`: one for all
the frames of a pass, which set their own camera, sun and pose on it, their view an operand)
between steps; on dask each frame goes back to the worker that loaded it (a soft placement: if
that worker is lost, the scheduler runs the frame elsewhere, which loads its scene once; only the
lost worker's frames are recomputed).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from collections import OrderedDict
from collections.abc import Callable, Sequence
from functools import cached_property
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from spacefit import executors
from spacefit.executors import Cluster, Executor, executor_of
from spacefit.precision import float64, on_device
from spacefit.rendering.bridge import outside_render_params, scene_values_program, seeds_array
from spacefit.rendering.derivatives import RenderChain, render_chain
from spacefit.rendering.memory import release_freed_memory
from spacefit.rendering.parts import PartImage
from spacefit.rendering.values import View, ad_names, scene_view, view_values_fn
from spacefit.scene.assembly import Assembly, assemble
from spacefit.scene.parameters import ATTITUDE, POSITION, ROLL, SUN_ANGLES, scene_value
from spacefit.scene.schema import Scene

POSE = (*ATTITUDE, *POSITION)


@dataclass(frozen=True)
class FrameSpec:
    """What one frame's renders need: its scene and how the fit renders it.

    Attributes:
        scene: the frame's scene (its own sun, camera, attitude).
        names: the registered parameters its renderer sees, in the order of its values.
        fd_steps: each one's central-difference step (0: a forward-mode AD column).
        spp, spp_grad, integrator: as :func:`~spacefit.rendering.derivatives.render_chain` takes them.
        shared_view: the frame sets its camera and sun on a loaded scene it shares with frames of
            other views, rendered whole (:func:`share_views`); else it has a loaded scene of its
            own, which renders only the window round the target unless vertices move.
        view_pose: with ``shared_view``, the frame sets its target's pose too, free or not (frames
            that turn the target: a light curve's points), so that frames of other poses share its
            loaded scene.
    """

    scene: Scene
    names: tuple[str, ...]
    fd_steps: tuple[float, ...]
    spp: int | None
    spp_grad: int | None
    integrator: str
    shared_view: bool = False
    view_pose: bool = False

    @cached_property
    def key(self) -> str:
        """A digest of everything that selects the frame's chain: equal specs share one."""
        text = repr((self.scene.to_toml(), self.names, self.fd_steps, self.spp, self.spp_grad, self.integrator, self.shared_view,
                     self.view_pose))
        return hashlib.sha256(text.encode()).hexdigest()


def share_views(specs: Sequence[FrameSpec]) -> list[FrameSpec]:
    """The specs of one fit's frames, set to share a loaded scene (:attr:`FrameSpec.shared_view`)
    when their scenes differ (a pass's views); the frames of one scene keep their own, cropped."""
    if len({spec.scene.to_toml() for spec in specs}) < 2:
        return list(specs)
    return [dataclasses.replace(spec, shared_view=True) for spec in specs]


# The loaded scenes a process keeps at most (a pass needs one; measured at 32 x 32 px, a worker is
# about 510 MiB with one, and 8 MiB more per frame it holds); past it the least recently used one
# is dropped with its frames.
MAX_SCENES = 8
# The values every frame sets on the loaded scene it shares: its camera (the whole camera frame
# through the roll) and its sun; its target's pose too when a pose parameter is free.
VIEW = (ROLL, *SUN_ANGLES)
# Scene-file keys of those values (a stage's key leaves them out).
VIEW_KEYS = {"camera": ("position_m", "attitude_deg", "look_at_m", "up", "roll_deg"), "sun": ("direction",)}
POSE_KEYS = {"target": ("attitude_deg", "position_m")}


def _stage(spec: FrameSpec, assembly: Assembly) -> str:
    """A digest of what frames sharing one loaded scene have in common: the scene but its camera
    pose, sun direction and (a pose parameter free) target pose, the meshes as loaded, the
    materials, the free names and how they are rendered (their steps among it: they choose how a pose is set,
    :func:`~spacefit.rendering.values.pose_by_view`)."""
    text = spec.scene.to_dict()
    for section, keys in (*VIEW_KEYS.items(), *(POSE_KEYS.items() if spec.view_pose or set(spec.names) & set(POSE) else ())):
        text[section] = {k: v for k, v in text.get(section, {}).items() if k not in keys}
    meshes = {name: hashlib.sha256(np.ascontiguousarray(assembly.faces(name)).tobytes()).hexdigest() for name in assembly.parts}
    return hashlib.sha256(repr((sorted(text.items()), meshes, sorted(assembly.materials.items()), spec.names, spec.fd_steps, spec.spp,
                                spec.spp_grad, spec.integrator)).encode()).hexdigest()


def _view_names(spec: FrameSpec) -> tuple[str, ...]:
    """The values a frame sets from its view besides its free ones: on a loaded scene shared with other
    views its camera and sun, and its target's pose with :attr:`FrameSpec.view_pose`."""
    if not spec.shared_view:
        return ()
    return tuple(n for n in (*VIEW, *(POSE if spec.view_pose else ())) if n not in spec.names)


def _frame_values(assembly: Assembly, names: Sequence[str], fd_steps: Sequence[float],
                  extra: Sequence[str]) -> Callable[[jax.Array, View], dict[str, jax.Array]]:
    """A frame's scene values as a function of its free values (``names``, their finite-difference steps
    ``fd_steps``, 0 for a forward-mode AD column) and its view (:func:`~spacefit.rendering.values.scene_view`,
    an operand), which gives the ``extra`` ones (:func:`_view_names`): on a loaded scene shared with other views
    every render sets the frame's camera and sun (and its pose, when free or :attr:`FrameSpec.view_pose`). A
    rigid pose moves the camera and the sun, the vertices kept as loaded (:func:`~spacefit.rendering.values.pose_by_view`)."""
    values = view_values_fn(assembly, (*names, *extra), ad_names(names, fd_steps))

    def values_of(x: jax.Array, view: View) -> dict[str, jax.Array]:
        return values(jnp.concatenate([jnp.asarray(x), jnp.asarray([view[n] for n in extra], dtype=jnp.result_type(x))]), view)

    return values_of


@dataclass(frozen=True)
class Stage:
    """A loaded scene and its frames' scene values as a function of (free values, view)."""

    chain: RenderChain
    values: Callable[[jax.Array, View], dict[str, jax.Array]]

    @cached_property
    def compiled_values(self) -> Callable[[jax.Array, View], dict[str, jax.Array]]:
        """:attr:`values` as one program for every frame on the scene, the view an operand (a program per frame
        held one compiled executable a frame for the fit's life: about 2.5 MiB a frame of a pass), the arrays it closes
        over (the parts' vertices) its operands, its values as the renders set them
        (:func:`~spacefit.rendering.bridge.scene_values_program`): the part image's and the primal renders' one program."""
        return scene_values_program(self.values)


@dataclass
class Loaded:
    """Loaded scenes (stages) and each frame's chain and view on one, by :attr:`FrameSpec.key`, the
    compiled image functions of each stage's frames, and each frame's last image and Jacobian: a
    process (a dask worker) keeps them between a fit's steps.

    The frames of a pass (:attr:`FrameSpec.shared_view`) differ in camera, sun and target pose
    only, so they share one loaded scene and set their own values on it at each render. Dr.Jit
    traces every loaded scene's plugins in each render (its calls cover every instance alive:
    mitsuba3#1700), so a process holding a loaded scene per frame paid per render for all of them:
    0.25 s per frame and step with one frame held, 1.4 s with eight (16 x 16 px). They share its
    compiled functions too, their views an operand: compiled per frame, the first step of a pass
    cost seconds per frame. At most ``max_scenes`` are kept, the least recently used dropped.
    """

    max_scenes: int = MAX_SCENES
    stages: OrderedDict[str, Stage] = field(default_factory=OrderedDict)
    chains: dict[str, tuple[str, RenderChain, View]] = field(default_factory=dict)
    compiled: dict[tuple[str, tuple[float, ...]], tuple[Callable[..., Any], Callable[..., Any]]] = field(default_factory=dict)
    jacobians: dict[str, tuple[bytes, tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)

    def chain(self, spec: FrameSpec, key: str) -> RenderChain:
        """The frame's chain on its loaded scene, loaded on first use (dropping the least recently used past
        :attr:`max_scenes`)."""
        if key in self.chains and self.chains[key][0] in self.stages:
            self.stages.move_to_end(self.chains[key][0])
            return self.chains[key][1]
        assembly = assemble(spec.scene)
        stage = _stage(spec, assembly) if spec.shared_view else key
        if stage not in self.stages:
            while len(self.stages) >= self.max_scenes:
                self._drop(next(iter(self.stages)))
            extra = _view_names(spec)
            chain = render_chain(assembly, (*spec.names, *extra), spp=spec.spp, spp_grad=spec.spp_grad, integrator=spec.integrator,
                                 fd_steps=None if spec.shared_view else np.asarray(spec.fd_steps, dtype=float),
                                 crop=False if spec.shared_view else None)
            self.stages[stage] = Stage(chain, _frame_values(assembly, spec.names, spec.fd_steps, extra))
        self.stages.move_to_end(stage)
        on, view = self.stages[stage], scene_view(assembly)
        chain = RenderChain(spec.names, on.chain.renderer, on.chain.drjit, lambda x: on.values(x, view),
                            np.asarray(spec.fd_steps, dtype=float))
        self.chains[key] = (stage, chain, view)
        return chain

    def _drop(self, stage: str) -> None:
        """Forget a loaded scene, its frames' chains and their compiled functions."""
        del self.stages[stage]
        gone = {key for key, (s, *_) in self.chains.items() if s == stage}
        self.chains = {key: v for key, v in self.chains.items() if key not in gone}
        self.compiled = {name: fn for name, fn in self.compiled.items() if name[0] != stage}
        self.jacobians = {key: v for key, v in self.jacobians.items() if key not in gone}

    def function(self, spec: FrameSpec, key: str, kind: str) -> Callable[[jax.Array, jax.Array], Any]:
        """The frame's image (``kind`` "primal") or its image and Jacobian ("jacobian") as a function
        of its values and seeds (:func:`~spacefit.rendering.bridge.seeds_array`), rendered outside JAX
        (:func:`~spacefit.rendering.bridge.outside_render_params`): one pair of programs per loaded scene and
        finite-difference steps, the seeds and the frame's view their operands (a new closure each step
        would compile each step, a closure per frame each frame). The Jacobian's function takes the image made before as
        ``image=`` (:func:`frame_jacobian`)."""
        chain = self.chain(spec, key)  # loads it, or marks its scene as recently used
        stage, _, view = self.chains[key]
        name = (stage, spec.fd_steps)
        if name not in self.compiled:
            on = self.stages[stage]
            self.compiled[name] = outside_render_params(chain.drjit, on.values, spec.fd_steps, on.compiled_values)
        compiled = self.compiled[name][kind == "jacobian"]
        return lambda x, seeds, **image: compiled(x, seeds, view, **image)


# This process's loaded scenes: a dask worker keeps its frames' between tasks.
_LOADED = Loaded()


def loaded_count() -> tuple[int, int]:
    """How many loaded scenes and frames this process (a worker) holds."""
    return len(_LOADED.stages), len(_LOADED.chains)


@float64
def frame_part_image(spec: FrameSpec, key: str, loaded: Loaded | None = None) -> PartImage:
    """Which part each pixel of the frame sees at its scene's values (loading its scene)."""
    loaded = loaded or _LOADED
    chain = loaded.chain(spec, key)
    stage, _, view = loaded.chains[key]
    x = on_device([scene_value(spec.scene, n) for n in spec.names], np.float64)
    # one program per loaded scene, the frame's view an operand: run operation by operation, the scene values made
    # some 20 single-operation programs per frame; the primal renders' program (float32 values, as Mitsuba's)
    chain.renderer.set_params({name: np.asarray(value) for name, value in loaded.stages[stage].compiled_values(x, view).items()})
    return chain.renderer.part_image()


@float64
def frame_primal(spec: FrameSpec, key: str, x: np.ndarray, seed: int, loaded: Loaded | None = None) -> np.ndarray:
    """The frame's radiance image (h, w, 3) float32 at its values ``x`` for ``seed``."""
    image = (loaded or _LOADED).function(spec, key, "primal")
    # a primal render uses no derivative seed
    return np.asarray(image(jnp.asarray(x, dtype=jnp.float64), seeds_array(seed, seed + 1)), dtype=np.float32)


@float64
def frame_jacobian(spec: FrameSpec, key: str, x: np.ndarray, seed: int, seed_grad: int, loaded: Loaded | None = None,
                   image: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The frame's image and Jacobian (h, w, 3, n) at ``x``: one call of the bridge's Jacobian
    callback (:func:`~spacefit.rendering.bridge.render_params`), as a fit's linearisation makes it.
    ``image``: the frame's image at ``x`` for ``seed``, rendered before (:func:`frame_primal`'s): the columns alone are rendered."""
    if not spec.names:  # the frame's renderer sees no free value (its image nuisances act in JAX): no column
        img = frame_primal(spec, key, x, seed, loaded) if image is None else image
        return img, np.zeros((*img.shape, 0), np.float32)
    loaded = loaded or _LOADED
    point = np.asarray([seed, seed_grad], dtype=np.float64).tobytes() + np.asarray(x, dtype=np.float64).tobytes()
    last = loaded.jacobians.get(key)
    if last is not None and last[0] == point:  # a solver's last linearisation, asked again by the standard errors
        return last[1]
    made_before = {} if image is None else {"image": image}
    img, J = loaded.function(spec, key, "jacobian")(jnp.asarray(x, dtype=jnp.float64), seeds_array(seed, seed_grad), **made_before)
    out = np.asarray(img, dtype=np.float32), np.asarray(J, dtype=np.float32)
    loaded.jacobians[key] = (point, out)
    return out


def frame_columns(spec: FrameSpec, key: str, x: np.ndarray, seed: int, seed_grad: int, image: np.ndarray,
                  loaded: Loaded | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`frame_jacobian` beside the frame's ``image`` at ``x`` for ``seed``, rendered before: its columns alone rendered."""
    return frame_jacobian(spec, key, x, seed, seed_grad, loaded, image)


class InProcess(executors.InProcess):
    """Every frame in this process, one after another; the loaded scenes live as long as the executor."""

    def __init__(self) -> None:
        self.loaded = Loaded()

    def chain(self, spec: FrameSpec) -> RenderChain:
        """The frame's loaded scene."""
        return self.loaded.chain(spec, spec.key)

    def close(self) -> None:
        """Drop the loaded scenes."""
        self.loaded = Loaded()


def frame_executor(cluster: Cluster | None) -> Executor:
    """The executor of a fit's ``cluster`` (:func:`spacefit.executors.executor_of`): in this process, one
    that keeps the frames' loaded scenes (:class:`InProcess`)."""
    return InProcess() if cluster is None else executor_of(cluster)


def run_frames(executor: Executor, fn: Callable[..., Any], specs: Sequence[FrameSpec], *per_frame: Sequence[Any]) -> list[Any]:
    """``[fn(spec_k, key_k, *args_k) for each frame k]`` in frame order on ``executor``. Each render traces
    its samples on all of Dr.Jit's threads and, when deterministic, splats them on one, in their order
    (:meth:`~spacefit.rendering.renderer.Renderer.radiance`, :meth:`~spacefit.rendering.drjit_scene.DrJitScene.forward`):
    a frame's image and Jacobian are those of a render wholly on one thread, bit for bit. Several frames (a pass): the
    C heap's freed pages handed back before and after (:func:`~spacefit.rendering.memory.release_freed_memory`), those
    the solver's step freed on XLA's threads and those the renders freed on Dr.Jit's, which the other's threads do not
    reuse: kept, they lay under each step's peak."""
    keys = [spec.key for spec in specs]
    joint = len(specs) > 1
    if joint:
        release_freed_memory()
    local = isinstance(executor, InProcess)
    out = executor.map(functools.partial(fn, loaded=executor.loaded) if local else fn, keys, specs, keys, *per_frame)
    if joint:
        release_freed_memory()
    return out
