"""Scene values as Dr.Jit takes them: a float array -> the Dr.Jit type of a traverse key's value, opaque,
and which values automatic differentiation reaches."""

from __future__ import annotations

import numpy as np

from spacefit.rendering.backend import dr, mi


def differentiable(value: object) -> bool:
    """Whether AD differentiates a scene value: a frame (the sun's, the camera's) is set whole, its
    Jacobian columns come from finite differences."""
    return not isinstance(value, mi.AffineTransform4f)


def to_value(template: object, value: np.ndarray) -> object:
    """A Dr.Jit value of the type of ``template`` (a scene parameter) from a float array, opaque
    (evaluated, not a literal): the frozen passes (:mod:`spacefit.rendering.frozen`) take it as an
    operand and replay, where a literal would be compiled into their kernels and retraced at each change.

    A transform is given whole (16 numbers, the camera's :meth:`~spacefit.geometry.frames.CameraFrame.mitsuba_to_world`)
    or, for a distant light's frame, by the direction its +z axis points along (3 numbers).
    """
    value = np.asarray(value, dtype=np.float32).ravel()
    if isinstance(template, mi.AffineTransform4f) and value.size == 16:
        result = mi.AffineTransform4f(value.reshape(4, 4))
    elif isinstance(template, mi.AffineTransform4f):
        d = value / np.linalg.norm(value)
        up = [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0]
        result = mi.AffineTransform4f(mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=d.tolist(), up=up))
    elif isinstance(template, mi.Color3f):
        result = mi.Color3f(*(mi.Float(value[i % len(value)]) for i in range(3)))
    else:
        result = type(template)(value)
    dr.make_opaque(result)
    return result
