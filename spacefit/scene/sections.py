"""The scene-file's sections: one frozen dataclass per section, each checked on construction.

A section coerces what a TOML file or Python gives (lists to tuples, integers to floats where a
number belongs) and checks every value before it exists, naming ``section.key``, the value and the
allowed range (:func:`spacefit.errors.check_range`): ``RenderSettings(spp=-1)`` raises at once. A
part's material is a :mod:`spacefit.materials` object from the start. The base and its checks are
:mod:`spacefit.scene.checks`; the target's sections (its pose, its parts) :mod:`spacefit.scene.target`.
The whole scene that joins them is :class:`Scene`; what the layers below it read of a scene is
:class:`SceneLike` (the parameter registry and the override language sit under the ``Scene`` class,
whose ``with_values`` is theirs). Reading a file is :mod:`spacefit.scene.toml`; changing values by
name is :mod:`spacefit.scene.overrides`.

Defaults are the thesis's Table 4-2. Units are in the key names: metres (``_m``), millimetres for
the optics as the thesis gives them (``_mm``), degrees at this user-facing edge only (``_deg``),
irradiance in W m^-2. The sun's ``direction`` is the direction the light travels.

The thesis's "light radiance 5 W m^-2 sr^-1" for its distant light is, in pbrt's convention, the
irradiance on a surface facing the light: ``sun.irradiance_w_m2 = 5``. ``"physical"`` selects the
total solar irradiance at 1 au, 1361 W m^-2 (Kopp & Lean 2011).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

from spacefit.errors import A_SCENE, InputError, InputTypeError, check_choice, check_direction, check_range, check_vector, closest, quote
from spacefit.geometry.articulation import SunTracking
from spacefit.geometry.wm import check_wm_params
from spacefit.scene.checks import MAX_COORDINATE_M, Section, Vec3, check_int, check_position
from spacefit.scene.sampling import SAMPLERS, check_sample_count
from spacefit.scene.target import PartSettings, TargetSettings

SOLAR_IRRADIANCE_W_M2 = 1361.0
# The differentiable variants: the bridge needs AD (scalar variants cannot render a Jacobian).
VARIANTS = ("auto", "llvm_ad_rgb", "cuda_ad_rgb")
# Mitsuba's pixel filters and how far (px) each spreads a sample: the tent's radius 1, the box's
# half pixel, the Gaussian's 4 standard deviations of 0.5 px.
FILTER_RADIUS_PX = {"tent": 1.0, "box": 0.5, "gaussian": 2.0}
FILTERS = tuple(FILTER_RADIUS_PX)
WRINKLE_MODELS = ("auto", "geometry", "effective")
# Radiance is float32 (at most 3.4e38) and a glint's BRDF can reach 1e6 or more: irradiances above
# this overflow it (1e39 rendered inf / NaN). The physical sun at 1 au is 1361 W m^-2.
MAX_IRRADIANCE_W_M2 = 1e20
# The camera's clipping distances (m): the near one is Mitsuba's default; the far one passes every
# distance within MAX_COORDINATE_M on each axis (Mitsuba's default, 1e4 m, rendered a target seen
# from 20 km with a long lens black).
NEAR_CLIP_M = 0.01
FAR_CLIP_M = 4.0 * MAX_COORDINATE_M
# Samples per pixel of one render: 65536 at 600 x 600 px is 2.4e10 samples, hours on a CPU; a fit's
# renders are not split into passes, so there the product with the pixels is bounded too
# (:func:`spacefit.rendering.memory.check_memory`).
MAX_SPP = 1 << 16
# Seeds are Mitsuba's (uint32): a fit adds offsets to its seeds, so they stay below 2^31.
MAX_SEED = 2**31 - 1
# Mitsuba's perspective camera takes a horizontal field of view in [0, 180] deg (180, or a focal
# length of 1e-200 mm, raises inside it); a pinhole's image grows as tan(fov / 2), and near 180 deg
# float32 rays lose the pixels at the edge. The vertical field of view is held to the same bound.
MAX_FOV_DEG = 179.0


@dataclass(frozen=True)
class RenderSettings(Section):
    """Image size (width, height px), samples per pixel, thesis trace depth, seed, backend, filter.

    ``depth`` is the thesis's (pbrt's) trace depth: the number of bounces after the camera ray's
    first hit; Mitsuba's ``max_depth`` is ``depth + 1``. Depth 1 is direct sun light only.

    ``deterministic`` makes a seed give a bitwise-identical image on the CPU: Mitsuba's film adds
    float32 samples from parallel threads in a varying order (differences about 1e-7 relative), so
    deterministic renders add them on one thread, in the samples' order (a render traces them on all
    threads first, and takes about the time of ``false``; the forward-mode derivative renders likewise,
    their samples traced on all threads, splatted on one). On CUDA images agree to that rounding only.

    ``sampler`` is Mitsuba's: ``multijitter`` (the default) stratifies each pixel's samples on a
    jittered grid, the lowest error at equal samples of the five measured (tied with ``orthogonal``,
    which takes fewer counts; the performance page). Each is unbiased and one seed gives one image. A
    count of samples that ``stratified``,
    ``ldsampler`` or ``orthogonal`` would round (:data:`SAMPLE_COUNTS`) is refused, here and at each
    render; ``multijitter`` renders one it would round as passes of counts it takes
    (:func:`split_sample_count`). None is rounded silently.

    Attributes:
        resolution: (width, height) px, each >= 1.
        spp: samples per pixel, in [1, 65536].
        depth: the trace depth (bounces after the first hit), >= 1.
        seed: the sampler's seed, >= 0.
        variant: Mitsuba variant, or ``"auto"`` (CUDA where there is a GPU, else LLVM).
        filter: Mitsuba's reconstruction filter (``"tent"``, ``"box"``, ``"gaussian"``).
        deterministic: add samples in one order (bitwise-identical images on the CPU).
        sampler: Mitsuba's sampler.

    Raises:
        InputError: a value outside its range, naming it as a scene-file key (``render.spp``).

    Example:
        >>> import spacefit as sf
        >>> sf.default_scene().render.spp
        20
        >>> try:
        ...     sf.RenderSettings(spp=0)
        ... except sf.InputError as err:
        ...     print(err)
        `render.spp` must be in [1, 65536], got 0.
    """

    resolution: tuple[int, int] = (600, 600)
    spp: int = 20
    depth: int = 2
    seed: int = 0
    variant: str = "auto"
    filter: str = "tent"
    deterministic: bool = True
    sampler: str = "multijitter"

    SECTION: ClassVar[str] = "render"

    def check(self) -> None:
        """Check this section's values (:class:`Section`)."""
        for i, axis in enumerate(("width", "height")):
            check_int(f"render.resolution ({axis})", self.resolution[i], 1, 16384)
        check_int("render.spp", self.spp, 1, MAX_SPP)
        check_int("render.depth", self.depth, 1, 64)
        check_int("render.seed", self.seed, 0, MAX_SEED)
        check_choice("render.variant", self.variant, VARIANTS)
        check_choice("render.filter", self.filter, FILTERS)
        check_choice("render.sampler", self.sampler, SAMPLERS)
        check_sample_count("render.spp", self.spp, self.sampler)


