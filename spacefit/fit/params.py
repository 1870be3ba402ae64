"""Free parameters: names, valid ranges, bijections from unconstrained space, and scene values.

A solver works on an unconstrained vector ``u``; each free parameter is ``x = b.forward(u)`` with
a bijection ``b`` onto its open valid range, so a solver never sees a clipped or invalid value.

Parameter names address the scene file's keys:

=============================  ===========  ======================================================
name                           range        scene value (Mitsuba traverse key)
=============================  ===========  ======================================================
``wrinkles.D``                 (2, 3)       vertex positions of every wrinkled part (W-M, JAX)
``wrinkles.G``                 (0, inf) m   vertex positions of every wrinkled part (W-M, JAX)
``wrinkles.rms_m``             (0, inf) m   the same through G = G(D, rms height), see below
``parts.P.alpha_x``            (1e-4, 1)    ``P.bsdf.alpha_u.value`` (rough conductor)
``parts.P.alpha_y``            (1e-4, 1)    ``P.bsdf.alpha_v.value``
``parts.P.alpha``              (1e-4, 1)    both of the above, tied (isotropic)
``parts.P.eta`` / ``.k``       (0, inf)     ``P.bsdf.eta.value`` / ``P.bsdf.k.value`` (grey only)
``parts.P.kd``                 (0, 1)       ``P.bsdf.reflectance.value`` (Lambert, grey)
``sun.irradiance_w_m2``        (0, inf)     ``sun.irradiance.value``
``sun.elevation_deg``          (-90, 90)    ``sun.to_world``: the sun's elevation above world xy
``sun.azimuth_deg``            any          ``sun.to_world``: the sun's azimuth from world +x to +y
=============================  ===========  ======================================================

The sun's angles give the direction towards it, (cos el cos az, cos el sin az, sin el); the light
travels the opposite way (the scene's ``sun.direction``). Like the scene file, they are in degrees.

``wrinkles.rms_m`` is the expected rms height of eq. 2-1 (:func:`spacefit.geometry.wm.wm_rms`). In
an image D and G trade off along a valley of nearly constant rms height; (D, rms) are the better
determined coordinates, and :func:`spacefit.fit.fit` uses them when D and G are both free.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.errors import InputError, check_choice
from spacefit.geometry.wm import wm_G_from_rms, wm_rms
from spacefit.materials import Conductor, Lambert, Mirror
from spacefit.scene.assembly import Assembly
from spacefit.scene.config import Scene


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
BIJECTIONS: Mapping[str, Bijection] = {
    "D": Bijection(2.0, 3.0),
    "G": POSITIVE,
    "rms_m": POSITIVE,
    "alpha_x": ROUGHNESS,
    "alpha_y": ROUGHNESS,
    "alpha": ROUGHNESS,
    "eta": POSITIVE,
    "k": POSITIVE,
    "kd": UNIT,
    "irradiance_w_m2": POSITIVE,
    "elevation_deg": Bijection(-90.0, 90.0),
    "azimuth_deg": Bijection(-math.inf),
}
# Central finite-difference steps of the parameters whose Jacobian columns come from finite
# differences with common random numbers (geometry: the AD integrators' derivatives in vertex
# positions disagree with finite differences, see README; the sun's direction: its frame is set
# as a whole transform, without derivatives). D's step is absolute, G's and the rms
# height's are relative to their start values. Larger steps than usual: the columns' Monte Carlo
# noise falls as 1 / step (measured in README), the truncation error of these smooth maps is small.
FD_STEP = {"D": 0.02, "G": 0.01, "rms_m": 0.03, "elevation_deg": 0.5, "azimuth_deg": 0.5}
RELATIVE_FD_STEP = ("G", "rms_m")


def available(scene: Scene) -> list[str]:
    """Every parameter name that can be freed in ``scene``."""
    names = ["wrinkles.D", "wrinkles.G", "wrinkles.rms_m"] if scene.wrinkles.enabled else []
    from spacefit.materials import make_material

    for part, spec in scene.parts.items():
        m = make_material(spec.material, spec.overrides)
        if isinstance(m, Conductor):
            names += [f"parts.{part}.{p}" for p in ("alpha_x", "alpha_y", "alpha")]
        if isinstance(m, (Conductor, Mirror)):
            names += [f"parts.{part}.{p}" for p in ("eta", "k") if not isinstance(getattr(m, p), tuple)]
        if isinstance(m, Lambert) and not isinstance(m.kd, tuple):
            names.append(f"parts.{part}.kd")
    return names + ["sun.irradiance_w_m2", "sun.elevation_deg", "sun.azimuth_deg"]


def scene_value(scene: Scene, name: str) -> float:
    """The value of parameter ``name`` in the scene (its fixed value, or a fit's default start)."""
    from spacefit.materials import make_material

    section, *rest = name.split(".")
    w = scene.wrinkles
    if name == "wrinkles.rms_m":
        return float(wm_rms(w.D, w.G, gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls))
    if section == "wrinkles":
        return float(getattr(w, rest[0]))
    if section == "sun":
        if rest[0] == "irradiance_w_m2":
            return float(scene.sun.irradiance_w_m2)
        towards = -np.asarray(scene.sun.direction, float) / np.linalg.norm(scene.sun.direction)
        if rest[0] == "elevation_deg":
            return math.degrees(math.asin(float(np.clip(towards[2], -1.0, 1.0))))
        return math.degrees(math.atan2(towards[1], towards[0]))
    part, field = rest
    m = make_material(scene.parts[part].material, scene.parts[part].overrides)
    return float(m.alpha_x if field == "alpha" else getattr(m, field))


@dataclass(frozen=True)
class FreeParameters:
    """The free parameters of a fit, in order, with their bijections and finite-difference steps."""

    names: tuple[str, ...]
    bijections: tuple[Bijection, ...]
    fd_steps: Float[np.ndarray, " n"]

    def to_physical(self, u: Float[Array, " n"]) -> Float[Array, " n"]:
        """Unconstrained vector -> physical values."""
        return jnp.stack([b.forward(u[i]) for i, b in enumerate(self.bijections)])

    def to_unconstrained(self, x: Float[Array, " n"]) -> Float[Array, " n"]:
        """Physical values -> unconstrained vector."""
        return jnp.stack([b.inverse(jnp.asarray(x[i], dtype=float)) for i, b in enumerate(self.bijections)])

    def check_start(self, x: Sequence[float]) -> None:
        """Raise if a start value lies outside (or on the edge of) its parameter's valid range."""
        for name, b, v in zip(self.names, self.bijections, x):
            if not b.contains(float(v)):
                raise InputError(f"start of `{name}` must be inside {b.describe()}, got {float(v):g}.")


def free_parameters(scene: Scene, names: Sequence[str]) -> FreeParameters:
    """Resolve and check free parameter names against a scene.

    Raises:
        InputError: for an unknown or repeated name (the message lists the valid ones).
    """
    valid = available(scene)
    if not names:
        raise InputError(f"`free` must name at least one parameter; valid: {', '.join(valid)}.")
    for name in names:
        check_choice("free", name, valid)
    if len(set(names)) != len(names):
        raise InputError(f"`free` names a parameter twice: {list(names)}.")
    if {"wrinkles.G", "wrinkles.rms_m"} <= set(names):
        raise InputError("`wrinkles.G` and `wrinkles.rms_m` set the same heights; free one of them.")
    for part in {n.split(".")[1] for n in names if n.startswith("parts.") and n.endswith(".alpha")}:
        if {f"parts.{part}.alpha_x", f"parts.{part}.alpha_y"} & set(names):
            raise InputError(f"`parts.{part}.alpha` ties alpha_x and alpha_y; do not free them as well.")
    fields = [n.split(".")[-1] for n in names]
    steps = np.array([FD_STEP.get(f, 0.0) * (scene_value(scene, n) if f in RELATIVE_FD_STEP else 1.0) for n, f in zip(names, fields)])
    return FreeParameters(tuple(names), tuple(BIJECTIONS[f] for f in fields), steps)


_KEYS = {"alpha_x": ("alpha_u",), "alpha_y": ("alpha_v",), "alpha": ("alpha_u", "alpha_v"), "eta": ("eta",), "k": ("k",)}


def scene_values_fn(assembly: Assembly, free: FreeParameters) -> Callable[[Array], dict[str, Array]]:
    """JAX function: physical free values (n,) -> the Mitsuba scene values they set, by traverse key.

    Geometry parameters give every wrinkled part's world vertex positions (flattened), through the
    JAX W-M heights, so their tangents in D and G are exact.
    """
    index = {name: i for i, name in enumerate(free.names)}
    w = assembly.scene.wrinkles
    geometry = [n for n in ("wrinkles.D", "wrinkles.G", "wrinkles.rms_m") if n in index]

    sun_angles = [n for n in ("sun.elevation_deg", "sun.azimuth_deg") if n in index]
    start_angles = {n: scene_value(assembly.scene, n) for n in ("sun.elevation_deg", "sun.azimuth_deg")}

    def values_of(x: Array) -> dict[str, Array]:
        out: dict[str, Array] = {}
        if sun_angles:
            el, az = (jnp.deg2rad(x[index[n]] if n in index else start_angles[n]) for n in ("sun.elevation_deg", "sun.azimuth_deg"))
            out["sun.to_world"] = -jnp.stack([jnp.cos(el) * jnp.cos(az), jnp.cos(el) * jnp.sin(az), jnp.sin(el)])
        if geometry:
            D = x[index["wrinkles.D"]] if "wrinkles.D" in index else w.D
            G = x[index["wrinkles.G"]] if "wrinkles.G" in index else w.G
            if "wrinkles.rms_m" in index:
                G = wm_G_from_rms(D, x[index["wrinkles.rms_m"]], gamma=w.gamma, M=w.M, L=w.L, Ls=w.Ls)
            for part in assembly.refinements:
                out[f"{part}.vertex_positions"] = jnp.ravel(assembly.world_vertices(part, D, G))
        for name, i in index.items():
            section, *rest = name.split(".")
            if section == "wrinkles":
                continue
            if name == "sun.irradiance_w_m2":
                out["sun.irradiance.value"] = jnp.full(3, x[i])
            elif section == "parts":
                part, field = rest
                if field == "kd":
                    out[f"{part}.bsdf.reflectance.value"] = jnp.full(3, x[i])
                else:
                    for key in _KEYS[field]:
                        out[f"{part}.bsdf.{key}.value"] = x[i]
        return out

    return values_of
