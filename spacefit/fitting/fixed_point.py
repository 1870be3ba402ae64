"""A fixed point ``y = g(y)`` in few evaluations of ``g``: Anderson's acceleration of the plain iteration.

The plain iteration ``y_(k+1) = g(y_k)`` closes on the fixed point as ``g``'s derivative contracts, by its rate rho
an iteration (0.68 for the pixel grid's step on a 12-frame pass, :mod:`spacefit.fitting.pixel_grid`), and its move
``f_k = g(y_k) - y_k`` is only 1 - rho of ``y_k``'s distance to the fixed point: a stop rule on the move stops short
by rho / (1 - rho) of it. Anderson's acceleration (Walker & Ni 2011, "Anderson acceleration for fixed-point
iterations", SIAM J. Numer. Anal. 49(4), its Type II, every earlier iterate kept, no damping) takes, with ``dF`` and
``dG`` the differences of the successive ``f`` and ``g``, ``y_(k+1) = g(y_k) - dG gamma``, ``gamma`` minimising
``|f_k - dF gamma|``: a multisecant Newton step ``(I - g')^-1 f_k``, ``g'`` known along the differences (Fang & Saad
2009, "Two classes of multisecant methods for nonlinear acceleration", Numer. Linear Algebra Appl. 16(3)), so that
its step estimates ``y_k``'s distance to the fixed point; on a linear ``g`` in n values its iterates are GMRES's, the
fixed point reached in at most n + 1 evaluations (Walker & Ni, sec. 2).

SciPy's ``scipy.optimize.anderson`` is a root finder of the same family (Eyert's variant) whose stop rules are on
the residual ``f`` (the move) or the step in absolute terms and whose default line search spends evaluations beyond
its ``maxiter``; the few lines below keep the budget in evaluations and the stop on the estimated distance.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from jaxtyping import Float


def anderson(g: Callable[[np.ndarray], np.ndarray], scale: Float[np.ndarray, " n"], steps: int,
             tolerance: float) -> tuple[np.ndarray, int]:
    """The fixed point ``y = g(y)`` from 0 by Anderson's acceleration (module docstring) on ``y / scale``: stops where
    its step from ``y_k``, taken from the second evaluation on (the first has no difference), is within ``tolerance``
    of ``scale`` in every value, or after ``steps`` evaluations of ``g``; returns ``y_(k+1)`` (not evaluated) and the
    evaluations."""
    y, fs, gs = np.zeros(len(scale)), [], []
    while len(gs) < steps:
        gs.append(g(y * scale) / scale)
        fs.append(gs[-1] - y)
        if len(gs) == 1:
            y = gs[0]
            continue
        dF, dG = np.diff(fs, axis=0).T, np.diff(gs, axis=0).T
        moved, y = y, gs[-1] - dG @ np.linalg.lstsq(dF, fs[-1], rcond=None)[0]
        if np.all(np.abs(y - moved) <= tolerance):
            break
    return y * scale, len(gs)
