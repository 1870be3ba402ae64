"""What the light-curve kinds of observation share (:class:`~spacefit.studies.plate_fit.PlateLightCurve`,
:class:`~spacefit.studies.lightcurve_fit.RenderedLightCurve`): their models are irradiances at the
observer, W m^-2, which their report and figure show as the magnitudes they were observed in,
m = m_sun - 2.5 log10(E / E_sun)."""

from __future__ import annotations

from abc import abstractmethod

import numpy as np

from spacefit.fitting.observations.base import ValueObservation


class LightCurveKind(ValueObservation):
    """A light curve: its values are irradiances, shown as magnitudes (brighter up)."""

    @abstractmethod
    def zero_point(self) -> tuple[float, float]:
        """The sun's magnitude in the light curve's band and the sun's irradiance at the target, W m^-2."""

    def shown(self, values: np.ndarray, unit: str) -> tuple[np.ndarray, str, str]:
        """Irradiances as magnitudes, m = m_sun - 2.5 log10(E / E_sun)."""
        sun_magnitude, sun_irradiance = self.zero_point()
        with np.errstate(divide="ignore"):
            return sun_magnitude - 2.5 * np.log10(np.asarray(values, dtype=float) / sun_irradiance), "magnitude", "magnitude"
