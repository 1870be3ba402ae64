"""What a set of observations could tell about free parameters, without a fit: the standard errors and
Fisher information that :func:`~spacefit.fitting.uncertainty.estimate` gives at given values."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.fitting.problem import FitRender, Observation, setup
from spacefit.fitting.uncertainty import estimate, stderr_corr
from spacefit.precision import float64


@dataclass(frozen=True)
class Identifiability:
    """What a set of observations can tell about the free parameters at given values.

    Attributes:
        names: free parameter names.
        stderr: standard error each would have (physical units; inf where undetermined).
        correlation: (n, n) correlation of the estimates.
        fisher_eigenvalues: eigenvalues of the Fisher information in the solver's coordinates
            (their square roots are the noise-weighted Jacobian's singular values); 0 marks a
            direction nothing constrains.
        extras: derived quantities, e.g. the rms height's standard error when D and G are free.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> observation = sf.Observation(scene, sf.render(scene), sigma=0.01)
        >>> what = sf.identifiability([observation], ["parts.legs.kd"], {"parts.legs.kd": 0.2})
        >>> what.names, what.correlation.shape
        (('parts.legs.kd',), (1, 1))
    """

    names: tuple[str, ...]
    stderr: dict[str, float]
    correlation: np.ndarray
    fisher_eigenvalues: np.ndarray
    extras: dict[str, Any]


@float64
def identifiability(
    observations: Observation | Sequence[Observation],
    free: Sequence[str],
    at: Mapping[str, float],
    *,
    loss: str = "pixel",
    spp: int | None = None,
    seed: int = 1,
    seed_grad: int = 2,
    wrinkle_coordinates: str = "rms",
) -> Identifiability:
    """Standard errors and Fisher information of ``free`` parameters at the values ``at``, no fit.

    With references rendered at ``at`` (and their noise ``sigma``), this predicts how well a fit
    could determine each parameter from these observations.

    Args:
        observations: the observations (their references and noise), as :func:`fit` takes them.
        free: the parameters.
        at: the values to evaluate at (physical units), by name.
        loss: one of :data:`LOSSES`.
        spp: samples per pixel of the renders (None: the scene's).
        seed, seed_grad: the primal's and the derivatives' seeds.
        wrinkle_coordinates: ``"rms"`` (solve in D and the rms height) or ``"G"`` (in D and G).

    Returns:
        An :class:`Identifiability`.

    Raises:
        InputError: any bad input, as :func:`fit` refuses it.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> observation = sf.Observation(scene, sf.render(scene), sigma=0.01)
        >>> what = sf.identifiability([observation], ["parts.legs.kd"], {"parts.legs.kd": 0.2})
        >>> bool(0 < what.stderr["parts.legs.kd"] < 0.2)
        True
    """
    s = setup(observations, free, start=at, loss=loss, render=FitRender(spp=spp, seed=seed, seed_grad=seed_grad),
              wrinkle_coordinates=wrinkle_coordinates)
    _, cov, _, extras = estimate(s, s.x0)
    stderr, corr = stderr_corr(cov)
    return Identifiability(s.user.names, dict(zip(s.user.names, stderr.tolist())), corr,
                           np.asarray(extras.pop("fisher_eigenvalues")), extras)
