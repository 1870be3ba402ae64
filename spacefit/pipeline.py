"""The simulator's main job: scene -> checked assembly -> render -> output folder."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import check_choice
from spacefit.geometry.mesh import export_stl
from spacefit.output import check_writable, staged_output, versions, write_render
from spacefit.progress import Progress
from spacefit.render.exr import write_exr
from spacefit.render.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.config import Scene


def _say(message: str, quiet: bool) -> None:
    if not quiet:
        print(message, file=sys.stderr, flush=True)


def render_to_folder(scene: Scene, out_dir: str | Path, *, quiet: bool = False) -> tuple[np.ndarray, dict[str, Any]]:
    """Render ``scene`` and write radiance.exr, preview.png, scene.toml and render.json to ``out_dir``.

    Every input is checked and the folder is checked writable before rendering; on any error no
    file is left behind. Returns the radiance image (W m^-2 sr^-1) and the sidecar dict.
    """
    check_writable(out_dir)
    t0 = time.perf_counter()
    assembly = assemble(scene)
    t_assemble = time.perf_counter() - t0
    _say(f"scene: {assembly.triangle_count():,} triangles, assembled in {t_assemble:.2f} s", quiet)
    t0 = time.perf_counter()
    renderer = Renderer(assembly)
    t_load = time.perf_counter() - t0
    r = scene.render
    t0 = time.perf_counter()
    radiance = renderer.render(progress=None if quiet else Progress(f"render {r.resolution[0]}x{r.resolution[1]} @ {r.spp} spp"))
    t_render = time.perf_counter() - t0
    sidecar = {
        "scene": scene.to_dict(),
        "seed": r.seed,
        "variant": renderer.variant,
        "units": {"radiance": "W m^-2 sr^-1 per RGB channel", "lengths": "m"},
        "triangles": {name: len(assembly.faces(name)) for name in assembly.parts},
        "timings_s": {"assemble": t_assemble, "load": t_load, "render": t_render},
        "versions": versions(),
    }
    write_render(out_dir, radiance, scene.to_toml(), sidecar, write_exr)
    _say(f"wrote {Path(out_dir) / 'radiance.exr'} (max {radiance.max():.4g} W m^-2 sr^-1) in {t_render:.2f} s", quiet)
    return radiance, sidecar


def export_part_stl(scene: Scene, part: str, path: str | Path) -> Path:
    """Write part ``part`` (wrinkled if the scene wrinkles it) as binary STL in the object frame."""
    check_choice("--part", part, scene.parts)
    assembly = assemble(scene)
    out = Path(path)
    with staged_output(out.parent) as stage:
        export_stl(stage / out.name, np.asarray(assembly.object_vertices(part)), assembly.faces(part))
    return out
