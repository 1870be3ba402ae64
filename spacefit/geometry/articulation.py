"""Articulation laws of a target's parts: how a part moves in the body.

A real spacecraft turns its solar arrays towards the sun; these laws say how, each a small frozen
dataclass checked on construction (:data:`ARTICULATIONS`): ``fixed`` in the body; ``sun_tracking``,
turned about a body axis through a pivot so that its normal faces the sun as closely as that turn
allows (:func:`~spacefit.geometry.rotations.tracking_rotation`); ``angle``, a given angle about the
axis (:func:`~spacefit.geometry.rotations.axis_rotation`; the conventions are
:mod:`spacefit.geometry.rotations`'). The body's own attitude laws are :mod:`spacefit.geometry.attitude`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from spacefit.errors import InputError, check_choice, check_direction, check_range, check_vector, inside, quote
from spacefit.geometry.rotations import axis_rotation, check_not_parallel, tracking_rotation, unit_axis

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s)
    from jaxtyping import Float

ARTICULATIONS = ("fixed", "sun_tracking", "angle")


@dataclass(frozen=True)
class Fixed:
    """A part fixed in the body frame (the default)."""

    KIND: ClassVar[str] = "fixed"

    def rotation(self, normal: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The part's turn in the body frame: none."""
        return np.eye(3)

    def table(self) -> dict[str, Any]:
        """The law as a scene file's part table states it (nothing: the default)."""
        return {}


