"""Fitting scene parameters to reference images: parameters, losses, solvers."""

from spacefit.fit.losses import LOSSES as LOSSES
from spacefit.fit.params import available as available
from spacefit.fit.solve import SOLVERS as SOLVERS
from spacefit.fit.solve import FitResult as FitResult
from spacefit.fit.solve import Observation as Observation
from spacefit.fit.solve import Identifiability as Identifiability
from spacefit.fit.solve import fit as fit
from spacefit.fit.solve import identifiability as identifiability
