"""The text of the units spacefit writes on its images, tables and stores: one home for each.

Quantities are SI throughout; these are the spellings of the two image units (a module of its own so that
tables and plots name them without importing the sensor model, which imports SciPy).
"""

RADIANCE_UNIT = "W m^-2 sr^-1"
"""The unit of rendered images and radiance references."""
DN_UNIT = "DN"
"""The unit of a sensor's digital numbers (ADC counts)."""
