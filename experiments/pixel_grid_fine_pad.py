"""The pixel grid's fine models' black sky (spacefit.fitting.fine_models.fine_pad): light at an image's edge (a 0.5 px
spot, 16 and 32 px images, the model made at 4x) blurred and shifted out of the image, the model on the fit's pad taken
as fine px (28; what the models had before), on the pad sized at 4x for the values, and on an ample one (4 x 28 fine px):
the largest difference from the ample pad's model, per the model's peak, in float64; and a centred spot with a 0.8 px
blur, whose pad stays the fit's. Run: ``python experiments/pixel_grid_fine_pad.py``.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
from studyio import commit, machine

from spacefit.fitting.nuisance import PAD_PX, image_model
from spacefit.fitting.fine_models import MOVES, fine_and_grid_models, fine_pad
from spacefit.formation import fast_pad

FACTOR = 4
NAMES = [*MOVES, "image.scale"]


def model(fine: np.ndarray, x: np.ndarray, pad: int | None, checked: bool = True) -> np.ndarray:
    """The model made at 4x on ``pad`` fine px (None: sized for x); ``checked`` False: as before, unchecked."""
    same = lambda image: image  # noqa: E731
    nuisances = image_model(NAMES, pad if pad is not None and not checked else PAD_PX)
    return np.asarray(fine_and_grid_models(jnp.asarray(fine), "box", x, 0, nuisances, same, same, same, [0, 1, 2], FACTOR,
                                           NAMES if checked else None, pad if checked else None)[0])


def main() -> None:
    print(f"machine: {machine()}; commit {commit()}; load {os.getloadavg()[0]:.1f}")
    print("size  blur  shift  centre   pads (fit's / sized / ample)   fit's pad - ample   sized - ample")
    for size in (16, 32):
        shape = (size * FACTOR, size * FACTOR)
        v, u = (np.mgrid[0 : shape[0], 0 : shape[1]] + 0.5) / FACTOR
        fits, ample = fast_pad(shape, PAD_PX), fast_pad(shape, FACTOR * PAD_PX)
        for centre, blur, shift in ((size - 0.5, 2.0, 0.0), (size - 0.5, 3.0, 2.0), (size - 0.5, 4.0, 0.0), (size / 2 - 0.3, 0.8, 0.3)):
            spot = np.exp(-((u - centre) ** 2 + (v - size / 2) ** 2) / (2 * 0.5**2))[..., None] * np.ones(3)
            x = np.array([blur, shift, -0.2, 1.5])
            truth = model(spot, x, ample)
            old, new = (np.abs(model(spot, x, p, c) - truth).max() / truth.max() for p, c in ((fits, False), (None, True)))
            print(f"{size:4d}  {blur:4.1f}  {shift:5.1f}  {'edge' if centre > size / 2 else 'centre':6s}   "
                  f"{fits:3d} / {fine_pad(shape, x, [0, 1, 2], FACTOR):3d} / {ample:3d}              {old:9.1e}         {new:9.1e}")


if __name__ == "__main__":
    with jax.enable_x64(True):
        main()
