"""The scene file's target: its pose and attitude law (``[target]``, :class:`TargetSettings`) and its
parts (``[parts.NAME]``, :class:`PartSettings`: a material, a mesh file or primitive of its own, an
articulation law), each checked on construction as every section is (:class:`~spacefit.scene.checks.Section`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_choice, check_direction, check_path, check_vector, inside, quote
from spacefit.geometry.articulation import Articulation, AxisAngle, Fixed, SunTracking
from spacefit.geometry.attitude import ATTITUDES, FixedAttitude, NadirSun, QuaternionTable, SunPointing, utc_seconds
from spacefit.geometry.frames import attitude_matrix
from spacefit.geometry.primitives import Primitive
from spacefit.geometry.rotations import PARALLEL_SINE
from spacefit.materials import MODELS, PRESETS, Material
from spacefit.scene.checks import Section, Vec3, check_position, plain

if TYPE_CHECKING:  # annotations only: jaxtyping's Array imports JAX (0.6 s)
    from jaxtyping import Float

# `target.mesh` of a target built only from its parts' primitives and files.
NO_MESH = "none"
# The values of `target.mesh` of the built-in lander, and those that name no file: the lander and no mesh.
BUILTIN = ("builtin", "")
MESHLESS = (*BUILTIN, NO_MESH)


@dataclass(frozen=True)
class TargetSettings(Section):
    """Target pose and geometry source: ``"builtin"`` (the lander), a mesh file whose groups are the
    parts, or ``"none"`` (:data:`NO_MESH`): only the parts given, each a primitive or a file of its own.

    ``attitude`` is the body's attitude law (:class:`NadirSun`, :class:`SunPointing`, :class:`QuaternionTable`): ``"fixed"`` (the
    default) at ``attitude_deg``; ``"nadir_sun"`` (body -z to ``nadir``, +y towards the sun as far as
    allowed) and ``"sun"`` (body +z to the sun, +x towards ``nadir`` as far as allowed), ``nadir`` the
    world direction towards the Earth's centre and the sun the scene's; ``"table"``, the file
    ``quaternions`` (``time_utc,qw,qx,qy,qz``) at ``time_utc``. ``attitude_deg`` counts for ``"fixed"`` only.

    Attributes:
        position_m: the body's origin in the world (m).
        attitude_deg: the body's attitude angles (deg) for ``attitude = "fixed"``.
        mesh: ``"builtin"``, a mesh file (OBJ, PLY) or ``"none"``.
        attitude: ``"fixed"``, ``"nadir_sun"``, ``"sun"`` or ``"table"``.
        nadir: the world direction towards the Earth's centre (``"nadir_sun"``, ``"sun"``).
        quaternions: the CSV file of ``"table"``.
        time_utc: the time (ISO 8601 UTC) the ``"table"`` is read at.

    Raises:
        InputError: a value outside its range or an unknown law, naming it (``target.attitude``).

    Example:
        >>> import spacefit as sf
        >>> sf.TargetSettings(attitude_deg=(0, 0, 30)).attitude_deg
        (0.0, 0.0, 30.0)
        >>> try:
        ...     sf.TargetSettings(attitude="spin")
        ... except sf.InputError as err:
        ...     print(err)
        `target.attitude` must be one of 'fixed', 'nadir_sun', 'sun', 'table'; got 'spin'.
    """

    position_m: Vec3 = (0.0, 0.0, 0.0)
    attitude_deg: Vec3 = (90.0, 0.0, 0.0)
    mesh: str = "builtin"
    attitude: str = "fixed"
    nadir: tuple[float, ...] = ()
    quaternions: str = ""
    time_utc: str = ""

    SECTION: ClassVar[str] = "target"
    # What each attitude law takes besides the scene's sun.
    TAKES: ClassVar[dict[str, tuple[str, ...]]] = {"fixed": (), "nadir_sun": ("nadir",), "sun": ("nadir",),
                                                   "table": ("quaternions", "time_utc")}

    def check(self) -> None:
        """Check this section's values (:class:`Section`)."""
        check_position("target.position_m", self.position_m)
        check_vector("target.attitude_deg", self.attitude_deg)
        check_choice("target.attitude", self.attitude, ATTITUDES)
        takes = self.TAKES[self.attitude]
        for key in ("nadir", "quaternions", "time_utc"):
            value = getattr(self, key)
            if key in takes and not value:
                raise InputError(f"`target.{key}` is missing: `target.attitude` = {self.attitude!r} takes "
                                 f"{' and '.join(takes)}.")
            if key not in takes and value:
                raise InputError(f"`target.{key}` = {quote(plain(value))} is not used by `target.attitude` = {self.attitude!r} "
                                 f"(it takes {' and '.join(takes) or 'attitude_deg'}).")
        default = TargetSettings.__dataclass_fields__["attitude_deg"].default
        if self.attitude != "fixed" and tuple(self.attitude_deg) != default:
            raise InputError(f"`target.attitude_deg` = {quote(plain(self.attitude_deg))} is not used by `target.attitude` = "
                             f"{self.attitude!r}, which sets the attitude; give `attitude = \"fixed\"` to place the body by angles.")
        if self.nadir:
            check_direction("target.nadir", self.nadir)
            object.__setattr__(self, "nadir", tuple(float(v) for v in self.nadir))
        if self.quaternions:
            check_path("target.quaternions", self.quaternions)
        if self.time_utc:
            utc_seconds("target.time_utc", self.time_utc)

    def attitude_law(self) -> FixedAttitude | NadirSun | SunPointing | QuaternionTable:
        """The body's attitude law (a quaternion table is read here)."""
        if self.attitude == "nadir_sun":
            return NadirSun()
        if self.attitude == "sun":
            return SunPointing()
        if self.attitude == "table":
            with inside("target"):
                return QuaternionTable.read(self.quaternions)
        return FixedAttitude(self.attitude_deg)

    def rotation(self, sun: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3 3"]:
        """The body-to-world rotation of the attitude law, ``sun`` the world direction towards the sun.

        Raises:
            InputError: the sun along ``target.nadir`` (nadir_sun, sun), a time outside the quaternion table."""
        law = self.attitude_law()
        if isinstance(law, (NadirSun, SunPointing)):
            nadir = check_direction("target.nadir", self.nadir)
            if np.linalg.norm(np.cross(nadir, sun)) < PARALLEL_SINE:
                raise InputError(f"`target.nadir` {list(self.nadir)} is along the sun's direction (`sun.direction` "
                                 f"{np.round(-np.asarray(sun), 6).tolist()}): with the sun at the target's zenith or nadir "
                                 f"`target.attitude` = {self.attitude!r} is undefined.")
            return law.rotation(nadir, sun)
        if isinstance(law, QuaternionTable):
            with inside("target"):
                return law.rotation(self.time_utc)
        return law.rotation()


@dataclass(frozen=True)
class PartSettings:
    """A part: its material (:class:`Conductor`, :class:`Lambert`, ... or a :data:`PRESETS` name), for a part of its own a mesh file or a
    primitive (a box, cylinder, ... table in the scene file), and its articulation law in the body
    (:class:`SunTracking`, :class:`AxisAngle`; fixed by default).

    Attributes:
        material: the part's material object.
        file: a mesh file (OBJ, PLY) of a part of its own, or empty.
        shape: a primitive shape of a part of its own, or None.
        articulation: how the part turns in the body.

    Raises:
        InputError: both a file and a shape, or a bad material or articulation.

    Example:
        >>> import spacefit as sf
        >>> sf.default_scene().parts["legs"].material
        Lambert(kd=0.2)
        >>> scene = sf.default_scene().with_values({"parts.legs.kd": 0.5})
        >>> scene.parts["legs"].material
        Lambert(kd=0.5)
    """

    material: Material
    file: str = ""
    shape: Primitive | None = None
    articulation: Articulation = Fixed()

    def __post_init__(self) -> None:
        if not isinstance(self.material, tuple(MODELS.values())):
            raise InputTypeError(f"`material` must be a spacefit material (sf.materials.Conductor, Mirror, Lambert; a "
                                 f"scene file names a preset), got {quote(self.material)}.")
        if not isinstance(self.file, str):
            raise InputTypeError(f"`file` must be a path string, got {quote(self.file)}.")
        if self.file:
            check_path("file", self.file)
        if self.shape is not None and not isinstance(self.shape, Primitive):
            raise InputTypeError(f"`shape` must be a spacefit.geometry.primitives.Primitive, got {quote(self.shape)}.")
        if self.shape is not None and self.file:
            raise InputError(f"a part takes a `file` or a `shape`, not both; got file {self.file!r} and shape "
                             f"{self.shape.shape!r}.")
        if not isinstance(self.articulation, (Fixed, SunTracking, AxisAngle)):
            raise InputTypeError(f"`articulation` must be a spacefit.geometry.articulation law (Fixed, SunTracking, AxisAngle), "
                                 f"got {quote(self.articulation)}.")
        if isinstance(self.articulation, SunTracking):
            self.articulation.check_normal(self.reference_normal(), "the part's normal (its +z in the body)")

    def reference_normal(self) -> Float[np.ndarray, "3"]:
        """The normal a sun-tracking part turns towards the sun: the part's own +z in the body frame (a
        plate's normal; a box's +z face; body +z for a mesh group or file)."""
        if self.shape is None:
            return np.array([0.0, 0.0, 1.0])
        return attitude_matrix(np.radians(self.shape.attitude_deg))[:, 2]


# The built-in lander's parts and their presets (thesis Table 4-2).
DEFAULT_PRESETS = {"body": "mli_thesis", "panels": "panel_thesis", "legs": "white_paint"}


def default_parts() -> dict[str, PartSettings]:
    """The built-in lander's parts, each with its preset material (:data:`DEFAULT_PRESETS`)."""
    return {name: PartSettings(PRESETS[preset]) for name, preset in DEFAULT_PRESETS.items()}
