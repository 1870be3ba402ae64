"""Attitude laws of a target's body: how the whole body points.

A real spacecraft points its body at the Earth or the sun; these laws say how, each a small frozen
dataclass checked on construction (:data:`ATTITUDES`; the conventions are
:mod:`spacefit.geometry.rotations`'): ``fixed`` (``target.attitude_deg``); ``nadir_sun``, a body axis
(default -z) to nadir and another (default +y) towards the sun as far as that allows, the frame of
lumos-sat and of :func:`spacefit.studies.observing.nadir_sun_frame` (z away from the Earth's centre, y
towards the sun projected; Fankhauser, Askari & Tyson 2023, AJ 166:59); ``sun``, a body axis (default
+z) to the sun and another (default +x) towards nadir as far as allowed; ``table``, quaternions over
time interpolated by spherical linear interpolation (Shoemake 1985, SIGGRAPH 19(3):245). The parts'
own articulation laws are :mod:`spacefit.geometry.articulation`.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from spacefit.errors import InputError, check_direction, check_vector, quote, read_text_rows
from spacefit.geometry.frames import attitude_matrix
from spacefit.geometry.rotations import check_not_parallel, quaternion_matrix, two_axis_rotation, unit_axis

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s)
    from jaxtyping import Float

ATTITUDES = ("fixed", "nadir_sun", "sun", "table")
# The columns of a quaternion table, scalar first.
QUATERNION_COLUMNS = ("time_utc", "qw", "qx", "qy", "qz")
# A quaternion's norm may differ from 1 by this much (rounding in a published table); it is normalised.
QUATERNION_NORM_TOLERANCE = 1e-3


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
        object.__setattr__(self, "nadir_axis", unit_axis("nadir_axis", self.nadir_axis))
        object.__setattr__(self, "sun_axis", unit_axis("sun_axis", self.sun_axis))
        check_not_parallel("sun_axis", np.asarray(self.sun_axis), "`nadir_axis`", np.asarray(self.nadir_axis))

    def rotation(self, nadir: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation for world directions towards ``nadir`` and towards the ``sun``.

        Raises:
            InputError: the sun at the target's nadir or zenith (the frame is undefined there)."""
        nadir, sun = check_direction("nadir", nadir), check_direction("sun", sun)
        check_not_parallel("sun", sun, "`nadir`", nadir)
        return two_axis_rotation(np.asarray(self.nadir_axis), nadir, np.asarray(self.sun_axis), sun)


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
        object.__setattr__(self, "sun_axis", unit_axis("sun_axis", self.sun_axis))
        object.__setattr__(self, "nadir_axis", unit_axis("nadir_axis", self.nadir_axis))
        check_not_parallel("nadir_axis", np.asarray(self.nadir_axis), "`sun_axis`", np.asarray(self.sun_axis))

    def rotation(self, nadir: Float[np.ndarray, "3"], sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation for world directions towards ``nadir`` and towards the ``sun``.

        Raises:
            InputError: the sun at the target's nadir or zenith (the turn about the sun is undefined there)."""
        nadir, sun = check_direction("nadir", nadir), check_direction("sun", sun)
        check_not_parallel("nadir", nadir, "`sun`", sun)
        return two_axis_rotation(np.asarray(self.sun_axis), sun, np.asarray(self.nadir_axis), nadir)


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
