"""Named scene parameters -> the Mitsuba scene values they set, by traverse key (a JAX function).

This is the one place where a registered parameter (:mod:`spacefit.scene.parameters`) meets
Mitsuba's vocabulary: ``parts.panels.alpha_x`` sets ``'panels.bsdf.brdf_0.alpha_u.value'`` (the keys
of the part's material model, :func:`spacefit.rendering.materials.material_keys`), the wrinkles'
D and G set every wrinkled part's ``vertex_positions`` through the JAX W-M heights (so their
tangents are exact), the sun's angles set its frame ``'sun.to_world'`` (by the direction its
light travels), the camera's roll the camera's frame ``'sensor.to_world'`` (whole). The bridge differentiates through the result; a :class:`Renderer` sets it in place.

The target's pose sets every part's ``vertex_positions``, or, where it moves the whole target rigidly and a
chain differentiates it by finite differences (:func:`pose_by_view`), the camera's and the sun's frames moved
the other way: the same picture (the target, the camera and the directional sun, the scene's one emitter,
turned and shifted together), the vertices left as loaded, so that the ray-tracing acceleration structure
stays and the renders replay (:mod:`spacefit.rendering.frozen`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from typing import Any

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from spacefit.errors import InputError
from spacefit.rendering.materials import material_keys
from spacefit.scene.assembly import Assembly
from spacefit.geometry.frames import CameraFrame, attitude_matrix
from spacefit.scene.parameters import ATTITUDE, GEOMETRY, POSITION, ROLL, SUN_ANGLES, scene_value
from spacefit.scene.sections import sun_followers
from spacefit.scene.conversions import G_of, sun_direction

SceneValuesFn = Callable[[Array], dict[str, Array]]


# A scene's view: what its scene values depend on besides the free parameters and the shared
# geometry: its camera's frame (as assembled, turned by the scene's roll) and roll, its sun's angles
# and its target's pose, by parameter name. The frames of a pass differ in it only: their values
# are one function of (x, view), the view an operand, compiled once for every frame.
View = dict[str, Any]
CAMERA = "camera"  # the view's camera frame: (position, right, up, forward) in the world (m, unit vectors)


def scene_view(assembly: Assembly) -> View:
    """The assembled scene's view (:data:`View`): its camera frame, roll (deg), sun angles (deg) and
    target pose (deg, m)."""
    cam = assembly.camera
    return {CAMERA: (cam.position, cam.right, cam.up, cam.forward),
            **{n: scene_value(assembly.scene, n) for n in (ROLL, *SUN_ANGLES, *ATTITUDE, *POSITION)}}


def scene_values_fn(assembly: Assembly, names: Sequence[str], ad: Collection[str] | None = None) -> SceneValuesFn:
    """JAX function: physical values (n,) of the parameters ``names`` -> the scene values they set
    (``ad``: as :func:`view_values_fn` takes it)."""
    values, view = view_values_fn(assembly, names, ad), scene_view(assembly)
    return lambda x: values(x, view)


def ad_names(names: Sequence[str], fd_steps: Sequence[float]) -> list[str]:
    """The names among ``names`` whose columns a chain takes by forward-mode AD: their finite-difference step
    (``fd_steps``, one per name) 0."""
    return [n for n, step in zip(names, fd_steps, strict=True) if step == 0]


def pose_by_view(names: Sequence[str], ad: Collection[str]) -> bool:
    """Whether a chain of the parameters ``names`` renders the target's pose by moving the camera and the
    sun the other way (:func:`view_values_fn`): a pose value among them, no wrinkle value (D, G, the rms
    height move the vertices anyway) and no pose value among ``ad``, those differentiated by forward-mode AD
    (which follows the vertices, not a frame: :func:`~spacefit.rendering.drjit_values.differentiable`)."""
    return (any(n in names for n in (*ATTITUDE, *POSITION)) and not any(n in names for n in GEOMETRY)
            and not any(n in ad for n in (*ATTITUDE, *POSITION)))


def _view_motion(to_world: np.ndarray, rotation: Array, position: Array) -> Array:
    """The 4 x 4 world motion that takes a target at ``rotation`` (object to world) and ``position`` (m) to the
    pose of the homogeneous object-to-world matrix ``to_world`` (its pose as loaded): applied to the camera and
    the sun, the picture of the target at (``rotation``, ``position``) with its vertices at ``to_world``."""
    to_world = jnp.asarray(to_world)  # here: float64 where the caller's values are
    turn = to_world[:3, :3] @ rotation.T
    top = jnp.concatenate([turn, (to_world[:3, 3] - turn @ position)[:, None]], axis=1)
    return jnp.concatenate([top, jnp.asarray([[0.0, 0.0, 0.0, 1.0]])], axis=0)


def _check_laws(assembly: Assembly, free: Sequence[str]) -> None:
    """Refuse freeing the target's attitude angles under an attitude law other than ``fixed``, or the
    sun's angles where a law follows the sun: the law, evaluated once by the assembly, sets what they would."""
    scene = assembly.scene
    followers = sun_followers(scene)
    for name in free:
        if name in ATTITUDE and scene.target.attitude != "fixed":
            raise InputError(f"`{name}` cannot be free: `target.attitude` = {scene.target.attitude!r} sets the target's "
                             "attitude (free the angles with target.attitude = \"fixed\").")
        if name in SUN_ANGLES and followers:
            raise InputError(f"`{name}` cannot be set in place: {', '.join(followers)} follow the sun, turned for the scene's "
                             "sun when it is assembled (assemble the scene again for another sun).")


