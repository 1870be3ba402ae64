"""Frames and the pinhole camera model of thesis section 3.2 (world, camera and object frames).

Conventions (all lengths in metres, angles in radians):

* The world frame is right-handed.
* An attitude ``(alpha, beta, gamma)`` is turned into a rotation with the thesis's matrices exactly as
  printed in section 3.2, ``R = R1(alpha) @ R2(beta) @ R3(gamma)``, where

      R1(a) = [[1, 0, 0], [0, cos a, sin a], [0, -sin a, cos a]]      (about x)
      R2(b) = [[cos b, 0, -sin b], [0, 1, 0], [sin b, 0, cos b]]      (about y)
      R3(c) = [[cos c, sin c, 0], [-sin c, cos c, 0], [0, 0, 1]]      (about z)

  Each is a right-handed rotation by the *negative* angle (clockwise seen from the axis tip), and
  ``R`` maps object coordinates to world coordinates: ``p_world = R @ p_object + position``.
  With the thesis's target attitude [90, 0, 0] deg a lander built with +z up ends up with its top
  along world +y, upright in the default camera's image.
* A camera with zero attitude looks along world -z with image right along +x and image up along +y;
  its attitude rotates that frame by ``R`` above. A roll then turns it about its optical axis,
  right-handed about the viewing direction (:func:`roll_axes`).
* Pixel coordinates are continuous, origin at the top-left corner of the image, u to the right,
  v down; pixel (i, j) covers [i, i + 1) x [j, j + 1). The principal point is the image centre plus
  an offset in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import A_SCENE, InputError, InputTypeError, check_count, check_range, check_type, check_vector, quote

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s), which a render does not need
    from jaxtyping import Float


def attitude_matrix(angles: Float[np.ndarray, "3"], xp: ModuleType = np) -> Float[np.ndarray, "3 3"]:
    """Rotation ``R1(alpha) R2(beta) R3(gamma)`` of thesis section 3.2 from angles in radians.

    ``xp`` is the array module: NumPy, or ``jax.numpy`` for a rotation differentiable in the angles.
    """
    angles = np.asarray(angles, dtype=float) if xp is np else angles
    a, b, c = angles[0], angles[1], angles[2]
    one, zero = xp.ones_like(a), xp.zeros_like(a)
    r1 = xp.stack([xp.stack([one, zero, zero]), xp.stack([zero, xp.cos(a), xp.sin(a)]), xp.stack([zero, -xp.sin(a), xp.cos(a)])])
    r2 = xp.stack([xp.stack([xp.cos(b), zero, -xp.sin(b)]), xp.stack([zero, one, zero]), xp.stack([xp.sin(b), zero, xp.cos(b)])])
    r3 = xp.stack([xp.stack([xp.cos(c), xp.sin(c), zero]), xp.stack([-xp.sin(c), xp.cos(c), zero]), xp.stack([zero, zero, one])])
    return r1 @ r2 @ r3


def object_to_world(
    position: Float[np.ndarray, "3"], attitude: Float[np.ndarray, "3"]
) -> Float[np.ndarray, "4 4"]:
    """Homogeneous object-to-world matrix from a position (m) and an attitude (rad)."""
    m = np.eye(4)
    m[:3, :3] = attitude_matrix(attitude)
    m[:3, 3] = position
    return m


def roll_axes(
    right: Float[np.ndarray, "3"], up: Float[np.ndarray, "3"], roll: object, xp: ModuleType = np
) -> tuple[Float[np.ndarray, "3"], Float[np.ndarray, "3"]]:
    """A camera's (right, up) turned by ``roll`` (rad) about its viewing direction, right-handed:
    image up turns towards image right, so the scene turns anticlockwise in the image.
    ``xp``: NumPy, or ``jax.numpy`` for axes differentiable in the roll."""
    c, s = xp.cos(roll), xp.sin(roll)
    return c * right - s * up, c * up + s * right


@dataclass(frozen=True)
class CameraFrame:
    """Position (m) and orthonormal axes (world) of a camera: forward is the optical axis."""

    position: Float[np.ndarray, "3"]
    right: Float[np.ndarray, "3"]
    up: Float[np.ndarray, "3"]
    forward: Float[np.ndarray, "3"]

    @classmethod
    def from_attitude(cls, position: np.ndarray, attitude: np.ndarray) -> CameraFrame:
        """Camera frame from a position (m) and an attitude (rad), see the module conventions."""
        r = attitude_matrix(attitude)
        return cls(np.asarray(position, float), r[:, 0], r[:, 1], -r[:, 2])

    @classmethod
    def look_at(cls, position: np.ndarray, target: np.ndarray, up: np.ndarray) -> CameraFrame:
        """Camera frame at ``position`` looking at ``target`` with image up as close to ``up``."""
        position = np.asarray(position, float)
        forward = np.asarray(target, float) - position
        if np.linalg.norm(forward) == 0.0:
            raise InputError("`camera.look_at_m` must differ from `camera.position_m`.")
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(up, float))
        if np.linalg.norm(right) < 1e-9:
            raise InputError("`camera.up` must not be parallel to the viewing direction.")
        right = right / np.linalg.norm(right)
        return cls(position, right, np.cross(right, forward), forward)

    def rolled(self, roll: float) -> CameraFrame:
        """This frame turned by ``roll`` (rad) about its optical axis (:func:`roll_axes`)."""
        return CameraFrame(self.position, *roll_axes(self.right, self.up, roll), self.forward)

    def mitsuba_to_world(self, roll: object = 0.0, xp: ModuleType = np) -> Float[np.ndarray, "4 4"]:
        """The 4 x 4 camera-to-world matrix of Mitsuba's perspective sensor (columns: image left, image
        up, forward, position) of this frame turned by a further ``roll`` (rad; a JAX scalar with
        ``xp`` = ``jax.numpy``, for a matrix differentiable in it)."""
        right, up = roll_axes(xp.asarray(self.right), xp.asarray(self.up), roll, xp)
        columns = xp.stack([-right, up, xp.asarray(self.forward), xp.asarray(self.position)], axis=1)
        return xp.concatenate([columns, xp.asarray([[0.0, 0.0, 0.0, 1.0]])], axis=0)

    def to_camera(self, points: Float[np.ndarray, "n 3"]) -> Float[np.ndarray, "n 3"]:
        """World points to camera coordinates (right, up, depth along forward), in metres."""
        d = np.atleast_2d(points) - self.position
        return np.stack([d @ self.right, d @ self.up, d @ self.forward], axis=-1)


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics: focal length and pixel pitch (m), size (px), principal point offset (px).

    Args:
        focal_length: f (m), > 0.
        pixel_pitch: the pixels' side (m), > 0 (square pixels).
        width, height: the image's size (px), >= 1.
        principal_offset: the principal point's offset from the image centre (px), (x right, y down).

    Raises:
        InputError: a value outside its range, naming it.

    Example:
        >>> import spacefit as sf
        >>> sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=640, height=480)
        Intrinsics(focal_length=0.05, pixel_pitch=1e-05, width=640, height=480, principal_offset=(0.0, 0.0))
        >>> sf.Intrinsics.from_scene(sf.default_scene()).width
        600
    """

    focal_length: float
    pixel_pitch: float
    width: int
    height: int
    principal_offset: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        check_range("Intrinsics.focal_length", self.focal_length, 0.0, lo_open=True, unit="m")
        check_range("Intrinsics.pixel_pitch", self.pixel_pitch, 0.0, lo_open=True, unit="m")
        check_count("Intrinsics.width", self.width, optional=False)
        check_count("Intrinsics.height", self.height, optional=False)
        object.__setattr__(self, "principal_offset", tuple(map(float, check_vector("Intrinsics.principal_offset", self.principal_offset, 2))))

    @classmethod
    def from_scene(cls, scene: Any) -> Intrinsics:
        """The intrinsics of a scene's camera (an ``sf.Scene``), in metres: ``camera.focal_length_mm`` and
        ``camera.pixel_pitch_mm`` (set by ``camera.fov_deg`` where it is given), ``render.resolution``
        and ``camera.principal_offset_px``; what :func:`observe` and a sensor take.

        Raises:
            InputTypeError: ``scene`` has no camera and render settings (the geometry sits under the scene's schema,
                so it reads them by name)."""
        c, r = getattr(scene, "camera", None), getattr(scene, "render", None)
        if not (hasattr(c, "focal_length_mm") and hasattr(r, "resolution")):
            raise InputTypeError(f"`scene` must be {A_SCENE}, got {quote(scene)}.")
        return cls(c.focal_length_mm * 1e-3, c.pixel_pitch_mm * 1e-3, r.resolution[0], r.resolution[1], c.principal_offset_px)

    @property
    def focal_px(self) -> float:
        """Focal length in pixels."""
        return self.focal_length / self.pixel_pitch

    @property
    def principal_point(self) -> tuple[float, float]:
        """Principal point (u0, v0) in pixel coordinates."""
        return (self.width / 2 + self.principal_offset[0], self.height / 2 + self.principal_offset[1])

    @property
    def fov_x(self) -> float:
        """Horizontal field of view (rad) of the image centred on the optical axis."""
        return 2.0 * np.arctan(self.width * self.pixel_pitch / (2.0 * self.focal_length))


