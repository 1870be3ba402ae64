"""The peer for tests/test_earthshine.py: lumos-sat 1.0.9's Earthshine (Fankhauser, Tyson & Askari 2023)
on a flat Lambert plate, written to ``experiments/results/earthshine/lumos_earthshine.csv``.

Runs in lumos-sat's own environment (``python3 -m venv .venv-lumos && .venv-lumos/bin/pip install
lumos-sat==1.0.9``; or its source on ``PYTHONPATH``: the calculator needs numpy and astropy only):
``.venv-lumos/bin/python experiments/earthshine_lumos.py``.

For each geometry (a 550 km satellite at an angle past the terminator, an observer on the ground
in the satellite's view, a plate's normal with the observer in front of it), the irradiance at the
observer of a plate of 1 m^2 and albedo 0.5 (``LAMBERTIAN(0.5)``) lit by the Earth alone
(``include_sun=False``), under a Lambert Earth of albedo 0.3 and under the paper's vegetation Phong
Earth (``PHONG(0.53, 0.28, 7.31)``), each with 601 x 601 panels (its mesh converged: 601 panels
differ from 1201 by under 2e-4 %). The geometry is lumos-sat's brightness frame: z from the Earth's
centre through the satellite, the sun in the y-z plane at (0, cos a, -sin a), the Earth's radius
6378 km (its ``EARTH_RADIUS``).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

import lumos.brdf.library
import lumos.calculator
import lumos.constants
import lumos.geometry

OUT = Path(__file__).resolve().parents[1] / "experiments" / "results" / "earthshine" / "lumos_earthshine.csv"
HEIGHT_M = 550e3
DENSITY = 601
EARTHS = {"lambert": lumos.brdf.library.LAMBERTIAN(0.3), "vegetation": lumos.brdf.library.PHONG(0.53, 0.28, 7.31)}
# angle past the terminator (deg), the observer's angle from the sub-satellite point and its azimuth (deg), the plate's normal
GEOMETRIES = [
    (-30.0, 0.0, 0.0, (0.0, 0.0, -1.0)),
    (-10.0, 8.0, 90.0, (0.0, 0.0, -1.0)),
    (0.0, 12.0, 200.0, (0.0, 0.0, -1.0)),
    (10.0, 5.0, 300.0, (0.0, 0.0, -1.0)),
    (20.0, 15.0, 45.0, (0.0, 0.0, -1.0)),
    (-20.0, 10.0, 90.0, (0.0, math.sqrt(0.5), -math.sqrt(0.5))),
    (5.0, 10.0, 270.0, (0.6, -0.48, -0.64)),
]


def main() -> None:
    """Write the peer's irradiances (module docstring)."""
    R = lumos.constants.EARTH_RADIUS
    rows = []
    for past, off, azimuth, normal in GEOMETRIES:
        theta, psi = math.radians(off), math.radians(azimuth)
        observer = R * np.array([math.sin(theta) * math.cos(psi), math.sin(theta) * math.sin(psi), math.cos(theta)])
        plate = lumos.geometry.Surface(1.0, np.array(normal), lumos.brdf.library.LAMBERTIAN(0.5))
        row = {"past_terminator_deg": past, "observer_x_m": observer[0], "observer_y_m": observer[1], "observer_z_m": observer[2],
               "normal_x": normal[0], "normal_y": normal[1], "normal_z": normal[2]}
        for name, earth in EARTHS.items():
            row[f"{name}_w_m2"] = float(lumos.calculator.get_intensity_satellite_frame(
                [plate], HEIGHT_M, math.radians(past), observer, include_sun=False, include_earthshine=True,
                earth_panel_density=DENSITY, earth_brdf=earth))
        rows.append(row)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    with open(OUT, "w", newline="") as f:
        f.write(f"# lumos-sat 1.0.9 Earthshine on a 1 m^2 Lambert plate (albedo 0.5), {HEIGHT_M / 1e3:g} km, {DENSITY} panels: "
                "experiments/earthshine_lumos.py\n")
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
