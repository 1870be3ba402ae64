"""A fit's free parameters: the ordered names with their bijections and finite-difference steps.

What each name means (range, unit, step, what it sets) is the registry's,
:mod:`spacefit.scene.parameters`. A solver works on an unconstrained vector ``u``; each free
parameter is ``x = b.forward(u)`` with a bijection ``b`` onto its open valid range, so a solver
never sees a clipped or invalid value.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from spacefit.errors import InputError
from spacefit.scene.config import Scene
from spacefit.scene.parameters import Bijection, check_names, fd_step, parameter


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
        return jnp.stack([b.inverse(jnp.asarray(x[i])) for i, b in enumerate(self.bijections)])

    def check_start(self, x: Sequence[float]) -> None:
        """Raise if a start value lies outside (or on the edge of) its parameter's valid range."""
        for name, b, v in zip(self.names, self.bijections, x):
            if not b.contains(float(v)):
                raise InputError(f"start of `{name}` must be inside {b.describe()}, got {float(v):g}.")


def free_parameters(scene: Scene, names: Sequence[str], observations: int = 1) -> FreeParameters:
    """Resolve and check free parameter names against a scene, for a fit of ``observations``
    observations (the range of a per-observation name's index, ``image.scale@k``).

    Raises:
        InputError: for an unknown or repeated name, or two that set one value (the message lists
            the valid ones).
    """
    names = tuple(names)
    check_names(scene, names, image=True, observations=observations)
    steps = np.array([fd_step(scene, n) for n in names])
    return FreeParameters(names, tuple(parameter(n).bijection for n in names), steps)
