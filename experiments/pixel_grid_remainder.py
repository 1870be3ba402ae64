"""How the pixel grid's model error of a fitted blur falls with the model's supersampling, and what
one Gauss-Newton step leaves of it (issue 34; :mod:`spacefit.fitting.pixel_grid`).

The panels case, noise-free, box filter, at ``--sizes`` px: the truth rendered once at 8x the
resolution per axis (``--spp`` per fine pixel), blurred there by a 0.8 px Gaussian and shifted by
(0.4, -0.25) px, binned 8 x 8 (a "continuous" observation: the Gaussian's transfer at the fine
Nyquist frequency, 4 cycles per px, is 1e-40). The models share that render: binned to S x the
resolution (S = 1, 2, 4: the box-filtered render at S x), blurred and shifted there, binned to 1x.
The image nuisances (blur, shift x and y, scale) are fitted by least squares (Gauss-Newton to
convergence) for each S; e(S) = fitted - truth. Printed: e(S), the ratio e(4) / (e(2) - e(4)) (the
remainder after the 4x model relative to the difference of the 4x and 2x models: 1/3 if the error
falls as 1/S^2), and from the 1x estimate the one Gauss-Newton step to the 4x model against the
fixed point ``x* = x + step(D(x*))`` that :func:`spacefit.fitting.pixel_grid.grid_step` iterates.

Run: ``.venv/bin/python experiments/pixel_grid_remainder.py [--sizes 32 48]`` (about a minute).
"""

from __future__ import annotations

import argparse
import os

import jax
import jax.numpy as jnp
import numpy as np
from studyio import commit, machine

import spacefit as sf
from spacefit.fitting.nuisance import blur_and_shift

TRUTH = np.array([0.8, 0.4, -0.25, 1.0])  # blur (px), shift x and y (px), scale
NAMES = ("blur", "shift x", "shift y", "scale")
FINEST = 8


def binned(image: jax.Array, by: int) -> jax.Array:
    """``image`` averaged over ``by`` x ``by`` blocks."""
    h, w, c = image.shape
    return image.reshape(h // by, by, w // by, by, c).mean(axis=(1, 3))


def model(render: jax.Array, theta: jax.Array, factor: int) -> jax.Array:
    """The blur and shift of ``theta`` applied to ``render`` (at ``factor`` x the resolution), binned to 1x, scaled."""
    return theta[3] * binned(blur_and_shift(render, factor * theta[0], factor * theta[1], factor * theta[2]), factor)


def least_squares(residual: callable, theta: np.ndarray, steps: int = 12) -> np.ndarray:
    """Gauss-Newton to convergence."""
    theta = jnp.asarray(theta)
    for _ in range(steps):
        r, J = residual(theta), jax.jacfwd(residual)(theta)
        theta = theta - jnp.linalg.lstsq(J, r)[0]
    return np.asarray(theta)


def measure(size: int, spp: int) -> None:
    case = sf.load_case("panels")
    scene = case.truth_scene.with_values({"render.resolution": [FINEST * size] * 2, "camera.pixel_pitch_mm": 18.75 * 128 / size / FINEST,
                                          "render.filter": "box", "render.spp": spp})
    fine = jnp.asarray(sf.render(scene), dtype=float)
    reference = model(fine, jnp.asarray(TRUTH), FINEST)
    renders = {s: binned(fine, FINEST // s) for s in (1, 2, 4)}
    fitted = {s: least_squares(lambda t, s=s: (model(renders[s], t, s) - reference).ravel(), TRUTH) for s in renders}
    e = {s: fitted[s] - TRUTH for s in fitted}
    print(f"\n{size} px (truth at {FINEST}x, {spp} spp per fine px):")
    print("  " + " | ".join(f"{n}: " + ", ".join(f"e({s}) {e[s][i]:+.5f}" for s in e) +
                             f", e(4)/(e(2)-e(4)) {e[4][i] / (e[2][i] - e[4][i]):+.3f}" for i, n in enumerate(NAMES[:3])))
    x = jnp.asarray(fitted[1])
    J = jax.jacfwd(lambda t: model(renders[1], t, 1).ravel())(x)
    step = lambda d: -np.asarray(jnp.linalg.lstsq(J, d)[0])  # noqa: E731
    difference = lambda t: (model(renders[4], t, 4) - model(renders[1], t, 1)).ravel()  # noqa: E731
    one = step(difference(x))
    delta = one
    for _ in range(20):
        delta = step(difference(x + delta))
    converged = least_squares(lambda t: (model(renders[4], t, 4) - reference).ravel(), fitted[1]) - fitted[1]
    print("  blur from the 1x estimate: one step " f"{one[0]:+.5f}, fixed point {delta[0]:+.5f}, the 4x model's own minimum "
          f"{converged[0]:+.5f}; the one step's excess {one[0] - converged[0]:+.5f}, the fixed point's {delta[0] - converged[0]:+.5f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 48])
    parser.add_argument("--spp", type=int, default=16, help="samples per fine pixel of the 8x render")
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    print(f"{machine()}, load {os.getloadavg()[0]:.1f}, commit {commit()}")
    for size in args.sizes:
        measure(size, args.spp)


if __name__ == "__main__":
    main()
