"""The smooth conductor (thesis eq. 2-5): a delta reflection weighted by conductor Fresnel."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from spacefit.materials.conductor import ETA, K, MIN_ALPHA, Conductor
from spacefit.materials.model import Field, MaterialModel, Spectrum


@dataclass(frozen=True)
class Mirror(MaterialModel):
    """Smooth conductor (thesis eq. 2-5): a delta reflection weighted by conductor Fresnel.

    Under a single distant sun a mirror is never seen lit directly (delta BRDF times delta light);
    it only shows what it reflects. Its BRDF has no finite value (:attr:`delta`).

    Args:
        eta: real part of the complex refractive index, one value or RGB (3 values), > 0.
        k: imaginary part (extinction coefficient), one value or RGB, >= 0.

    Raises:
        InputError: a value outside its range.

    Example:
        >>> import spacefit as sf
        >>> sf.Mirror(eta=0.18, k=0.01).delta
        True
    """

    name: ClassVar[str] = "mirror"
    fields: ClassVar[tuple[Field, ...]] = (ETA, K)
    delta: ClassVar[bool] = True

    eta: Spectrum
    k: Spectrum

    def effective(self, slope_rms: float) -> Conductor | None:
        """The smoothest Beckmann conductor of the same index, widened by the wrinkles' slopes."""
        return Conductor(self.eta, self.k, MIN_ALPHA, MIN_ALPHA, "beckmann").effective(slope_rms)
