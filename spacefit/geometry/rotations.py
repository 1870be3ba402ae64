"""Rotations of spacefit's articulation and attitude laws, and the checks of the directions they take.

Conventions (docs/reference/conventions.md; those of :mod:`spacefit.geometry.frames`):

* A body attitude is a rotation R from the body frame to the world frame, ``p_world = R p_body +
  position``, as ``target.attitude_deg`` gives it (:func:`~spacefit.geometry.frames.attitude_matrix`).
* An angle ``a`` about a unit axis ``u`` is the rotation :func:`axis_rotation`: the thesis's
  convention, a right-handed rotation by ``-a`` (clockwise seen from the axis tip), so that the angle
  ``a`` about x, y, z is ``R1(a)``, ``R2(a)``, ``R3(a)`` of the attitude angles exactly.
* A quaternion ``(w, x, y, z)`` (scalar first, Hamilton's product) with ``w = cos(phi / 2)`` and
  ``(x, y, z) = sin(phi / 2) u`` is the right-handed rotation by ``phi`` about ``u``; as an attitude it
  maps body to world (its matrix is R above, :func:`quaternion_matrix`).

A sun-tracking part turns about a body axis by the angle that maximises ``n . s`` (n the part's
normal, s the unit direction towards the sun, both in the body frame): the normal's component across
the axis is turned onto the sun's (:func:`tracking_rotation`); where the sun lies along the axis every
angle gives the same ``n . s`` and the part keeps its placed attitude (angle 0). A two-axis attitude
points one body axis along a world direction and turns a second towards another as far as that
allows (:func:`two_axis_rotation`, the TRIAD construction).
"""

from __future__ import annotations

from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import InputError, check_direction

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s)
    from jaxtyping import Float

# Below this length of the sun's component across a tracking axis the sun lies along the axis: the part
# keeps its placed attitude (every angle gives the same n . s).
ALONG_AXIS = 1e-9
# Two directions this close to parallel (sine of their angle) leave a two-axis attitude undefined.
PARALLEL_SINE = 1e-6


def _rodrigues(axis: Any, c: Any, s: Any, xp: ModuleType) -> Any:
    """The right-handed rotation about the unit ``axis`` whose angle has cosine ``c`` and sine ``s``
    (Rodrigues' formula, ``c I + s [u]x + (1 - c) u u^T``); ``c``, ``s`` scalars or (n,) for (n, 3, 3)."""
    u = xp.asarray(axis)
    zero = 0.0 * u[0]
    cross = xp.stack([xp.stack([zero, -u[2], u[1]]), xp.stack([u[2], zero, -u[0]]), xp.stack([-u[1], u[0], zero])])
    c, s = xp.asarray(c)[..., None, None], xp.asarray(s)[..., None, None]
    return c * xp.eye(3) + s * cross + (1.0 - c) * xp.outer(u, u)


def axis_rotation(axis: Float[np.ndarray, "3"], angle: float, xp: ModuleType = np) -> Float[np.ndarray, "3 3"]:
    """The rotation by ``angle`` (rad) about the unit ``axis`` in spacefit's convention (module
    docstring): right-handed by ``-angle``, so ``axis_rotation(x, a)`` is ``R1(a)`` of
    :func:`~spacefit.geometry.frames.attitude_matrix`. ``xp``: NumPy or ``jax.numpy``."""
    return _rodrigues(axis, xp.cos(angle), -xp.sin(angle), xp)


def tracking_rotation(axis: Float[np.ndarray, "3"], normal: Float[np.ndarray, "3"], sun: Float[np.ndarray, "... 3"],
                      xp: ModuleType = np) -> Float[np.ndarray, "... 3 3"]:
    """The rotation about the unit ``axis`` that turns a part with unit ``normal`` to face the unit
    direction ``sun`` as closely as that one rotation allows (``n . s`` largest: the normal's component
    across the axis onto the sun's); the identity where the sun's component across the axis is shorter
    than :data:`ALONG_AXIS` (the sun along the axis). ``sun`` (3,) or (n, 3) gives (3, 3) or (n, 3, 3);
    ``xp``: NumPy or ``jax.numpy`` (differentiable in ``sun`` everywhere, the degenerate case included)."""
    u, n = xp.asarray(axis), xp.asarray(normal)
    across = n - xp.dot(n, u) * u
    e1 = across / xp.linalg.norm(across)
    e2 = xp.cross(u, e1)
    x, y = xp.asarray(sun) @ e1, xp.asarray(sun) @ e2
    r2 = x * x + y * y
    along = r2 < ALONG_AXIS**2
    r = xp.sqrt(xp.where(along, 1.0, r2))  # the sqrt's derivative at 0 is infinite: take it where it is finite
    return _rodrigues(u, xp.where(along, 1.0, x / r), xp.where(along, 0.0, y / r), xp)


def unit_axis(name: str, value: Any) -> tuple[float, float, float]:
    """``value`` as a unit direction (3 floats), refused as ``name`` where it is zero or not finite."""
    return tuple(check_direction(name, value).tolist())


def check_not_parallel(name: str, a: np.ndarray, other: str, b: np.ndarray) -> None:
    """Refuse unit directions ``a`` (named ``name``) and ``b`` (``other``) closer to parallel than :data:`PARALLEL_SINE`."""
    if np.linalg.norm(np.cross(a, b)) < PARALLEL_SINE:
        raise InputError(f"`{name}` {np.round(a, 6).tolist()} must not be parallel to {other} {np.round(b, 6).tolist()}: "
                         "the rotation about it would be undefined.")


def two_axis_rotation(body1: np.ndarray, world1: np.ndarray, body2: np.ndarray, world2: np.ndarray) -> np.ndarray:
    """The rotation (body to world) taking ``body1`` onto ``world1`` and turning ``body2`` about it
    towards ``world2`` as far as allowed (the TRIAD construction; all unit, neither pair parallel)."""

    def triad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        c = np.cross(a, b)
        c /= np.linalg.norm(c)
        return np.stack([a, c, np.cross(a, c)], axis=1)

    return triad(world1, world2) @ triad(body1, body2).T


def quaternion_matrix(q: Float[np.ndarray, "... 4"]) -> Float[np.ndarray, "... 3 3"]:
    """The rotation matrix of unit quaternions ``(w, x, y, z)`` (module docstring: right-handed by phi about u)."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)
