"""spacefit: a differentiable renderer for BRDF parameter fitting of space targets.

``import spacefit as sf`` is the API: every name a user needs is here, listed in ``__all__``; the
modules behind it are private and may change. Importing spacefit changes no global state: JAX's
64-bit mode is switched on only inside the calls that need it (:mod:`spacefit.precision`).

Names are imported on first use (module ``__getattr__``, PEP 562): ``spacefit render`` then loads
neither the fitting stack (JAX, optimistix) nor the plotting one, about 2 s of a 3 s start-up.
"""

from __future__ import annotations

import importlib
import warnings

__version__ = "0.1.0"

# Public name -> (module, name in that module). Editors and type checkers see these names through the
# stub __init__.pyi that tools/api_stub.py writes from _EXPORTS and __all__: rerun it after changing either.
_EXPORTS: dict[str, tuple[str, str]] = {
    "Case": ("spacefit.cases", "Case"),
    "Pass": ("spacefit.fitting.passes", "Pass"),
    "PassObservation": ("spacefit.fitting.observations.passes", "PassObservation"),
    "Frame": ("spacefit.fitting.passes", "Frame"),
    "frame_table": ("spacefit.fitting.pass_report", "frame_table"),
    "read_frame_table": ("spacefit.fitting.pass_report", "read_frame_table"),
    "plot_frames": ("spacefit.fitting.pass_report", "plot_frames"),
    "arc_pass": ("spacefit.fitting.pass_simulation", "arc_pass"),
    "simulate_pass": ("spacefit.fitting.pass_simulation", "simulate_pass"),
    "case_names": ("spacefit.cases", "case_names"),
    "load_case": ("spacefit.cases", "load_case"),
    "InputError": ("spacefit.errors", "InputError"),
    "FitResult": ("spacefit.fitting.result", "FitResult"),
    "fit": ("spacefit.fitting.loop", "fit"),
    "LOSSES": ("spacefit.fitting.losses", "LOSSES"),
    "FitRender": ("spacefit.fitting.problem", "FitRender"),
    "FitOptions": ("spacefit.fitting.loop", "FitOptions"),
    "Resume": ("spacefit.fitting.resume", "Resume"),
    "ObservationFiles": ("spacefit.fitting.observation_files", "ObservationFiles"),
    "Observation": ("spacefit.fitting.observations.image", "Observation"),
    "format_result": ("spacefit.fitting.report", "format_result"),
    "write_fit_report": ("spacefit.fitting.report", "write_fit_report"),
    "read_fit": ("spacefit.fitting.saved", "read_fit"),
    "Adam": ("spacefit.fitting.solvers", "Adam"),
    "SOLVERS": ("spacefit.fitting.solvers", "SOLVERS"),
    "Status": ("spacefit.fitting.status", "Status"),
    "Identifiability": ("spacefit.fitting.identifiability", "Identifiability"),
    "identifiability": ("spacefit.fitting.identifiability", "identifiability"),
    "Distortion": ("spacefit.geometry.distortion", "Distortion"),
    "distort_image": ("spacefit.formation", "distort_image"),
    "Intrinsics": ("spacefit.geometry.frames", "Intrinsics"),
    "pixel_solid_angles": ("spacefit.geometry.frames", "pixel_solid_angles"),
    "wm_rms": ("spacefit.geometry.wm", "wm_rms"),
    "wm_rms_slope": ("spacefit.geometry.wm", "wm_rms_slope"),
    "MLI_SLOPE_RANGE": ("spacefit.geometry.wrinkle", "MLI_SLOPE_RANGE"),
    "ObservedImage": ("spacefit.imageio.reading", "ObservedImage"),
    "read_image": ("spacefit.imageio.reading", "read_image"),
    "sensor_of": ("spacefit.imageio.provenance", "sensor_of"),
    "format_sensor_sources": ("spacefit.imageio.provenance", "format_sensor_sources"),
    "write_observation": ("spacefit.imageio.writing", "write_observation"),
    "Conductor": ("spacefit.materials", "Conductor"),
    "Lambert": ("spacefit.materials", "Lambert"),
    "DiffuseConductor": ("spacefit.materials", "DiffuseConductor"),
    "OrenNayar": ("spacefit.materials", "OrenNayar"),
    "MaterialModel": ("spacefit.materials", "MaterialModel"),
    "register_material": ("spacefit.materials", "register_material"),
    "BRDFTable": ("spacefit.materials.measured", "BRDFTable"),
    "BRDF_MODELS": ("spacefit.fitting.brdf_table", "BRDF_MODELS"),
    "read_brdf_table": ("spacefit.materials.measured", "read_brdf_table"),
    "fit_brdf_table": ("spacefit.fitting.observations.brdf", "fit_brdf_table"),
    "fitted_material": ("spacefit.fitting.observations.brdf", "fitted_material"),
    "compare_brdf_models": ("spacefit.fitting.observations.brdf", "compare_brdf_models"),
    "BRDFTableObservation": ("spacefit.fitting.observations.brdf", "BRDFTableObservation"),
    "PlateLightCurve": ("spacefit.studies.plate_fit", "PlateLightCurve"),
    "RenderedLightCurve": ("spacefit.studies.lightcurve_fit", "RenderedLightCurve"),
    "target_plates": ("spacefit.studies.target_plates", "target_plates"),
    "compare_plates_to_render": ("spacefit.studies.plates_vs_render", "compare_plates_to_render"),
    "PlatesVsRender": ("spacefit.studies.plates_vs_render", "PlatesVsRender"),
    "choose_light_curve_model": ("spacefit.studies.plates_vs_render", "choose_light_curve_model"),
    "ChosenLightCurve": ("spacefit.studies.plates_vs_render", "ChosenLightCurve"),
    "TabulatedBRDF": ("spacefit.materials.tabulated", "TabulatedBRDF"),
    "write_table_fit": ("spacefit.fitting.report", "write_table_fit"),
    "Site": ("spacefit.studies.orbit", "Site"),
    "Orbit": ("spacefit.studies.orbit", "Orbit"),
    "PassGeometry": ("spacefit.studies.orbit", "PassGeometry"),
    "pass_geometry": ("spacefit.studies.orbit", "pass_geometry"),
    "RefusedRow": ("spacefit.studies.observation_files", "RefusedRow"),
    "write_light_curve": ("spacefit.studies.observing", "write_light_curve"),
    "LightCurveObservations": ("spacefit.studies.lightcurve_observations", "LightCurveObservations"),
    "read_light_curve": ("spacefit.studies.observing", "read_light_curve"),
    "Plate": ("spacefit.studies.plates", "Plate"),
    "predict_magnitudes": ("spacefit.studies.plates", "predict_magnitudes"),
    "fit_plates": ("spacefit.studies.plate_fit", "fit_plates"),
    "fitted_plates": ("spacefit.studies.plate_fit", "fitted_plates"),
    "DesignMember": ("spacefit.studies.design", "DesignMember"),
    "fit_design": ("spacefit.studies.design", "fit_design"),
    "predict_design": ("spacefit.studies.design", "predict_design"),
    "design_noise_mag": ("spacefit.studies.design", "design_noise_mag"),
    "MagnitudePrediction": ("spacefit.studies.design", "MagnitudePrediction"),
    "Prediction": ("spacefit.fitting.prediction", "Prediction"),
    "predictive_intervals": ("spacefit.fitting.prediction", "predictive_intervals"),
    "residual_noise": ("spacefit.fitting.prediction", "residual_noise"),
    "Earth": ("spacefit.studies.earthshine", "Earth"),
    "EarthshineSources": ("spacefit.studies.earthshine", "EarthshineSources"),
    "earthshine_sources": ("spacefit.studies.earthshine", "earthshine_sources"),
    "earthshine_irradiance": ("spacefit.studies.earthshine", "earthshine_irradiance"),
    "light_curve_convergence": ("spacefit.studies.lightcurve_convergence", "light_curve_convergence"),
    "fit_light_curve": ("spacefit.studies.lightcurve_fit", "fit_light_curve"),
    "Mirror": ("spacefit.materials", "Mirror"),
    "PRESETS": ("spacefit.materials.registry", "PRESETS"),
    "fit_to_folder": ("spacefit.pipeline", "fit_to_folder"),
    "fit_light_curve_to_folder": ("spacefit.pipeline", "fit_light_curve_to_folder"),
    "LightCurveFiles": ("spacefit.studies.lightcurve_files", "LightCurveFiles"),
    "render_to_folder": ("spacefit.render_job", "render_to_folder"),
    "Jacobian": ("spacefit.rendering.derivatives", "Jacobian"),
    "jacobian": ("spacefit.rendering.derivatives", "jacobian"),
    "render_function": ("spacefit.rendering.derivatives", "render_function"),
    "read_exr": ("spacefit.rendering.exr", "read_exr"),
    "write_exr": ("spacefit.rendering.exr", "write_exr"),
    "PartImage": ("spacefit.rendering.parts", "PartImage"),
    "Renderer": ("spacefit.rendering.renderer", "Renderer"),
    "render": ("spacefit.rendering.renderer", "render"),
    "Scene": ("spacefit.scene.schema", "Scene"),
    "RenderSettings": ("spacefit.scene.sections", "RenderSettings"),
    "CameraSettings": ("spacefit.scene.sections", "CameraSettings"),
    "SunSettings": ("spacefit.scene.sections", "SunSettings"),
    "TargetSettings": ("spacefit.scene.target", "TargetSettings"),
    "WrinkleSettings": ("spacefit.scene.sections", "WrinkleSettings"),
    "PartSettings": ("spacefit.scene.target", "PartSettings"),
    "SunTracking": ("spacefit.geometry.articulation", "SunTracking"),
    "AxisAngle": ("spacefit.geometry.articulation", "AxisAngle"),
    "NadirSun": ("spacefit.geometry.attitude", "NadirSun"),
    "SunPointing": ("spacefit.geometry.attitude", "SunPointing"),
    "QuaternionTable": ("spacefit.geometry.attitude", "QuaternionTable"),
    "default_scene": ("spacefit.scene.toml", "default_scene"),
    "load_scene": ("spacefit.scene.toml", "load_scene"),
    "PARAMETERS": ("spacefit.scene.parameters", "PARAMETERS"),
    "Parameter": ("spacefit.scene.entries", "Parameter"),
    "available_parameters": ("spacefit.scene.parameters", "available"),
    "parameter_table": ("spacefit.scene.parameters", "parameter_table"),
    "Sensor": ("spacefit.sensor", "Sensor"),
    "read_sensor_file": ("spacefit.sensor", "read_sensor_file"),
    "sweep": ("spacefit.studies.sweep", "sweep"),
    "Sensitivity": ("spacefit.studies.sensitivity", "Sensitivity"),
    "sensitivity": ("spacefit.studies.sensitivity", "sensitivity"),
    "LightCurve": ("spacefit.studies.lightcurve", "LightCurve"),
    "light_curve": ("spacefit.studies.lightcurve", "light_curve"),
    "read_sweep_file": ("spacefit.studies.sweep", "read_sweep_file"),
    "verify_store": ("spacefit.studies.store", "verify_store"),
    "StoreReport": ("spacefit.studies.store", "StoreReport"),
    "expected_dn": ("spacefit.formation", "expected_dn"),
    "noise_variance_dn": ("spacefit.formation", "noise_variance_dn"),
    "observe": ("spacefit.formation", "observe"),
    "saturated_mask": ("spacefit.sensor", "saturated_mask"),
    "choose_exposure": ("spacefit.formation", "choose_exposure"),
    "ClusterError": ("spacefit.executors", "ClusterError"),
    "plot_comparison": ("spacefit.fitting.plots", "plot_comparison"),
    "plot_convergence": ("spacefit.fitting.plots", "plot_convergence"),
}