def project(
    points: Float[np.ndarray, "n 3"], frame: CameraFrame, intrinsics: Intrinsics
) -> tuple[Float[np.ndarray, "n 2"], Float[np.ndarray, " n"]]:
    """Central projection of world points (thesis section 3.2).

    Returns:
        pixel coordinates (u, v) and depth along the optical axis (m); points with depth <= 0 lie
        behind the camera and their (u, v) is meaningless.
    """
    c = frame.to_camera(points)
    depth = c[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u0, v0 = intrinsics.principal_point
        u = u0 + intrinsics.focal_px * c[:, 0] / depth
        v = v0 - intrinsics.focal_px * c[:, 1] / depth
    return np.stack([u, v], axis=-1), depth


def pixel_solid_angles(intrinsics: Intrinsics) -> Float[np.ndarray, "h w"]:
    """Solid angle (sr) of each pixel seen from the pinhole, exact for a flat rectangular pixel.

    A rectangle ``[0, x] x [0, y]`` of the image plane at distance f from the pinhole, with one
    corner at the foot of the optical axis, subtends ``F(x, y) = atan(x y / (f sqrt(x^2 + y^2 + f^2)))``
    (integrate ``f dx dy / (x^2 + y^2 + f^2)^(3/2)``); F is odd in x and in y, so a pixel
    ``[x0, x1] x [y0, y1]`` subtends ``F(x1, y1) - F(x0, y1) - F(x1, y0) + F(x0, y0)`` wherever it
    lies. For pixels small against f this is the familiar ``(p / f)^2 cos^3(theta)`` (theta the
    pixel centre's angle off the axis), which it matches to O((p / f)^2) relative. Round-off: the
    differences of F lose about ``1e-16 (f / p)^2 tan^2(half field)`` relative (1e-11 for the
    thesis's 4 mm pixels at f = 7 m, 1e-5 for 4 um pixels).

    Returns:
        (height, width) solid angles in sr, row v, column u (pixel (u, v) covers [u, u + 1) x [v, v + 1)).

    Args:
        intrinsics: the camera (:class:`Intrinsics`).

    Example:
        >>> import spacefit as sf
        >>> omega = sf.pixel_solid_angles(sf.Intrinsics(focal_length=0.05, pixel_pitch=1e-5, width=4, height=3))
        >>> omega.shape, f"{omega[1, 2]:.4g}"  # about (p / f)^2 sr near the axis
        ((3, 4), '4e-08')
    """
    check_type("intrinsics", intrinsics, Intrinsics, "an sf.Intrinsics")
    f, p = intrinsics.focal_length, intrinsics.pixel_pitch
    u0, v0 = intrinsics.principal_point
    x = (np.arange(intrinsics.width + 1) - u0) * p
    y = (np.arange(intrinsics.height + 1) - v0) * p
    xx, yy = np.meshgrid(x, y)
    corner = np.arctan(xx * yy / (f * np.sqrt(xx**2 + yy**2 + f**2)))
    return corner[1:, 1:] - corner[1:, :-1] - corner[:-1, 1:] + corner[:-1, :-1]
