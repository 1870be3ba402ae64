"""What one entry of the parameter registry (:mod:`spacefit.scene.parameters`) holds: a :class:`Parameter`
with its unit, its valid range (:class:`Bounds`), how it reads and sets a scene, and its :data:`GROUPS`.

Plain Python and NumPy: the solver's coordinates on these ranges (bijections, in JAX) are the fitting
code's, :mod:`spacefit.fitting.params`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.materials import Material
from spacefit.scene.sections import SceneLike

# A scene's value of parameter ``name`` (its full name, ``parts.panels.kd``).
Getter = Callable[[SceneLike, str], float]
# The scene-file keys (and their values) that set parameter ``name`` to ``values[name]``, given every
# value being set (a joint scene value takes its siblings from them, or from the scene).
Setter = Callable[[SceneLike, str, Mapping[str, float]], dict[str, Any]]
# The groups a parameter may belong to.
GROUPS = {
    "wrinkles": "the W-M height field's parameters (D, G, rms height)",
    "sun-angles": "the direction towards the sun",
    "attitude": "the target's attitude angles",
    "position": "the target's position",
    "roll": "the camera's roll",
    "moves-vertices": "moves vertices (or the camera about them): a render needs the whole film, not the target's window",
    "image": "a fit-only nuisance of the image formation, applied to the render in JAX",
    "nuisance": "a fit's nuisance parameter, reported apart from the materials",
    "per-observation": "a joint fit may free it once per observation (name@k)",
    "joint": "sets one scene value together with the others of its group (they may be freed together)",
}


@dataclass(frozen=True)
class Bounds:
    """A parameter's valid range: the open interval (lo, hi) a fit moves in (-inf / inf: unbounded);
    a scene value may lie on a finite bound."""

    lo: float
    hi: float = math.inf

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


POSITIVE = Bounds(0.0)
WHOLE_LINE = Bounds(-math.inf)


@dataclass(frozen=True)
class Parameter:
    """One kind of free parameter.

    Attributes:
        pattern: its name, ``P`` standing for a part name (``parts.P.alpha_x``).
        unit: SI unit ("1" for dimensionless; degrees at the user-facing edge, as in the scene file).
        bounds: its valid range (the solver's coordinate maps the real line onto its inside).
        doc: what it sets, in words.
        get: its value in a scene (its fixed value, or a fit's default start).
        set: the scene-file keys that set it.
        groups: the :data:`GROUPS` it belongs to.
        fd_step: central finite-difference step of its Jacobian column (0: a forward-mode AD render).
            Geometry columns come from finite differences with common random numbers (the AD
            integrators' derivatives in vertex positions are biased, README); the sun's frame is
            set as a whole transform. Larger steps than usual: the columns' Monte Carlo noise falls
            as 1 / step (README), the truncation error of these smooth maps is small.
        relative_step: ``fd_step`` is relative to the parameter's value.
        materials: for ``parts.P.*``, the material models that have it (grey values only).
        scene_fields: the scene-file fields it replaces (default: its own).
        scale: the size of a change that matters, in its unit, for a parameter whose value may be
            near 0 (angles, shifts): a standard error is judged against the larger of it and the
            value ("poorly determined" in :meth:`FitResult.uncertainty`); 0: against the value.
        label: what it is in a few words, for axes and tables (:func:`label`; without the part or unit).

    Example:
        >>> import spacefit as sf
        >>> kd = sf.PARAMETERS["parts.P.kd"]
        >>> kd.unit, kd.label, kd.bounds.lo, kd.bounds.hi
        ('1', 'albedo kd', 0.0, 1.0)
    """

    pattern: str
    unit: str
    bounds: Bounds
    doc: str
    get: Getter
    set: Setter
    groups: frozenset[str] = frozenset()
    fd_step: float = 0.0
    relative_step: bool = False
    materials: tuple[type, ...] = ()
    scene_fields: tuple[str, ...] = ()
    scale: float = 0.0
    label: str = ""

    @property
    def field(self) -> str:
        """The last component of the name (``alpha_x``)."""
        return self.pattern.rsplit(".", 1)[-1]

    def applies_to(self, material: Material) -> bool:
        """Whether a part of this material has this parameter (grey, i.e. scalar, values only)."""
        if not isinstance(material, self.materials):
            return False
        return not isinstance(getattr(material, type(material).field(self.field).name), tuple)
