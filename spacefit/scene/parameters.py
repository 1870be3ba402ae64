"""The registry of free parameters: one home for every fittable (and sweepable) scene value.

Each :class:`Parameter` knows its name pattern, unit, valid range and the bijection a solver works
through, its finite-difference step (or 0 for forward-mode AD), the scene-file keys it replaces,
and, for materials, the Mitsuba BSDF fields it sets. The CLI's help, the error messages and the
README's table (:func:`parameter_table`) are generated from it.

Names address the scene file's keys: ``wrinkles.D``; ``parts.P.alpha_x`` for part ``P``;
``sun.elevation_deg``. The sun's angles give the direction towards it,
(cos el cos az, cos el sin az, sin el); the light travels the opposite way (the scene's
``sun.direction``). Like the scene file, they are in degrees.

``image.*`` are nuisances of the image formation (an exposure scale, an offset, a Gaussian PSF, a
sub-pixel shift): a fit applies them to the render in JAX (:mod:`spacefit.fitting.nuisance`), so
they are fit-only names; a render or a sweep refuses them. Without them free, none is applied. Each
may be one per observation of a joint fit (:attr:`Parameter.per_observation`): ``image.scale@k`` is
observation k's alone (k from 0, in the order the observations are given), ``image.scale`` one
shared by all (:func:`observation_name`). Together with the target's pose (``target.attitude_*_deg``,
``target.position_*_m``) and the camera's roll about its optical axis (``camera.roll_deg``) they are
a fit's nuisance parameters (:data:`NUISANCES`), reported apart from the materials.

``wrinkles.rms_m`` is the expected rms height of eq. 2-1 (:func:`spacefit.geometry.wm.wm_rms`). In an
image D and G trade off along a valley of nearly constant rms height; (D, rms) are the better
determined coordinates (:func:`rms_of`, :func:`G_of` are the one place the two are converted).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from spacefit.errors import InputError, check_choice
from spacefit.precision import float64
from spacefit.geometry.wm import wm_G_from_rms, wm_rms
from spacefit.materials import Conductor, Lambert, Material, Mirror, make_material
from spacefit.scene.config import Scene, WrinkleSettings


@dataclass(frozen=True)
class Bijection:
    """Map from the real line onto the open interval (lo, hi): logistic if bounded, exp if bounded
    below only, the identity on the whole line (lo = -inf)."""

    lo: float
    hi: float = math.inf

    def forward(self, u: Array) -> Array:
        """Unconstrained -> physical."""
        if math.isinf(self.lo):
            return u
        if math.isinf(self.hi):
            return self.lo + jnp.exp(u)
        return self.lo + (self.hi - self.lo) * jax.nn.sigmoid(u)

    def inverse(self, x: Array) -> Array:
        """Physical -> unconstrained (x must lie strictly inside the interval)."""
        if math.isinf(self.lo):
            return x
        if math.isinf(self.hi):
            return jnp.log(x - self.lo)
        p = (x - self.lo) / (self.hi - self.lo)
        return jnp.log(p) - jnp.log1p(-p)

    def contains(self, x: float) -> bool:
        """Whether x is strictly inside the interval (a valid start)."""
        return bool(np.isfinite(x) and self.lo < x < self.hi)

    def at_bound(self, x: float, tolerance: float = 1e-3) -> str | None:
        """"lower" or "upper" when x lies within ``tolerance`` (a fraction of the width) of a bound
        of a bounded interval, where the logistic saturates and the parameter stops moving."""
        if math.isinf(self.lo) or math.isinf(self.hi):
            return None
        p = (x - self.lo) / (self.hi - self.lo)
        return "lower" if p < tolerance else "upper" if p > 1.0 - tolerance else None

    def describe(self) -> str:
        """The interval as text, e.g. ``(0, 1)``."""
        return f"({self.lo:g}, {self.hi:g})"


UNIT = Bijection(0.0, 1.0)
POSITIVE = Bijection(0.0)
# GGX roughness below 1e-4 is a mirror in float32 and Mitsuba's GGX evaluates to NaN there.
ROUGHNESS = Bijection(1e-4, 1.0)
# The widest Gaussian PSF (sigma, px) a fit may try; its kernel reaches out to 5 sigma.
PSF_SIGMA_MAX_PX = 4.0


@dataclass(frozen=True)
class Parameter:
    """One kind of free parameter.

    Attributes:
        pattern: its name, ``P`` standing for a part name (``parts.P.alpha_x``).
        unit: SI unit ("1" for dimensionless; degrees at the user-facing edge, as in the scene file).
        bijection: the map from the solver's unconstrained coordinate onto the valid range.
        doc: what it sets, in words.
        fd_step: central finite-difference step of its Jacobian column (0: a forward-mode AD render).
            Geometry columns come from finite differences with common random numbers (the AD
            integrators' derivatives in vertex positions are biased, README); the sun's frame is
            set as a whole transform. Larger steps than usual: the columns' Monte Carlo noise falls
            as 1 / step (README), the truncation error of these smooth maps is small.
        relative_step: ``fd_step`` is relative to the parameter's value.
        materials: for ``parts.P.*``, the material types that have it (grey values only).
        bsdf_fields: for ``parts.P.*``, the Mitsuba BSDF fields it sets.
        scene_fields: the scene-file fields it replaces (default: its own).
        per_observation: a joint fit may free it once per observation (``image.scale@k``).
    """

    pattern: str
    unit: str
    bijection: Bijection
    doc: str
    fd_step: float = 0.0
    relative_step: bool = False
    materials: tuple[type, ...] = ()
    bsdf_fields: tuple[str, ...] = ()
    scene_fields: tuple[str, ...] = ()
    per_observation: bool = False

    @property
    def field(self) -> str:
        """The last component of the name (``alpha_x``)."""
        return self.pattern.rsplit(".", 1)[-1]

    def applies_to(self, material: Material) -> bool:
        """Whether a part of this material has this parameter (grey, i.e. scalar, values only)."""
        if not isinstance(material, self.materials):
            return False
        value = getattr(material, "alpha_x" if self.field == "alpha" else self.field)
        return not isinstance(value, tuple)


_CONDUCTORS = (Conductor, Mirror)
PARAMETERS: dict[str, Parameter] = {p.pattern: p for p in (
    Parameter("wrinkles.D", "1", Bijection(2.0, 3.0), "W-M fractal dimension (eq. 2-1): vertex positions of every wrinkled part",
              fd_step=0.02),
    Parameter("wrinkles.G", "m", POSITIVE, "W-M height scale (eq. 2-1): vertex positions of every wrinkled part",
              fd_step=0.01, relative_step=True),
    Parameter("wrinkles.rms_m", "m", POSITIVE, "rms height of the wrinkles: sets G at the current D",
              fd_step=0.03, relative_step=True, scene_fields=("G",)),
    Parameter("parts.P.alpha_x", "1", ROUGHNESS, "GGX roughness along the part's tangent axis",
              materials=(Conductor,), bsdf_fields=("alpha_u",)),
    Parameter("parts.P.alpha_y", "1", ROUGHNESS, "GGX roughness across the part's tangent axis",
              materials=(Conductor,), bsdf_fields=("alpha_v",)),
    Parameter("parts.P.alpha", "1", ROUGHNESS, "both roughnesses, tied (isotropic)",
              materials=(Conductor,), bsdf_fields=("alpha_u", "alpha_v"), scene_fields=("alpha_x", "alpha_y")),
    Parameter("parts.P.eta", "1", POSITIVE, "real part of the conductor's refractive index (grey)",
              materials=_CONDUCTORS, bsdf_fields=("eta",)),
    Parameter("parts.P.k", "1", POSITIVE, "imaginary part of the conductor's refractive index (grey)",
              materials=_CONDUCTORS, bsdf_fields=("k",)),
    Parameter("parts.P.kd", "1", UNIT, "Lambert albedo (grey)", materials=(Lambert,), bsdf_fields=("reflectance",)),
    Parameter("sun.irradiance_w_m2", "W m^-2", POSITIVE, "the sun's irradiance on a surface facing it"),
    Parameter("sun.elevation_deg", "deg", Bijection(-90.0, 90.0), "elevation of the direction towards the sun above world xy",
              fd_step=0.5, scene_fields=("direction",)),
    Parameter("sun.azimuth_deg", "deg", Bijection(-math.inf), "azimuth of the direction towards the sun, world +x to +y",
              fd_step=0.5, scene_fields=("direction",)),
    *(Parameter(f"target.attitude_{axis}_deg", "deg", Bijection(-math.inf),
                f"the target's attitude angle {name} (about object {axis}, thesis 3.2): every vertex",
                fd_step=0.5, scene_fields=("attitude_deg",)) for axis, name in zip("xyz", ("alpha", "beta", "gamma"))),
    *(Parameter(f"target.position_{axis}_m", "m", Bijection(-math.inf), f"the target's world {axis} position: every vertex",
                fd_step=0.02, scene_fields=("position_m",)) for axis in "xyz"),
    Parameter("camera.roll_deg", "deg", Bijection(-math.inf),
              "the camera's turn about its optical axis (image up towards image right), either camera mode", fd_step=0.5),
    Parameter("image.scale", "1", POSITIVE, "exposure scale: the render times it (fit only, after the render; default 1)",
              per_observation=True),
    Parameter("image.offset_w_m2_sr", "W m^-2 sr^-1", Bijection(-math.inf), "offset added to every pixel (fit only; default 0)",
              per_observation=True),
    Parameter("image.blur_sigma_px", "px", Bijection(0.0, PSF_SIGMA_MAX_PX),
              "sigma of a continuous Gaussian blur, before the pixel (fit only; no blur unless free; start 0.5)", per_observation=True),
    *(Parameter(f"image.shift_{axis}_px", "px", Bijection(-math.inf),
                f"sub-pixel shift of the image towards +{axis} ({where}), by a Fourier phase (fit only; default 0)",
                per_observation=True)
      for axis, where in (("x", "columns, rightwards"), ("y", "rows, downwards"))),
)}
GEOMETRY = ("wrinkles.D", "wrinkles.G", "wrinkles.rms_m")
SUN_ANGLES = ("sun.elevation_deg", "sun.azimuth_deg")
ATTITUDE = ("target.attitude_x_deg", "target.attitude_y_deg", "target.attitude_z_deg")
POSITION = ("target.position_x_m", "target.position_y_m", "target.position_z_m")
ROLL = "camera.roll_deg"
# Parameters that move vertices (or the camera about them): a render of them needs the whole film, not the target's window.
MOVES_VERTICES = (*GEOMETRY, *ATTITUDE, *POSITION, ROLL)
IMAGE = ("image.scale", "image.offset_w_m2_sr", "image.blur_sigma_px", "image.shift_x_px", "image.shift_y_px")
# The nuisance parameters of a fit: reported apart from the materials (with the per-observation forms of IMAGE's).
NUISANCES = (*IMAGE, *ATTITUDE, *POSITION, ROLL)
# Joins a per-observation parameter's name and its observation's index: ``image.scale@1``.
OBSERVATION_MARK = "@"
# Default start of the PSF width (px): 0, no blur, is outside its open range, and its derivative vanishes there.
PSF_SIGMA_START_PX = 0.5
# Parameters that set one scene value together.
JOINT = (SUN_ANGLES, ATTITUDE, POSITION)


def observation_name(name: str, observation: int | str) -> str:
    """The name of per-observation parameter ``name`` for observation ``observation`` alone (``image.scale@1``)."""
    return f"{name}{OBSERVATION_MARK}{observation}"


def observation_of(name: str) -> tuple[str, int | None]:
    """A parameter name without its observation index, and the index (None: not per observation)."""
    base, mark, index = name.partition(OBSERVATION_MARK)
    return base, (int(index) if mark and index.isascii() and index.isdigit() else None)


def is_image(name: str) -> bool:
    """Whether ``name`` is a fit-only image nuisance (:data:`IMAGE`), shared or one observation's."""
    return observation_of(name)[0] in IMAGE


def is_nuisance(name: str) -> bool:
    """Whether ``name`` is a nuisance parameter (:data:`NUISANCES`), shared or one observation's."""
    return observation_of(name)[0] in NUISANCES


def _pattern(name: str) -> str:
    name = observation_of(name)[0]
    section, *rest = name.split(".")
    return f"parts.P.{rest[-1]}" if section == "parts" and len(rest) == 2 else name


def parameter(name: str) -> Parameter:
    """The registry entry of a parameter name (``parts.panels.alpha_x`` -> ``parts.P.alpha_x``)."""
    pattern = _pattern(name)
    if pattern not in PARAMETERS:
        check_choice("parameter", name, PARAMETERS)
    return PARAMETERS[pattern]


def _materials(scene: Scene) -> dict[str, Material]:
    return {part: make_material(spec.material, spec.overrides, where=f"parts.{part}") for part, spec in scene.parts.items()}


def available(scene: Scene) -> list[str]:
    """Every parameter name that can be freed (or swept) in ``scene``, in registry order."""
    materials = _materials(scene)
    names = []
    for p in PARAMETERS.values():
        if p.pattern.startswith("parts."):
            names += [p.pattern.replace(".P.", f".{part}.") for part, m in materials.items() if p.applies_to(m)]
        elif not p.pattern.startswith("wrinkles.") or scene.wrinkles.enabled:
            names.append(p.pattern)
    return names


def _check_observation(argument: str, name: str, observations: int) -> None:
    """Raise :class:`InputError` unless ``name`` is a per-observation name (``image.scale@k``) with k in range."""
    base, _, index = name.partition(OBSERVATION_MARK)
    if base not in PARAMETERS or not PARAMETERS[base].per_observation:
        per = [p.pattern for p in PARAMETERS.values() if p.per_observation]
        raise InputError(f"`{argument}` names {name!r}, but only {', '.join(per)} may be one observation's "
                         f"(`{per[0]}{OBSERVATION_MARK}k`).")
    if index not in [str(k) for k in range(observations)]:
        raise InputError(f"`{argument}` names {name!r}: the observation index {index!r} must be an integer from 0 to "
                         f"{observations - 1} (the fit has {observations} observation{'s' * (observations > 1)}).")


def check_names(
    scene: Scene, names: list[str] | tuple[str, ...], argument: str = "free", image: bool = False, observations: int = 1,
) -> None:
    """Raise :class:`InputError` for an unknown or repeated name, or two names that set the same value;
    ``image``: whether the fit-only :data:`IMAGE` nuisances are valid; ``observations``: how many
    observations a fit has (the range of a per-observation name's index, ``image.scale@k``)."""
    valid = [n for n in available(scene) if image or n not in IMAGE]
    if not names:
        raise InputError(f"`{argument}` must name at least one parameter; valid: {', '.join(valid)}.")
    for name in names:
        if OBSERVATION_MARK in name and image:
            _check_observation(argument, name, observations)
        else:
            check_choice(argument, name, valid)
    for name in names:
        base, k = observation_of(name)
        if k is not None and base in names:
            raise InputError(f"`{argument}` names both {base!r} (one for every observation) and {name!r} (observation {k}'s "
                             "own); free one of the two forms.")
    if len(set(names)) != len(names):
        raise InputError(f"`{argument}` names a parameter twice: {list(names)}.")
    for a in names:
        for b in names:
            if a < b and scene_keys(a) & scene_keys(b) and not any({a, b} <= set(group) for group in JOINT):
                raise InputError(f"`{a}` and `{b}` set the same scene value; free one of them.")


def scene_keys(name: str) -> set[str]:
    """The scene-file keys whose values parameter ``name`` replaces."""
    head = name.rsplit(".", 1)[0]
    return {f"{head}.{f}" for f in parameter(name).scene_fields} or {name}


def rms_of(w: WrinkleSettings, D: float | Array, G: float | Array) -> Array:
    """Expected rms height (m) of the wrinkles ``w`` at (D, G)."""
    return wm_rms(D, G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)


def G_of(w: WrinkleSettings, D: float | Array, rms: float | Array) -> Array:
    """The height scale G (m) that gives the wrinkles ``w`` an rms height ``rms`` (m) at D."""
    return wm_G_from_rms(D, rms, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)


def sun_angles_deg(direction: tuple[float, float, float] | np.ndarray) -> tuple[float, float]:
    """Elevation and azimuth (deg) of the direction towards the sun, from its direction of travel."""
    towards = -np.asarray(direction, float) / np.linalg.norm(direction)
    return math.degrees(math.asin(float(np.clip(towards[2], -1.0, 1.0)))), math.degrees(math.atan2(towards[1], towards[0]))


def sun_direction(elevation_deg: float | Array, azimuth_deg: float | Array) -> Array:
    """The sun's direction of travel from the elevation and azimuth (deg) of the direction towards it."""
    el, az = jnp.deg2rad(elevation_deg), jnp.deg2rad(azimuth_deg)
    return -jnp.stack([jnp.cos(el) * jnp.cos(az), jnp.cos(el) * jnp.sin(az), jnp.sin(el)])


_GETTERS: dict[str, Callable[[Scene], float]] = {
    "wrinkles.D": lambda s: s.wrinkles.D,
    "wrinkles.G": lambda s: s.wrinkles.G,
    "wrinkles.rms_m": lambda s: float(rms_of(s.wrinkles, s.wrinkles.D, s.wrinkles.G)),
    "sun.irradiance_w_m2": lambda s: s.sun.irradiance_w_m2,
    "sun.elevation_deg": lambda s: sun_angles_deg(s.sun.direction)[0],
    "sun.azimuth_deg": lambda s: sun_angles_deg(s.sun.direction)[1],
    **{name: (lambda s, i=i: s.target.attitude_deg[i]) for i, name in enumerate(ATTITUDE)},
    **{name: (lambda s, i=i: s.target.position_m[i]) for i, name in enumerate(POSITION)},
    ROLL: lambda s: s.camera.roll_deg,
    "image.scale": lambda s: 1.0,
    "image.offset_w_m2_sr": lambda s: 0.0,
    "image.blur_sigma_px": lambda s: PSF_SIGMA_START_PX,
    "image.shift_x_px": lambda s: 0.0,
    "image.shift_y_px": lambda s: 0.0,
}


def scene_value(scene: Scene, name: str) -> float:
    """The value of parameter ``name`` in the scene (its fixed value, or a fit's default start)."""
    name = observation_of(name)[0]
    if name in _GETTERS:
        return float(_GETTERS[name](scene))
    _, part, field = name.split(".")
    m = make_material(scene.parts[part].material, scene.parts[part].overrides)
    return float(m.alpha_x if field == "alpha" else getattr(m, field))


def fd_step(scene: Scene, name: str) -> float:
    """The central finite-difference step of ``name`` at the scene's value (0: forward-mode AD)."""
    p = parameter(name)
    return p.fd_step * (scene_value(scene, name) if p.relative_step else 1.0)


def parameter_table() -> str:
    """The registry as a Markdown table (the README's list of free parameters is this text)."""
    rows = ["| name | unit | valid range | Jacobian column | sets |", "|---|---|---|---|---|"]
    for p in PARAMETERS.values():
        column = "forward-mode AD" if not p.fd_step else (
            f"central differences, step {p.fd_step:g}{' x value' if p.relative_step else ' ' + p.unit}")
        kinds = f" ({', '.join(m.__name__ for m in p.materials)})" if p.materials else ""
        own = f"; `{observation_name(p.pattern, 'k')}`: observation k's own" if p.per_observation else ""
        rows.append(f"| `{p.pattern}` | {p.unit} | {p.bijection.describe()} | {column} | {p.doc}{kinds}{own} |")
    return "\n".join(rows)


@float64
def scene_with_values(scene: Scene, values: Mapping[str, float]) -> Scene:
    """A validated copy of ``scene`` with registered parameters set by name (physical units; the
    inverse of :func:`scene_value`): the scene file that renders them. The sun's angles become
    ``sun.direction``, the pose's components set ``target.attitude_deg`` / ``position_m``, the rms
    height a G at the scene's (or the given) D, a conductor's ``alpha`` the field the scene spells it
    with (``alpha``, or ``alpha_x`` and ``alpha_y``). The fit-only :data:`IMAGE` nuisances are not
    scene values and are left out.

    Raises:
        InputError: for a name the scene cannot free, or a value out of its range.
    """
    v = {n: float(x) for n, x in values.items() if not is_image(n)}
    if v:  # a fit of image nuisances alone renders its scene as given
        check_names(scene, list(v), "values")
    keys: dict[str, Any] = {n: x for n, x in v.items()
                            if n not in (*SUN_ANGLES, *ATTITUDE, *POSITION, "wrinkles.rms_m") and _pattern(n) != "parts.P.alpha"}
    if set(SUN_ANGLES) & set(v):
        el, az = (v.get(n, scene_value(scene, n)) for n in SUN_ANGLES)
        keys["sun.direction"] = np.asarray(sun_direction(el, az), dtype=float).tolist()
    for group, key in ((ATTITUDE, "target.attitude_deg"), (POSITION, "target.position_m")):
        if set(group) & set(v):
            keys[key] = [v.get(n, scene_value(scene, n)) for n in group]
    if "wrinkles.rms_m" in v:
        keys["wrinkles.G"] = float(G_of(scene.wrinkles, v.get("wrinkles.D", scene.wrinkles.D), v["wrinkles.rms_m"]))
    for name, x in v.items():
        if _pattern(name) == "parts.P.alpha":
            _, part, _ = name.split(".")
            fields = ("alpha",) if "alpha" in scene.parts[part].overrides else ("alpha_x", "alpha_y")
            keys.update({f"parts.{part}.{f}": x for f in fields})
    return scene.with_values(keys)
