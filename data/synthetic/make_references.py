"""Render the synthetic reference cases into data/synthetic/, from the package's case files.

Every case of ``spacefit/synthetic/cases.toml`` that has a scene file of its own there (the package
data :func:`spacefit.load_case` reads).

For case NAME this writes the folder ``data/synthetic/NAME/`` (beside this script) all at once:

* ``reference.exr``: radiance (W m^-2 sr^-1), rendered with the scene's own seed (7); each EXR's
  header says the render's samples per pixel (``RENDSPP``: the goodness of fit counts its noise);
* ``preview.png``: 8-bit sRGB preview (99.5th percentile of lit pixels at white);
* ``reference_noise2.exr``, ``reference_noise5.exr``: the reference plus Gaussian noise, independent
  per pixel and channel, of standard deviation 2 % / 5 % of the mean radiance of the lit pixels
  (:func:`spacefit.cases.add_noise`, the one noise recipe);
* ``truth.json``: the free parameters' true values (the scene's), the seeds, each noisy file's
  sigma, the resolved scene, timings and package versions.

Run: ``.venv/bin/python data/synthetic/make_references.py [CASE ...]`` (default: every case), or
``make synthetic``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any


import spacefit as sf
from spacefit.cases import CASES_DIR, add_noise
from spacefit.errors import check_choice
from spacefit.imageio import RENDER_SPP_KEY
from spacefit.output import preview_scale, staged_output, to_srgb8, versions, write_json
from spacefit.progress import Progress
from spacefit.rendering.exr import write_exr
from spacefit.rendering.png import write_png

HERE = Path(__file__).resolve().parent
NOISE_PERCENT = (2, 5)


def make_case(name: str) -> dict[str, Any]:
    """Render case ``name`` into ``HERE / name`` and return its truth record."""
    case = sf.load_case(name)
    scene, names = case.truth_scene, case.free
    t0 = time.perf_counter()
    renderer = sf.Renderer(scene)
    t_load = time.perf_counter() - t0
    r = scene.render
    t0 = time.perf_counter()
    radiance = renderer.render(progress=Progress(f"{name} {r.resolution[0]}x{r.resolution[1]} @ {r.spp} spp"))
    t_render = time.perf_counter() - t0
    truth: dict[str, Any] = {
        "case": name,
        "cases_entry": name,
        "free": list(names),
        "truth": case.truth,
        "seed": r.seed,
        "variant": renderer.variant,
        "mean_lit_radiance_w_m2_sr": float(radiance[radiance.max(axis=-1) > 0].mean()),
        "noise": {},
        "units": {"radiance": "W m^-2 sr^-1 per RGB channel", "lengths": "m"},
        "scene": scene.to_dict(),
        "timings_s": {"assemble_and_load": t_load, "render": t_render},
        "versions": versions(),
    }
    with staged_output(HERE / name) as stage:
        rendered = {RENDER_SPP_KEY: r.spp}  # the goodness of fit counts the references' own render noise
        write_exr(stage / "reference.exr", radiance, header=rendered)
        write_png(stage / "preview.png", to_srgb8(radiance, preview_scale(radiance)))
        for percent in NOISE_PERCENT:
            noisy, sigma = add_noise(radiance, percent, r.seed)
            file = f"reference_noise{percent}.exr"
            write_exr(stage / file, noisy, header=rendered)
            truth["noise"][file] = {
                "percent_of_mean_lit_radiance": percent, "sigma_w_m2_sr": sigma, "seed": [r.seed, percent]
            }
        write_json(stage / "truth.json", truth)
    return truth


def main() -> None:
    cases = [name for name in sf.case_names() if (CASES_DIR / f"{name}.toml").is_file()]  # derived cases have no files
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="*", metavar="CASE", help=f"cases to render (default: all of {', '.join(cases)})")
    args = p.parse_args()
    for name in args.cases or cases:
        truth = make_case(check_choice("CASE", name, cases))
        print(f"{name}: {truth['truth']} -> {HERE / name}")


if __name__ == "__main__":
    main()