@dataclass(frozen=True)
class SunTracking:
    """A part turned about the body ``axis`` through ``pivot_m`` (body frame, m) so that its normal faces
    the sun as closely as that rotation allows (:func:`tracking_rotation`), as solar arrays are.

    A scene file gives it in a part's table: ``articulation = "sun_tracking"``, ``axis = [1, 0, 0]``.

    Args:
        axis: the rotation axis in the body frame (any length but 0).
        pivot_m: a point on the axis (body frame, m).

    Raises:
        InputError: a zero or non-finite axis or pivot.

    Example:
        >>> import spacefit as sf
        >>> sf.SunTracking(axis=(1, 0, 0))
        SunTracking(axis=(1.0, 0.0, 0.0), pivot_m=(0.0, 0.0, 0.0))
    """

    axis: tuple[float, float, float]
    pivot_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    KIND: ClassVar[str] = "sun_tracking"

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis", unit_axis("axis", self.axis))
        object.__setattr__(self, "pivot_m", tuple(check_vector("pivot_m", self.pivot_m).tolist()))

    def check_normal(self, normal: Float[np.ndarray, "3"], name: str = "`normal`", axis_name: str = "axis") -> None:
        """Refuse a part ``normal`` along the axis: no turn about it moves the normal towards the sun
        (``name``, ``axis_name``: the normal and the axis as the message shows them)."""
        check_not_parallel(axis_name, np.asarray(self.axis), name, np.asarray(normal, float))

    def rotation(self, normal: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The part's turn in the body frame for the unit direction ``sun`` towards the sun (body frame)."""
        self.check_normal(normal)
        return tracking_rotation(np.asarray(self.axis), np.asarray(normal, float), check_direction("sun", sun))

    def table(self) -> dict[str, Any]:
        """The law as a scene file's part table states it."""
        return {"articulation": self.KIND, "axis": list(self.axis), "pivot_m": list(self.pivot_m)}


@dataclass(frozen=True)
class AxisAngle:
    """A part turned by ``angle_deg`` about the body ``axis`` through ``pivot_m`` (body frame, m), in
    spacefit's convention (:func:`axis_rotation`).

    Args:
        axis: the rotation axis in the body frame (any length but 0).
        angle_deg: the turn (deg), right-handed about ``axis``.
        pivot_m: a point on the axis (body frame, m).

    Raises:
        InputError: a zero or non-finite axis, pivot or angle.

    Example:
        >>> import spacefit as sf
        >>> sf.AxisAngle(axis=(0, 0, 1), angle_deg=30)
        AxisAngle(axis=(0.0, 0.0, 1.0), angle_deg=30.0, pivot_m=(0.0, 0.0, 0.0))
    """

    axis: tuple[float, float, float]
    angle_deg: float
    pivot_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    KIND: ClassVar[str] = "angle"

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis", unit_axis("axis", self.axis))
        object.__setattr__(self, "angle_deg", check_range("angle_deg", self.angle_deg, -360.0, 360.0, unit="deg"))
        object.__setattr__(self, "pivot_m", tuple(check_vector("pivot_m", self.pivot_m).tolist()))

    def rotation(self, normal: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The part's turn in the body frame (the sun's direction does not matter)."""
        return axis_rotation(np.asarray(self.axis), np.radians(self.angle_deg))

    def table(self) -> dict[str, Any]:
        """The law as a scene file's part table states it."""
        return {"articulation": self.KIND, "axis": list(self.axis), "angle_deg": self.angle_deg, "pivot_m": list(self.pivot_m)}


Articulation = Fixed | SunTracking | AxisAngle


# The keys of a part table that give its articulation, and those each law takes (``pivot_m`` optional).
ARTICULATION_KEYS = ("articulation", "axis", "angle_deg", "pivot_m")
_TAKES = {"fixed": (), "sun_tracking": ("axis",), "angle": ("axis", "angle_deg")}


def articulation(kind: str, axis: Any = None, angle_deg: Any = None, pivot_m: Any = None,
                 default_pivot_m: Any = (0.0, 0.0, 0.0)) -> Articulation:
    """The articulation law ``kind`` (one of :data:`ARTICULATIONS`) with what it takes: ``axis`` for
    ``sun_tracking`` and ``angle``, ``angle_deg`` for ``angle``, ``pivot_m`` for either (default
    ``default_pivot_m``); a key the law does not take is refused.

    Raises:
        InputError: an unknown kind, a missing or unused key, or a value out of range, naming it."""
    check_choice("articulation", kind, ARTICULATIONS)
    takes = _TAKES[kind]
    given = {"axis": axis, "angle_deg": angle_deg, "pivot_m": pivot_m}
    for key, value in given.items():
        if key in takes and value is None:
            raise InputError(f"`{key}` is missing: articulation {kind!r} takes {' and '.join(takes)}.")
        if key not in takes and value is not None and (key != "pivot_m" or kind == "fixed"):
            raise InputError(f"`{key}` = {quote(value)} is not a key of articulation {kind!r} "
                             f"(it takes {' and '.join(takes) or 'none'}{', and pivot_m' if takes else ''}).")
    pivot = default_pivot_m if pivot_m is None else pivot_m
    if kind == "fixed":
        return Fixed()
    if kind == "sun_tracking":
        return SunTracking(axis, pivot)
    return AxisAngle(axis, angle_deg, pivot)


def pop_articulation(table: dict[str, Any], where: str, old: Articulation | None = None,
                     default_pivot_m: Any = (0.0, 0.0, 0.0)) -> Articulation:
    """Take a part table's articulation keys (:data:`ARTICULATION_KEYS`) out of ``table``: the part's
    law (keys not given keep ``old``'s values while its kind stays; a new kind keeps only its pivot),
    ``old`` (or :class:`Fixed`) when none is given; the pivot defaults to ``default_pivot_m``.

    Raises:
        InputError: for an axis, angle or pivot without an ``articulation``, or a value the law refuses,
            naming ``where.key``.
    """
    given = {key: table.pop(key) for key in ARTICULATION_KEYS if key in table}
    if not given:
        return old if old is not None else Fixed()
    if old is not None and not isinstance(old, Fixed):
        kind = given.get("articulation", old.KIND)
        kept = old.table() if kind == old.KIND else {} if kind == "fixed" else {"pivot_m": list(old.pivot_m)}
        given = {**kept, **given}
    if "articulation" not in given:
        raise InputError(f"`{where}.articulation` is missing: {', '.join(given)} belong to an articulation "
                         f"(one of {', '.join(ARTICULATIONS)}).")
    with inside(where):
        return articulation(given.pop("articulation"), default_pivot_m=default_pivot_m, **given)
