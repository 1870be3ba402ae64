"""Materials of the lander's parts: value objects and the registry of named presets."""

from spacefit.materials.models import Conductor as Conductor
from spacefit.materials.models import DiffuseConductor as DiffuseConductor
from spacefit.materials.models import Lambert as Lambert
from spacefit.materials.models import Material as Material
from spacefit.materials.models import Mirror as Mirror
from spacefit.materials.registry import MODELS as MODELS
from spacefit.materials.registry import PRESETS as PRESETS
from spacefit.materials.registry import make_material as make_material
from spacefit.materials.registry import material_table as material_table
from spacefit.materials.registry import with_material_values as with_material_values
