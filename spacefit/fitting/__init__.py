"""Fitting scene parameters to reference images: set-up, solvers, uncertainty and the fit loop."""