@dataclass(frozen=True)
class CameraSettings(Section):
    """Pinhole camera: optics in mm as in Table 4-2, pose by attitude or by ``look_at_m``.

    ``principal_offset_px`` moves the principal point from the image centre (u right, v down).
    When ``look_at_m`` holds 3 numbers it replaces ``attitude_deg``, with ``up`` as image up.
    ``roll_deg`` then turns the camera about its optical axis, in either mode (right-handed about the
    viewing direction: image up turns towards image right, the scene turns anticlockwise in the image).

    The field of view is set one of two ways. ``fov_deg`` = 0 (the default): by the pixel pitch, and
    a change of ``render.resolution`` alone keeps the pitch, so fewer pixels see a narrower field.
    ``fov_deg`` > 0: the horizontal field of view of the whole film, and the pixel pitch follows,
    ``pixel_pitch_mm = 2 focal_length_mm tan(fov_deg / 2) / width`` (:class:`Scene` sets it), so a
    change of resolution keeps the field and scales the pixels. A scene file's ``[camera]`` (or one
    ``with_values`` call) gives one of the two; setting one later (``with_values``, ``--set``)
    replaces the other, and ``to_toml`` writes the one that sets the field.

    Attributes:
        focal_length_mm: focal length (mm), > 0.
        pixel_pitch_mm: the pixels' side (mm), > 0.
        fov_deg: horizontal field of view (deg), 0 (set by the pitch) or in (0, 180).
        principal_offset_px: the principal point's offset (px).
        position_m: the pinhole's position in the world (m).
        attitude_deg: the camera's attitude angles (deg), used without ``look_at_m``.
        look_at_m: a world point (m) the camera looks at, or empty.
        up: the world direction that is image up with ``look_at_m``.
        roll_deg: turn about the optical axis (deg).

    Raises:
        InputError: a value outside its range, naming it as a scene-file key (``camera.focal_length_mm``).

    Example:
        >>> import spacefit as sf
        >>> camera = sf.CameraSettings(position_m=(0, 0, 50), look_at_m=(0, 0, 0))
        >>> camera.position_m
        (0.0, 0.0, 50.0)
        >>> sf.default_scene().with_values({"camera.position_m": [0, 0, 50]}).camera.position_m
        (0.0, 0.0, 50.0)
    """

    focal_length_mm: float = 7000.0
    pixel_pitch_mm: float = 4.0
    fov_deg: float = 0.0
    principal_offset_px: tuple[float, float] = (0.0, 0.0)
    position_m: Vec3 = (0.0, 0.0, 70.0)
    attitude_deg: Vec3 = (0.0, 0.0, 0.0)
    look_at_m: tuple[float, ...] = ()
    up: Vec3 = (0.0, 1.0, 0.0)
    roll_deg: float = 0.0

    SECTION: ClassVar[str] = "camera"

    def check(self) -> None:
        """Check this section's values (:class:`Section`)."""
        check_range("camera.focal_length_mm", self.focal_length_mm, 0.0, lo_open=True, unit="mm")
        check_range("camera.pixel_pitch_mm", self.pixel_pitch_mm, 0.0, lo_open=True, unit="mm")
        check_range("camera.fov_deg", self.fov_deg, 0.0, MAX_FOV_DEG, unit="deg")
        check_vector("camera.principal_offset_px", self.principal_offset_px, 2)
        check_position("camera.position_m", self.position_m)
        check_vector("camera.attitude_deg", self.attitude_deg)
        if len(self.look_at_m) not in (0, 3):
            raise InputError(f"`camera.look_at_m` must be empty or 3 numbers, got {list(self.look_at_m)}.")
        if self.look_at_m:
            check_position("camera.look_at_m", self.look_at_m)
        check_direction("camera.up", self.up)
        check_range("camera.roll_deg", self.roll_deg, unit="deg")


