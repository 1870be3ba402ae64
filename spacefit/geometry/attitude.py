"""Articulation laws of a target's parts and attitude laws of its body.

A real spacecraft turns its solar arrays towards the sun and points its body at the Earth; these
laws say how, each a small frozen dataclass checked on construction.

Conventions (docs/reference/conventions.md; those of :mod:`spacefit.geometry.frames`):

* A body attitude is a rotation R from the body frame to the world frame, ``p_world = R p_body +
  position``, as ``target.attitude_deg`` gives it (:func:`~spacefit.geometry.frames.attitude_matrix`).
* An angle ``a`` about a unit axis ``u`` is the rotation :func:`axis_rotation`: the thesis's
  convention, a right-handed rotation by ``-a`` (clockwise seen from the axis tip), so that the angle
  ``a`` about x, y, z is ``R1(a)``, ``R2(a)``, ``R3(a)`` of the attitude angles exactly.
* A quaternion ``(w, x, y, z)`` (scalar first, Hamilton's product) with ``w = cos(phi / 2)`` and
  ``(x, y, z) = sin(phi / 2) u`` is the right-handed rotation by ``phi`` about ``u``; as an attitude it
  maps body to world (its matrix is R above).

Part articulation (:data:`ARTICULATIONS`): ``fixed`` in the body; ``sun_tracking``, turned about a
body axis through a pivot by the angle that maximises ``n . s`` (n the part's normal, s the unit
direction towards the sun, both in the body frame): the normal's component across the axis is turned
onto the sun's (:func:`tracking_rotation`); where the sun lies along the axis every angle gives the
same ``n . s`` and the part keeps its placed attitude (angle 0); ``angle``, a given angle about the axis.

Body attitude (:data:`ATTITUDES`): ``fixed`` (``target.attitude_deg``); ``nadir_sun``, a body axis
(default -z) to nadir and another (default +y) towards the sun as far as that allows, the frame of
lumos-sat and of :func:`spacefit.studies.observing.nadir_sun_frame` (z away from the Earth's centre, y
towards the sun projected; Fankhauser, Askari & Tyson 2023, AJ 166:59); ``sun``, a body axis (default
+z) to the sun and another (default +x) towards nadir as far as allowed; ``table``, quaternions over
time interpolated by spherical linear interpolation (Shoemake 1985, SIGGRAPH 19(3):245).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from spacefit.errors import InputError, check_choice, check_direction, check_range, check_vector, inside, quote, read_text_rows
from spacefit.geometry.frames import attitude_matrix

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s)
    from jaxtyping import Float

ARTICULATIONS = ("fixed", "sun_tracking", "angle")
ATTITUDES = ("fixed", "nadir_sun", "sun", "table")
# Below this length of the sun's component across a tracking axis the sun lies along the axis: the part
# keeps its placed attitude (every angle gives the same n . s).
ALONG_AXIS = 1e-9
# Two directions this close to parallel (sine of their angle) leave a two-axis attitude undefined.
PARALLEL_SINE = 1e-6
# The columns of a quaternion table, scalar first.
QUATERNION_COLUMNS = ("time_utc", "qw", "qx", "qy", "qz")
# A quaternion's norm may differ from 1 by this much (rounding in a published table); it is normalised.
QUATERNION_NORM_TOLERANCE = 1e-3


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


def _unit(name: str, value: Any) -> tuple[float, float, float]:
    return tuple(check_direction(name, value).tolist())


def _not_parallel(name: str, a: np.ndarray, other: str, b: np.ndarray) -> None:
    if np.linalg.norm(np.cross(a, b)) < PARALLEL_SINE:
        raise InputError(f"`{name}` {np.round(a, 6).tolist()} must not be parallel to {other} {np.round(b, 6).tolist()}: "
                         "the rotation about it would be undefined.")


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
        object.__setattr__(self, "axis", _unit("axis", self.axis))
        object.__setattr__(self, "pivot_m", tuple(check_vector("pivot_m", self.pivot_m).tolist()))

    def check_normal(self, normal: Float[np.ndarray, "3"], name: str = "`normal`", axis_name: str = "axis") -> None:
        """Refuse a part ``normal`` along the axis: no turn about it moves the normal towards the sun
        (``name``, ``axis_name``: the normal and the axis as the message shows them)."""
        _not_parallel(axis_name, np.asarray(self.axis), name, np.asarray(normal, float))

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
        object.__setattr__(self, "axis", _unit("axis", self.axis))
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


def _two_axis(body1: np.ndarray, world1: np.ndarray, body2: np.ndarray, world2: np.ndarray) -> np.ndarray:
    """The rotation (body to world) taking ``body1`` onto ``world1`` and turning ``body2`` about it
    towards ``world2`` as far as allowed (the TRIAD construction; all unit, neither pair parallel)."""

    def triad(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        c = np.cross(a, b)
        c /= np.linalg.norm(c)
        return np.stack([a, c, np.cross(a, c)], axis=1)

    return triad(world1, world2) @ triad(body1, body2).T


@dataclass(frozen=True)
class FixedAttitude:
    """The body at the attitude ``attitude_deg`` (the convention of ``target.attitude_deg``)."""

    attitude_deg: tuple[float, float, float] = (90.0, 0.0, 0.0)

    KIND: ClassVar[str] = "fixed"

    def __post_init__(self) -> None:
        object.__setattr__(self, "attitude_deg", tuple(check_vector("attitude_deg", self.attitude_deg).tolist()))

    def rotation(self) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation."""
        return attitude_matrix(np.radians(self.attitude_deg))


