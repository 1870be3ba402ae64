"""Observation files: simulated DN written as 16-bit PNG, TIFF or FITS; references read from EXR, FITS, PNG, TIFF.

One module per idea: the formats and the sidecar's name (formats), the FITS header's sensor values,
row order and reader (fits), the PNG and TIFF readers (raster), :func:`read_image` with its masks
and the sidecar (reading), :func:`write_observation` (writing), and the sensor of a DN image with
the source of each value (provenance: :func:`sensor_of`, :func:`format_sensor_sources`). This face
hands on the names other modules import from ``spacefit.imageio``; it defines nothing.
"""

from spacefit.imageio.fits import ROW_ORDERS, RowOrderWarning
from spacefit.imageio.formats import RENDER_SPP_KEY, RESPONSES, UNITS, sidecar_path
from spacefit.imageio.provenance import SENSOR_DEFAULTS, format_sensor_sources, sensor_of
from spacefit.imageio.reading import ObservedImage, read_image
from spacefit.imageio.writing import write_observation

__all__ = [
    "RENDER_SPP_KEY",
    "RESPONSES",
    "ROW_ORDERS",
    "SENSOR_DEFAULTS",
    "UNITS",
    "ObservedImage",
    "RowOrderWarning",
    "format_sensor_sources",
    "read_image",
    "sensor_of",
    "sidecar_path",
    "write_observation",
]