def view_values_fn(assembly: Assembly, names: Sequence[str], ad: Collection[str] | None = None) -> Callable[[Array, View], dict[str, Array]]:
    """JAX function: physical values (n,) of the parameters ``names`` and a view (:func:`scene_view`
    of this scene or of one differing in its view only) -> the scene values they set.

    ``ad``: the names whose derivatives a chain takes by forward-mode AD. Given, a rigid pose
    (:func:`pose_by_view`) moves the camera and the sun the other way and the vertices stay as loaded.
    None: the pose moves the vertices (:meth:`~spacefit.rendering.renderer.Renderer.set_values`, whose
    earlier values stay set: a pose by the view would undo a roll or a sun set before it)."""
    index = {name: i for i, name in enumerate(names)}
    scene = assembly.scene
    w = scene.wrinkles
    geometry = [n for n in GEOMETRY if n in index]
    pose = [n for n in (*ATTITUDE, *POSITION) if n in index]
    sun_angles = [n for n in SUN_ANGLES if n in index]
    _check_laws(assembly, [n for n in (*ATTITUDE, *sun_angles) if n in index])
    law_rotation = None if scene.target.attitude == "fixed" else jnp.asarray(assembly.to_world[:3, :3])
    by_view = ad is not None and pose_by_view(names, ad)

    def values_of(x: Array, view: View) -> dict[str, Array]:
        def value(name: str) -> Array:
            return x[index[name]] if name in index else view[name]

        out: dict[str, Array] = {}
        if sun_angles or by_view:
            out["sun.to_world"] = sun_direction(*(value(n) for n in SUN_ANGLES), xp=jnp)
        if ROLL in index or by_view:  # the assembled camera is turned by the scene's roll already
            roll = jnp.deg2rad(x[index[ROLL]] - view[ROLL]) if ROLL in index else 0.0
            out["sensor.to_world"] = CameraFrame(*view[CAMERA]).mitsuba_to_world(roll, jnp)
        if geometry or pose:
            rotation = attitude_matrix(jnp.deg2rad(jnp.stack([value(n) for n in ATTITUDE])), jnp) if law_rotation is None else law_rotation
            position = jnp.stack([value(n) for n in POSITION])
        if by_view:
            motion = _view_motion(assembly.to_world, rotation, position)
            out["sun.to_world"] = motion[:3, :3] @ out["sun.to_world"]
            out["sensor.to_world"] = motion @ out["sensor.to_world"]
        elif geometry or pose:
            D = x[index["wrinkles.D"]] if "wrinkles.D" in index else w.D
            G = x[index["wrinkles.G"]] if "wrinkles.G" in index else w.G
            if "wrinkles.rms_m" in index:
                G = G_of(w, D, x[index["wrinkles.rms_m"]])
            for part in assembly.parts if pose else assembly.refinements:
                out[f"{part}.vertex_positions"] = jnp.ravel(assembly.object_vertices(part, D, G) @ rotation.T + position)
        for name, i in index.items():
            if name == "sun.irradiance_w_m2":
                out["sun.irradiance.value"] = jnp.full(3, x[i])
            elif name.startswith("parts."):
                _, part, field = name.split(".")
                for key, write in material_keys(part, assembly.materials[part], field):
                    out[key] = write(x[i])
        return out

    return values_of
