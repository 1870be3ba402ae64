"""Plates against the path tracer: the flat-plate light curve of a target derived from its own parts
(``sf.target_plates``) against the rendered light curve of the same scene, per phase angle and RMS,
in magnitudes and per cent (``sf.compare_plates_to_render``).

Targets: the built-in lander (the default scene), ``data/scenes/box-wing.toml`` and
``data/scenes/starlink-v1p5.toml``, each as shipped and, for the two with wrinkled insulation, with
the wrinkles off too (their parts' flat bases, which is what the plates have), and then at one
bounce (``render.depth`` 1, the plates' own), so that the wrinkles' share of the difference, the
second bounce's and the rest (parts shadowing and hiding each other, covered faces) show apart. The sun turns about the target from the camera's direction in the
camera's image plane (``phase_plane_sun``). The camera is moved along its line of sight to
``--range-m`` (10 km; the focal length scaled with it, ``sf.compare_plates_to_render(range_m=)``): the
plates see an unresolved target, every point of it seeing the observer in one direction, and the
scenes' own cameras, 70 m away, see their glints from a spread of directions (the lander's light curve
at 70 m differs from its light curve at 2 km by 2 to 40 %). The image is rendered at ``--resolution`` px
square with the pixel pitch scaled to keep each scene's field of view, at ``--spp`` samples, the
scenes' own depth unless stated.

Run: ``.venv/bin/python experiments/plates_vs_render.py [--resolution 200] [--spp 64] [--range-m 10000] [--phases 0 15 ... 150]``.
"""

from __future__ import annotations

import argparse
import datetime
import time
from pathlib import Path

from studyio import commit, machine

import spacefit as sf

ROOT = Path(__file__).resolve().parents[1]
BOX_WING, STARLINK = ROOT / "data" / "scenes" / "box-wing.toml", ROOT / "data" / "scenes" / "starlink-v1p5.toml"
# label: (scene file, None for the default; wrinkles on as shipped or off; render.depth, None: the scene's)
TARGETS = {
    "lander (default scene)": (None, True, None),
    "lander, wrinkles off": (None, False, None),
    "lander, wrinkles off, depth 1": (None, False, 1),
    "box-wing": (BOX_WING, True, None),
    "box-wing, wrinkles off": (BOX_WING, False, None),
    "box-wing, wrinkles off, depth 1": (BOX_WING, False, 1),
    "starlink-v1p5": (STARLINK, True, None),
}


def scene_of(path: Path | None, wrinkles: bool, depth: int | None, resolution: int, spp: int) -> sf.Scene:
    """The scene at ``resolution`` px square (pixel pitch scaled: the same field of view) and ``spp``,
    its wrinkles off unless ``wrinkles``, at ``depth`` bounces (None: its own)."""
    scene = sf.load_scene(path)
    width = scene.render.resolution[0]
    values = {"render.resolution": [resolution, resolution], "render.spp": spp,
              "camera.pixel_pitch_mm": scene.camera.pixel_pitch_mm * width / resolution}
    if not wrinkles:
        values["wrinkles.enabled"] = False
    if depth is not None:
        values["render.depth"] = depth
    return scene.with_values(values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=200)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--range-m", type=float, default=10000.0)
    parser.add_argument("--phases", type=float, nargs="+", default=[0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 135.0, 150.0])
    args = parser.parse_args()
    print(f"machine: {machine()}; date: {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC; commit {commit()}")
    print(f"command: .venv/bin/python experiments/plates_vs_render.py --resolution {args.resolution} --spp {args.spp} "
          f"--range-m {args.range_m:g} --phases {' '.join(f'{p:g}' for p in args.phases)}")
    summary = []
    for label, (path, wrinkles, depth) in TARGETS.items():
        scene = scene_of(path, wrinkles, depth, args.resolution, args.spp)
        start = time.perf_counter()
        comparison = sf.compare_plates_to_render(scene, phase_deg=args.phases, range_m=args.range_m)
        plates = sf.target_plates(scene)
        print(f"\n== {label}: {len(plates)} plates of {len({p.name for p in plates})} parts "
              f"({time.perf_counter() - start:.0f} s)")
        print(comparison.table())
        summary.append((label, comparison.rms_mag, comparison.rms_percent, comparison.largest_mag))
    print(f"\n{'target':<32s} {'RMS (mag)':>10s} {'RMS (%)':>8s} {'max |diff| (mag)':>17s}")
    for label, rms_mag, rms_percent, largest in summary:
        print(f"{label:<32s} {rms_mag:10.4f} {rms_percent:8.2f} {largest:17.4f}")


if __name__ == "__main__":
    main()
