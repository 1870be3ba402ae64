"""Observation kinds: what a fit compares with its model, each kind in its own module.

Every kind keeps one contract (:mod:`spacefit.fitting.observations.base`): from the fit's named free
values it predicts its data, in their unit; it says which registered parameters
(:mod:`spacefit.scene.parameters`) it depends on and its own value of each (a fit's default start);
its residuals are (model - data) / sigma, or ln(model / data) / sigma_rel for data spanning
decades, sigma known or not; the fit's one goodness of fit, covariance, verdict and report
(:func:`fit`) take them as they take an image's pixels; its part of the fit's report and its
figure are its own (:class:`~spacefit.fitting.observations.base.Reported`: ``report``, ``plot``).

The kinds and their homes:

* an image and the scene it was taken in: :class:`spacefit.fitting.observations.image.Observation`
  (``sf.Observation``);
* a pass, its frames' images with per-frame values: :class:`spacefit.fitting.observations.passes.PassObservation`
  (``sf.PassObservation``; the frame table is :mod:`spacefit.fitting.passes`);
* a measured BRDF table and a material model of one part: :mod:`spacefit.fitting.observations.brdf`;
* a light curve predicted by flat plates: :class:`spacefit.studies.plate_fit.PlateLightCurve`;
* a light curve predicted by the path tracer: :class:`spacefit.studies.lightcurve_fit.RenderedLightCurve`.

A new kind (a spectral band, a polarimetric value) subclasses
:class:`~spacefit.fitting.observations.base.ValueObservation` in its own module; nothing else changes.
"""