@dataclass(frozen=True)
class SunSettings(Section):
    """One distant sun: irradiance on a surface facing it (W m^-2) and direction of travel.

    Scene files may give the direction as ``elevation_deg`` and ``azimuth_deg`` in the target's frame
    instead (the parameters ``sun.elevation_deg`` and ``sun.azimuth_deg``).

    Attributes:
        irradiance_w_m2: irradiance (W m^-2) on a surface facing the sun, > 0.
        direction: the direction the light travels (world frame, any length but 0).

    Raises:
        InputError: a value outside its range, naming it (``sun.irradiance_w_m2``).

    Example:
        >>> import spacefit as sf
        >>> sf.SunSettings()
        SunSettings(irradiance_w_m2=5.0, direction=(0.0, 0.0, -1.0))
        >>> scene = sf.default_scene().with_values({"sun.elevation_deg": 30})
        >>> [round(x, 3) for x in scene.sun.direction]
        [-0.866, -0.0, -0.5]
    """

    irradiance_w_m2: float = 5.0
    direction: Vec3 = (0.0, 0.0, -1.0)

    SECTION: ClassVar[str] = "sun"

    def __post_init__(self) -> None:
        if isinstance(self.irradiance_w_m2, str) and self.irradiance_w_m2 == "physical":
            object.__setattr__(self, "irradiance_w_m2", SOLAR_IRRADIANCE_W_M2)
        super().__post_init__()

    def check(self) -> None:
        """Check this section's values (:class:`Section`)."""
        check_range("sun.irradiance_w_m2", self.irradiance_w_m2, 0.0, MAX_IRRADIANCE_W_M2, lo_open=True, unit="W m^-2")
        check_direction("sun.direction", self.direction)


