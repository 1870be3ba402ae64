"""Materials of the lander's parts: one module per model, the registry of models and named presets."""

from spacefit.materials.conductor import Conductor as Conductor
from spacefit.materials.diffuse_conductor import DiffuseConductor as DiffuseConductor
from spacefit.materials.lambert import Lambert as Lambert
from spacefit.materials.mirror import Mirror as Mirror
from spacefit.materials.model import Field as Field
from spacefit.materials.model import Material as Material
from spacefit.materials.model import MaterialModel as MaterialModel
from spacefit.materials.oren_nayar import OrenNayar as OrenNayar
from spacefit.materials.registry import MODELS as MODELS
from spacefit.materials.registry import PRESETS as PRESETS
from spacefit.materials.registry import make_material as make_material
from spacefit.materials.registry import material_table as material_table
from spacefit.materials.registry import register_material as register_material
from spacefit.materials.registry import with_material_values as with_material_values
from spacefit.materials.tabulated import TabulatedBRDF as TabulatedBRDF
