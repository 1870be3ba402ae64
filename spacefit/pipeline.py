"""The main jobs: scene -> checked assembly -> render -> output folder, and reference files -> fit -> report."""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_choice
from spacefit.fitting.report import write_fit_report
from spacefit.fitting.loop import FitResult, fit
from spacefit.fitting.problem import Observation
from spacefit.geometry.mesh import export_stl
from spacefit.output import check_writable, staged_output, versions, write_render
from spacefit.progress import Progress
from spacefit.rendering.exr import read_exr, write_exr
from spacefit.rendering.renderer import Renderer
from spacefit.scene.assembly import assemble
from spacefit.scene.config import Scene, load_scene, parse_override
from spacefit.scene.parameters import scene_keys


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
    parts = renderer.part_image()
    sidecar = {
        "scene": scene.to_dict(),
        "seed": r.seed,
        "variant": renderer.variant,
        "units": {"radiance": "W m^-2 sr^-1 per RGB channel", "lengths": "m"},
        "triangles": {name: len(assembly.faces(name)) for name in assembly.parts},
        "parts": {"index": {name: i for i, name in enumerate(parts.names)}, "table": parts.table(radiance),
                  "note": "part index -1 is space; pixels count for the part their centre sees"},
        "wrinkle_model": {name: dataclasses.asdict(choice) for name, choice in assembly.lod.items()},
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


def fit_to_folder(
    references: Sequence[str | Path],
    scenes: Sequence[str | Path],
    free: Sequence[str],
    out_dir: str | Path,
    *,
    overrides: Sequence[str] = (),
    resolution: tuple[int, int] | None = None,
    sigma: float | None = None,
    quiet: bool = False,
    **options: Any,
) -> FitResult:
    """Fit the ``free`` parameters to reference EXR files; write fit.json and the plots to ``out_dir``.

    Every input is checked before rendering (the folder is checked writable first); on any error
    nothing is left behind.

    Args:
        references: reference radiance images (OpenEXR, W m^-2 sr^-1), fitted jointly.
        scenes: scene TOML files: one for all references, or one per reference in order.
        free: parameter names (see :mod:`spacefit.scene.parameters`); their start values are the first
            scene's unless ``start`` is given.
        out_dir: output folder of the report (see :mod:`spacefit.fitting.report`).
        overrides: ``key=value`` scene overrides applied to every scene; none may fix a free parameter.
        resolution: (width, height) px replacing every scene's ``render.resolution``; the
            references must have that size.
        sigma: noise standard deviation of the references, W m^-2 sr^-1 (residuals are divided by it).
        quiet: no progress display or messages on stderr.
        options: keyword arguments of :func:`spacefit.fitting.fit` (``solver``, ``loss``, ``start``,
            ``spp``, ``spp_grad``, ``max_steps``, ...).

    Returns:
        The fit's result.
    """
    check_writable(out_dir)
    if len(scenes) not in (1, len(references)):
        raise InputError(
            "give one scene for all references or one per reference; "
            f"got {len(scenes)} scenes for {len(references)} references."
        )
    _check_not_fixed(free, overrides)
    t0 = time.perf_counter()
    scene_overrides = [*overrides, *([f"render.resolution=[{resolution[0]}, {resolution[1]}]"] if resolution else [])]
    loaded = [load_scene(path, scene_overrides) for path in scenes]
    images = [read_exr(path) for path in references]
    observations = [Observation(loaded[i % len(loaded)], image, sigma) for i, image in enumerate(images)]
    t_read = time.perf_counter() - t0
    display, last = Progress(f"fit {', '.join(free)}"), [0, 0]

    def progress(step: int, total: int) -> None:
        last[:] = step, total
        if not quiet:
            display(step, total)

    t0 = time.perf_counter()
    result = fit(observations, free, progress=progress, **options)
    t_fit = time.perf_counter() - t0
    if not quiet and last[0] < last[1]:
        display(last[0], last[0])  # the solve stopped before its step limit: end the display there
    inputs = {
        "references": [str(path) for path in references],
        "scene_files": [str(path) for path in scenes],
        "overrides": scene_overrides,
        "scenes": [scene.to_dict() for scene in loaded],
        "sigma": sigma,
        "options": options,
    }
    timings = {"read_inputs": t_read, "setup": t_fit - result.wall_time_s}
    write_fit_report(out_dir, result, images, inputs=inputs, timings_s=timings)
    _say(f"wrote {Path(out_dir) / 'fit.json'}, comparison.png and convergence.png", quiet)
    return result


def _check_not_fixed(free: Sequence[str], overrides: Sequence[str]) -> None:
    """Refuse an override of a free parameter: the fit would replace it without a word."""
    for text in overrides:
        key = ".".join(parse_override(text)[0])
        for name in free:
            if key in scene_keys(name):
                raise InputError(
                    f"`{name}` is both free and fixed by the override {text!r}; drop the override "
                    f"(its start value can be given as `start`, --start {name}=VALUE)."
                )
