"""A fit's free parameters: the ordered names with the solver's coordinates and finite-difference steps.

What each name means (range, unit, step, what it sets) is the registry's,
:mod:`spacefit.scene.parameters`. A solver works on an unconstrained vector ``u``; each free
parameter is ``x = b.forward(u)`` with a :class:`Bijection` ``b`` onto the open interval of its
registered :class:`~spacefit.scene.entries.Bounds`, so a solver never sees a clipped or invalid
value. Per observation k of a joint fit, :meth:`FreeParameters.rendered` says which free values its
renderer sees (its own ``target.attitude_z_deg@k`` in place of a shared one).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.errors import InputError
from spacefit.scene.schema import Scene
from spacefit.scene.names import Name
from spacefit.scene.parameters import check_names, fd_step, is_image, parameter
from spacefit.scene.entries import Bounds


@dataclass(frozen=True)
class Bijection(Bounds):
    """Map from the real line onto the open interval (lo, hi): logistic if bounded, exp if bounded
    below only, the identity on the whole line (lo = -inf)."""

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


# one program per map and set of bijections: called on values (not inside a traced program), the maps ran operation by
# operation, some 40 single-operation programs per fit, each traced and lowered in every process
@functools.partial(jax.jit, static_argnums=(0, 1))
def _mapped(fn: Callable[[Bijection, Array], Array], bijections: tuple[Bijection, ...], v: Float[Array, " n"]) -> Float[Array, " n"]:
    """``fn(b_i, v_i)`` for each value, one call per distinct bijection on all its values at once: value by
    value, a pass's program (a solver's step) grew by each frame's own values' maps (5 a frame)."""
    groups: dict[Bijection, list[int]] = {}
    for i, b in enumerate(bijections):
        groups.setdefault(b, []).append(i)
    order = np.concatenate([np.asarray(indices) for indices in groups.values()])
    mapped = jnp.concatenate([fn(b, v[np.asarray(indices)]) for b, indices in groups.items()])
    return mapped if np.array_equal(order, np.arange(order.size)) else mapped[np.argsort(order)]


def bijection(name: str) -> Bijection:
    """The solver's coordinate of parameter ``name``: a bijection onto its registered bounds."""
    bounds = parameter(name).bounds
    return Bijection(bounds.lo, bounds.hi)


@dataclass(frozen=True)
class FreeParameters:
    """The free parameters of a fit, in order, with their bijections and finite-difference steps."""

    names: tuple[str, ...]
    bijections: tuple[Bijection, ...]
    fd_steps: Float[np.ndarray, " n"]

    def to_physical(self, u: Float[Array, " n"]) -> Float[Array, " n"]:
        """Unconstrained vector -> physical values."""
        return _mapped(Bijection.forward, self.bijections, jnp.asarray(u))

    def to_unconstrained(self, x: Float[Array, " n"]) -> Float[Array, " n"]:
        """Physical values -> unconstrained vector."""
        return _mapped(Bijection.inverse, self.bijections, jnp.asarray(x))

    def check_start(self, x: Sequence[float]) -> None:
        """Raise if a start value lies outside (or on the edge of) its parameter's valid range."""
        for name, b, v in zip(self.names, self.bijections, x):
            if not b.contains(float(v)):
                raise InputError(f"start of `{name}` must be inside {b.describe()}, got {float(v):g}.")

    def rendered(self, k: int) -> tuple[tuple[str, ...], np.ndarray]:
        """What observation k's renderer sees: the registered names (without ``@k``) of the free
        values that are not image nuisances, and their indices in the free vector. Its own
        per-observation value (``target.attitude_z_deg@k``) stands for the parameter; other
        observations' own values are not among them."""
        names, indices = [], []
        for i, name in enumerate(self.names):
            ref = Name(name)
            if is_image(name) or ref.observation not in (None, k):
                continue
            names.append(ref.parameter)
            indices.append(i)
        return tuple(names), np.array(indices, dtype=int)


def free_parameters(scene: Scene, names: Sequence[str], observations: int = 1) -> FreeParameters:
    """Resolve and check free parameter names against a scene, for a fit of ``observations``
    observations (the range of a per-observation name's index, ``image.scale@k``).

    Raises:
        InputError: for an unknown or repeated name, or two that set one value (the message lists
            the valid ones).
    """
    names = check_names(scene, names, image=True, observations=observations)
    steps = np.array([fd_step(scene, n) for n in names])
    return FreeParameters(names, tuple(bijection(n) for n in names), steps)