@dataclass(frozen=True)
class NadirSun:
    """The body's ``nadir_axis`` to nadir and its ``sun_axis`` towards the sun as far as that allows
    (body frame; defaults: lumos-sat's frame, z away from the Earth's centre, y towards the sun).

    A scene's ``target.attitude = "nadir_sun"``, with ``target.nadir`` the world direction to nadir.

    Args:
        nadir_axis: the body axis pointed at nadir.
        sun_axis: the body axis turned towards the sun, not parallel to ``nadir_axis``.

    Raises:
        InputError: a zero axis, or two parallel ones.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> law = sf.NadirSun()
        >>> rotation = law.rotation(nadir=np.array([0.0, 0.0, -1.0]), sun=np.array([1.0, 0.0, 0.0]))
        >>> np.round(rotation @ np.array(law.sun_axis), 6)  # body +y turned to the sun
        array([1., 0., 0.])
    """

    nadir_axis: tuple[float, float, float] = (0.0, 0.0, -1.0)
    sun_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)

    KIND: ClassVar[str] = "nadir_sun"

    def __post_init__(self) -> None:
        object.__setattr__(self, "nadir_axis", _unit("nadir_axis", self.nadir_axis))
        object.__setattr__(self, "sun_axis", _unit("sun_axis", self.sun_axis))
        _not_parallel("sun_axis", np.asarray(self.sun_axis), "`nadir_axis`", np.asarray(self.nadir_axis))

    def rotation(self, nadir: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation for world directions towards ``nadir`` and towards the ``sun``.

        Raises:
            InputError: the sun at the target's nadir or zenith (the frame is undefined there)."""
        nadir, sun = check_direction("nadir", nadir), check_direction("sun", sun)
        _not_parallel("sun", sun, "`nadir`", nadir)
        return _two_axis(np.asarray(self.nadir_axis), nadir, np.asarray(self.sun_axis), sun)


@dataclass(frozen=True)
class SunPointing:
    """The body's ``sun_axis`` to the sun and its ``nadir_axis`` towards nadir as far as that allows
    (body frame; defaults +z and +x).

    A scene's ``target.attitude = "sun"``.

    Args:
        sun_axis: the body axis pointed at the sun.
        nadir_axis: the body axis turned towards nadir, not parallel to ``sun_axis``.

    Raises:
        InputError: a zero axis, or two parallel ones.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> law = sf.SunPointing()
        >>> rotation = law.rotation(nadir=np.array([0.0, 0.0, -1.0]), sun=np.array([1.0, 0.0, 0.0]))
        >>> np.round(rotation @ np.array(law.sun_axis), 6)  # body +z to the sun
        array([1., 0., 0.])
    """

    sun_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    nadir_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)

    KIND: ClassVar[str] = "sun"

    def __post_init__(self) -> None:
        object.__setattr__(self, "sun_axis", _unit("sun_axis", self.sun_axis))
        object.__setattr__(self, "nadir_axis", _unit("nadir_axis", self.nadir_axis))
        _not_parallel("nadir_axis", np.asarray(self.nadir_axis), "`sun_axis`", np.asarray(self.sun_axis))

    def rotation(self, nadir: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation for world directions towards ``nadir`` and towards the ``sun``.

        Raises:
            InputError: the sun at the target's nadir or zenith (the turn about the sun is undefined there)."""
        nadir, sun = check_direction("nadir", nadir), check_direction("sun", sun)
        _not_parallel("nadir", nadir, "`sun`", sun)
        return _two_axis(np.asarray(self.sun_axis), sun, np.asarray(self.nadir_axis), nadir)


def utc_seconds(name: str, text: str) -> float:
    """Seconds since 1970-01-01 UTC of an ISO 8601 UTC time (``2024-03-01T04:00:00``, a space for the
    ``T``, a trailing ``Z`` and fractions allowed; leap seconds not counted, as POSIX time)."""
    iso = str(text).strip().replace(" ", "T", 1)
    iso = iso[:-1] if iso.endswith(("Z", "z")) else iso
    try:
        time = dt.datetime.fromisoformat(iso)
    except ValueError:
        raise InputError(f"`{name}` must be an ISO 8601 time (UTC, 2024-03-01T04:00:00), got {quote(text)}.") from None
    if time.tzinfo is not None and time.utcoffset() != dt.timedelta(0):
        raise InputError(f"`{name}` must be a UTC time, got {quote(text)} (offset {time.utcoffset()}).")
    return time.replace(tzinfo=dt.timezone.utc).timestamp()


def quaternion_matrix(q: Float[np.ndarray, "... 4"]) -> Float[np.ndarray, "... 3 3"]:
    """The rotation matrix of unit quaternions ``(w, x, y, z)`` (module docstring: right-handed by phi about u)."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


@dataclass(frozen=True, eq=False)
class QuaternionTable:
    """The body's attitude over time: ``times_s`` (n,) seconds since 1970 UTC, increasing, and unit
    quaternions ``quaternions`` (n, 4), scalar first (body to world, the Conventions page), interpolated
    by spherical linear interpolation along the shorter arc; ``source`` names where they came from.

    A scene's ``target.attitude = "table"`` reads one from ``target.quaternions`` (:meth:`read`).

    Args:
        times_s: (n,) times, seconds since 1970 UTC, increasing.
        quaternions: (n, 4) unit quaternions (w, x, y, z), body to world.
        source: the file or name they came from, for messages.

    Raises:
        InputError: times that do not increase, or quaternions that are not (n, 4) unit ones.

    Example:
        >>> import numpy as np, spacefit as sf
        >>> table = sf.QuaternionTable(times_s=np.array([0.0, 10.0]), quaternions=np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0]]))
        >>> table.times_s
        array([ 0., 10.])
    """

    times_s: np.ndarray
    quaternions: np.ndarray
    source: str = "quaternions"

    KIND: ClassVar[str] = "table"

    def __post_init__(self) -> None:
        t = np.asarray(self.times_s, float)
        q = np.asarray(self.quaternions, float)
        if t.ndim != 1 or len(t) < 1 or q.shape != (len(t), 4):
            raise InputError(f"{self.source}: times (n,) and quaternions (n, 4) with n >= 1 rows are needed, got "
                             f"shapes {t.shape} and {q.shape}.")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
            raise InputError(f"{self.source}: times and quaternions must be finite.")
        if np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0))
            raise InputError(f"{self.source}: times must increase, but row {i + 2} is not later than row {i + 1}.")
        norm = np.linalg.norm(q, axis=1)
        if np.any(np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE):
            i = int(np.argmax(np.abs(norm - 1.0)))
            raise InputError(f"{self.source}: row {i + 1}'s quaternion {q[i].tolist()} has norm {norm[i]:.6g}; "
                             f"a unit quaternion is needed (within {QUATERNION_NORM_TOLERANCE:g}).")
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "quaternions", q / norm[:, None])

    @classmethod
    def read(cls, path: str | Path) -> QuaternionTable:
        """Read a CSV file with the header ``time_utc,qw,qx,qy,qz`` (:data:`QUATERNION_COLUMNS`, scalar
        first, in that order; ``#`` lines are comments), one ISO 8601 UTC time and quaternion a row.

        Raises:
            InputError: no such file, other columns, an unreadable value, times not increasing, a
                quaternion not of unit norm; each naming the file and row."""
        lines = read_text_rows("quaternions", path, "quaternion table")
        header = [c.strip() for c in lines[0].split(",")] if lines else []
        if tuple(header) != QUATERNION_COLUMNS:
            raise InputError(f"quaternion table {str(path)!r} must have the header {','.join(QUATERNION_COLUMNS)} (scalar first), "
                             f"got {','.join(header) or 'an empty file'}.")
        times, quaternions = [], []
        for row, line in enumerate(lines[1:], start=1):
            cells = [c.strip() for c in line.split(",")]
            if len(cells) != len(QUATERNION_COLUMNS):
                raise InputError(f"quaternion table {str(path)!r} row {row}: {len(cells)} values, {len(QUATERNION_COLUMNS)} needed.")
            times.append(utc_seconds(f"{path} row {row} time_utc", cells[0]))
            try:
                quaternions.append([float(c) for c in cells[1:]])
            except ValueError:
                raise InputError(f"quaternion table {str(path)!r} row {row}: the quaternion must be 4 numbers, got "
                                 f"{quote(cells[1:])}.") from None
        if not times:
            raise InputError(f"quaternion table {str(path)!r} has no rows.")
        return cls(np.array(times), np.array(quaternions), f"quaternion table {str(path)!r}")

    def quaternion(self, time_utc: str) -> Float[np.ndarray, "4"]:
        """The unit quaternion at ``time_utc`` (ISO 8601 UTC), by slerp between the rows around it.

        Raises:
            InputError: a time before the first row or after the last (no extrapolation)."""
        t = utc_seconds("time_utc", time_utc)
        first, last = self.times_s[0], self.times_s[-1]
        if not first <= t <= last:
            span = " to ".join(dt.datetime.fromtimestamp(s, dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S") for s in (first, last))
            raise InputError(f"`time_utc` {quote(time_utc)} is outside the {self.source}, which spans {span} UTC.")
        i = min(int(np.searchsorted(self.times_s, t, side="right")) - 1, len(self.times_s) - 2)
        if i < 0:  # one row: its time is the only one allowed
            return self.quaternions[0]
        q0, q1 = self.quaternions[i], self.quaternions[i + 1]
        if np.dot(q0, q1) < 0:  # q and -q are one rotation: take the shorter arc
            q1 = -q1
        f = (t - self.times_s[i]) / (self.times_s[i + 1] - self.times_s[i])
        angle = np.arccos(np.clip(np.dot(q0, q1), -1.0, 1.0))
        if angle < 1e-12:
            return q0
        q = (np.sin((1 - f) * angle) * q0 + np.sin(f * angle) * q1) / np.sin(angle)
        return q / np.linalg.norm(q)

    def rotation(self, time_utc: str) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation at ``time_utc`` (:meth:`quaternion`)."""
        return quaternion_matrix(self.quaternion(time_utc))