__all__ = [
    "PARAMETERS", "PRESETS", "LOSSES", "SOLVERS",
    "Adam", "Case", "Conductor", "FitOptions", "Resume", "FitRender", "FitResult", "Identifiability", "InputError", "Jacobian", "Lambert", "Mirror",
    "Observation", "ObservationFiles", "Parameter", "PartImage", "Renderer", "Scene", "Status",
    "available_parameters", "case_names", "default_scene", "fit", "fit_to_folder", "format_result", "identifiability",
    "jacobian", "load_case", "load_scene", "parameter_table", "read_exr", "render", "render_function",
    "render_to_folder", "wm_rms", "wm_rms_slope", "write_exr", "write_fit_report", "read_fit",
    "Distortion", "Intrinsics", "ObservedImage", "Sensor", "distort_image", "expected_dn", "noise_variance_dn", "observe",
    "pixel_solid_angles", "read_image", "read_sensor_file", "saturated_mask", "choose_exposure", "write_observation", "sensor_of", "format_sensor_sources",
    "MLI_SLOPE_RANGE",
    "Pass", "PassObservation", "Frame", "frame_table", "read_frame_table", "plot_frames", "arc_pass", "simulate_pass",
    "read_sweep_file", "sweep", "verify_store", "StoreReport", "ClusterError", "Sensitivity", "sensitivity", "LightCurve", "light_curve",
    "plot_comparison", "plot_convergence",
    "DiffuseConductor", "OrenNayar", "MaterialModel", "register_material", "BRDFTable", "BRDF_MODELS", "read_brdf_table", "fit_brdf_table", "fitted_material", "compare_brdf_models", "TabulatedBRDF",
    "write_table_fit", "Site", "LightCurveObservations", "read_light_curve", "write_light_curve", "RefusedRow",
    "Orbit", "PassGeometry", "pass_geometry", "Plate", "predict_magnitudes", "fit_plates", "fitted_plates",
    "light_curve_convergence", "fit_light_curve", "BRDFTableObservation", "PlateLightCurve", "RenderedLightCurve",
    "LightCurveFiles", "fit_light_curve_to_folder", "target_plates", "compare_plates_to_render", "PlatesVsRender", "choose_light_curve_model", "ChosenLightCurve",
    "Earth", "EarthshineSources", "earthshine_sources", "earthshine_irradiance",
    "DesignMember", "fit_design", "predict_design", "design_noise_mag", "MagnitudePrediction", "Prediction", "predictive_intervals", "residual_noise",
    "RenderSettings", "CameraSettings", "SunSettings", "TargetSettings", "WrinkleSettings", "PartSettings",
    "SunTracking", "AxisAngle", "NadirSun", "SunPointing", "QuaternionTable",
]


# Former public names -> (the name that replaces them, why): still reachable, with a DeprecationWarning.
_DEPRECATED: dict[str, tuple[str, str]] = {
    "TableFit": ("FitResult", "a table's or a light curve's fit is an sf.fit and returns an sf.FitResult"),
}


def __getattr__(name: str) -> object:
    """Import a public name's module on first use (PEP 562); a deprecated name warns and gives its replacement."""
    if name in _DEPRECATED:
        replacement, why = _DEPRECATED[name]
        warnings.warn(f"sf.{name} is deprecated: {why}; use sf.{replacement}.", DeprecationWarning, stacklevel=2)
        return __getattr__(replacement)
    if name not in _EXPORTS:
        raise AttributeError(f"module 'spacefit' has no attribute {name!r}")
    module, attr = _EXPORTS[name]
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    """The public names, imported or not, and the module's own."""
    return sorted({*globals(), *_EXPORTS})