@dataclass(frozen=True)
class WrinkleSettings(Section):
    """W-M wrinkles (thesis eq. 2-1, section 2.2) on the named parts; lengths in metres.

    D, gamma, M, L and Ls are the thesis's values. Its G = 10 read in metres, like L and Ls, gives
    an rms height of 0.27 m on a 1.4 m body and an rms slope of 37 (spikes like hair; the body
    folds over itself), and no common unit for all lengths changes the slope. The default G is
    1e-5 m, the thesis's "10" read as micrometres with L and Ls in metres: rms height 4.3 mm, rms
    slope 0.59, inside :data:`MLI_SLOPE_RANGE` (crumpled foil). The literal
    reading is kept as the scene ``data/scenes/thesis-literal.toml`` (docs/explanation/wrinkles.md).

    ``spacing_m`` is the refinement density: the distance between the sample points that carry
    heights (the thesis's sampling grid inside each triangle).

    ``model`` chooses how wrinkles are rendered: ``"geometry"`` displaces a refined mesh, the
    thesis's way; ``"effective"`` keeps the flat mesh and widens the part's microfacet roughness by
    the wrinkles' slopes; ``"auto"`` (default)
    takes the effective model, cheaper and far less noisy, where a pixel at the part spans at least
    ``lod_footprint`` times the largest wrinkle (L) and the wrinkles are gentle enough for a
    roughness, and the geometry otherwise. The default ``lod_footprint`` is where the level of
    detail study measured the effective model within 15 % of
    the geometry (docs/explanation/level-of-detail.md). Fits render the geometry for ``"auto"``.

    Attributes:
        enabled: whether any part is wrinkled.
        parts: the wrinkled parts.
        D: fractal dimension, in (2, 3).
        G: height scale (m), > 0.
        gamma: the frequencies' ratio, > 1.
        M: the number of ridge directions, >= 1.
        L, Ls: the longest and the cut-off wavelength (m), 0 < Ls < L.
        seed: the random phases' seed.
        spacing_m: the refinement density (m), > 0.
        model: ``"geometry"``, ``"effective"`` or ``"auto"``.
        lod_footprint: the pixel footprint, in units of L, above which ``"auto"`` takes the effective model.

    Raises:
        InputError: a value outside its range, naming it (``wrinkles.D``).

    Example:
        >>> import spacefit as sf
        >>> w = sf.default_scene().wrinkles
        >>> w.D, w.G
        (2.3, 1e-05)
        >>> f"{sf.wm_rms(w.D, w.G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls):.2g} m"
        '0.0043 m'
    """

    enabled: bool = True
    parts: tuple[str, ...] = ("body",)
    D: float = 2.3
    G: float = 1e-5
    gamma: float = 1.5
    M: int = 5
    L: float = 0.1
    Ls: float = 5e-3
    seed: int = 0
    spacing_m: float = 0.02
    model: str = "auto"
    lod_footprint: float = 3.0

    SECTION: ClassVar[str] = "wrinkles"

    def check(self) -> None:
        """Check this section's values (:class:`Section`)."""
        check_wm_params(self.D, self.G, self.gamma, self.M, self.L, self.Ls)
        check_int("wrinkles.seed", self.seed, 0, MAX_SEED)
        check_range("wrinkles.spacing_m", self.spacing_m, 0.0, lo_open=True, unit="m")
        check_choice("wrinkles.model", self.model, WRINKLE_MODELS)
        check_range("wrinkles.lod_footprint", self.lod_footprint, 0.0, lo_open=True)


SECTIONS: Mapping[str, type[Section]] = {
    "render": RenderSettings,
    "camera": CameraSettings,
    "sun": SunSettings,
    "target": TargetSettings,
    "wrinkles": WrinkleSettings,
}


@runtime_checkable
class SceneLike(Protocol):
    """A whole scene as the layers under :class:`Scene` read it: its sections,
    its parts, and a checked copy with values set by name (the ``Scene`` class is the one implementation)."""

    # Read-only members (properties): the frozen Scene's attributes cannot be set, which a plain
    # attribute in a Protocol would demand (mypy refused sf.available_parameters(scene) for it).
    @property
    def render(self) -> RenderSettings: ...
    @property
    def camera(self) -> CameraSettings: ...
    @property
    def sun(self) -> SunSettings: ...
    @property
    def target(self) -> TargetSettings: ...
    @property
    def wrinkles(self) -> WrinkleSettings: ...
    @property
    def parts(self) -> Mapping[str, PartSettings]: ...

    def with_values(self, values: Mapping[str, Any]) -> SceneLike:
        """A checked copy with values replaced by name."""
        ...


def sun_followers(scene: SceneLike) -> list[str]:
    """What the scene turns by its sun when it is assembled: its sun-tracking parts (``parts.<name>``) and
    its target where the attitude law follows the sun (``target``); a sun moved in place would leave them."""
    parts = [f"parts.{name}" for name, p in scene.parts.items() if isinstance(p.articulation, SunTracking)]
    return [*parts, *(["target"] if scene.target.attitude in ("nadir_sun", "sun") else [])]


def check_scene(scene: object, name: str = "scene") -> SceneLike:
    """Raise :class:`InputTypeError` unless ``scene`` is a scene (:class:`Scene`)."""
    if not isinstance(scene, SceneLike):
        raise InputTypeError(f"`{name}` must be {A_SCENE}, got {quote(scene)}.")
    return scene


def unknown_part(key: str, parts: Sequence[str]) -> InputError:
    """The error for a name ``parts.P...`` whose part P the scene lacks, suggesting the closest part."""
    path = key.split(".")
    close = closest(path[1], parts)
    hint = f" Did you mean `{'.'.join(['parts', close, *path[2:]])}`?" if close else ""
    return InputError(f"unknown scene key `{key}`: `{path[1]}` is not a part of the scene (parts: {', '.join(parts)}).{hint}")


