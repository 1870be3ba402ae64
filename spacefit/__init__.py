"""spacefit: a differentiable renderer for BRDF parameter fitting of space targets.

``import spacefit as sf`` is the API: every name a user needs is here, listed in ``__all__``; the
modules behind it are private and may change. Importing spacefit changes no global state: JAX's
64-bit mode is switched on only inside the calls that need it (:mod:`spacefit.precision`).
"""

from spacefit.cases import Case as Case
from spacefit.cases import case_names as case_names
from spacefit.cases import load_case as load_case
from spacefit.errors import InputError as InputError
from spacefit.fitting.loop import FitResult as FitResult
from spacefit.fitting.loop import fit as fit
from spacefit.fitting.losses import LOSSES as LOSSES
from spacefit.fitting.problem import Observation as Observation
from spacefit.fitting.report import format_result as format_result
from spacefit.fitting.report import write_fit_report as write_fit_report
from spacefit.fitting.solvers import SOLVERS as SOLVERS
from spacefit.fitting.solvers import Status as Status
from spacefit.fitting.uncertainty import Identifiability as Identifiability
from spacefit.fitting.uncertainty import identifiability as identifiability
from spacefit.geometry.distortion import Distortion as Distortion
from spacefit.geometry.distortion import distort_image as distort_image
from spacefit.geometry.frames import Intrinsics as Intrinsics
from spacefit.geometry.frames import pixel_solid_angles as pixel_solid_angles
from spacefit.geometry.wm import wm_rms as wm_rms
from spacefit.imageio import ObservedImage as ObservedImage
from spacefit.imageio import read_image as read_image
from spacefit.imageio import write_observation as write_observation
from spacefit.geometry.wm import wm_rms_slope as wm_rms_slope
from spacefit.materials import PRESETS as PRESETS
from spacefit.materials import Conductor as Conductor
from spacefit.materials import Lambert as Lambert
from spacefit.materials import Mirror as Mirror
from spacefit.pipeline import fit_to_folder as fit_to_folder
from spacefit.pipeline import render_to_folder as render_to_folder
from spacefit.rendering.derivatives import Jacobian as Jacobian
from spacefit.rendering.derivatives import jacobian as jacobian
from spacefit.rendering.derivatives import render_function as render_function
from spacefit.rendering.exr import read_exr as read_exr
from spacefit.rendering.exr import write_exr as write_exr
from spacefit.rendering.renderer import PartImage as PartImage
from spacefit.rendering.renderer import Renderer as Renderer
from spacefit.rendering.renderer import render as render
from spacefit.scene.config import Scene as Scene
from spacefit.scene.config import default_scene as default_scene
from spacefit.scene.config import load_scene as load_scene
from spacefit.scene.parameters import PARAMETERS as PARAMETERS
from spacefit.scene.parameters import Parameter as Parameter
from spacefit.scene.parameters import available as available_parameters
from spacefit.scene.parameters import parameter_table as parameter_table
from spacefit.sensor import Sensor as Sensor
from spacefit.sensor import expected_dn as expected_dn
from spacefit.sensor import noise_variance_dn as noise_variance_dn
from spacefit.sensor import observe as observe
from spacefit.sensor import saturated_mask as saturated_mask

__version__ = "0.1.0"

__all__ = [
    "PARAMETERS", "PRESETS", "LOSSES", "SOLVERS",
    "Case", "Conductor", "FitResult", "Identifiability", "InputError", "Jacobian", "Lambert", "Mirror",
    "Observation", "Parameter", "PartImage", "Renderer", "Scene", "Status",
    "available_parameters", "case_names", "default_scene", "fit", "fit_to_folder", "format_result", "identifiability",
    "jacobian", "load_case", "load_scene", "parameter_table", "read_exr", "render", "render_function",
    "render_to_folder", "wm_rms", "wm_rms_slope", "write_exr", "write_fit_report",
    "Distortion", "Intrinsics", "ObservedImage", "Sensor", "distort_image", "expected_dn", "noise_variance_dn", "observe",
    "pixel_solid_angles", "read_image", "saturated_mask", "write_observation",
]
