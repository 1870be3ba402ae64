"""The render job: a scene -> its checked assembly -> a render -> an output folder (:func:`render_to_folder`), and
one part of a scene written as STL (:func:`export_part_stl`). The fit jobs are :mod:`spacefit.pipeline`'s."""

from __future__ import annotations

import dataclasses
import math
import sys
import threading
import time
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_choice, check_path
from spacefit.geometry.mesh import export_stl
from spacefit.geometry.wrinkle import FOLD_WARN_FRACTION
from spacefit.interrupts import run_interruptibly
from spacefit.locks import holding_lock
from spacefit.output import prepare_output, staged_output, versions, write_render
from spacefit.progress import Progress, say
from spacefit.rendering.exr import write_exr
from spacefit.rendering.png import write_png
from spacefit.rendering.logs import errors_only, kernel_log
from spacefit.rendering.renderer import Renderer
from spacefit.rendering.parts import PartImage
from spacefit.scene.assembly import Assembly, assemble, fold_notes
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene


@holding_lock("out_dir")
def render_to_folder(scene: Scene, out_dir: str | Path, *, quiet: bool = False, overwrite: bool = False,
                     inputs: tuple[str | Path, ...] = (), timings_s: Mapping[str, float] = {},
                     show_timings: bool = False) -> tuple[np.ndarray, dict[str, Any]]:
    """Render ``scene`` and write radiance.exr, preview.png, scene.toml and render.json to ``out_dir``.

    It runs holding the folder's lock (one writer per folder: a second is refused, naming the folder). Every input is
    checked and the folder is checked (new, empty, or a previous render replaced only with ``overwrite``; none of the ``inputs`` files
    written over) before rendering; on any error or interruption nothing is left behind. Ctrl-C or
    SIGTERM during the render raises KeyboardInterrupt within about 0.1 s; the render goes on in the
    background to the end of its pass. A
    non-finite image is refused, naming the cause; an all-black one is written with a warning that
    says why. Returns the radiance image (W m^-2 sr^-1) and the sidecar dict as render.json holds it.

    The sidecar's ``timings_s`` holds the wall time (s) of each stage, after the caller's earlier
    ones (``timings_s``, e.g. the CLI's imports); ``show_timings`` prints them as a table on stderr,
    with the writing of the folder (which render.json cannot hold).

    Args:
        scene: the scene (:class:`Scene`).
        out_dir: the folder to write (made if missing; its parent must exist).
        quiet: print nothing.
        overwrite: replace a previous render in ``out_dir``.
        inputs: files the render reads (a mesh, the scene file), never written over.
        timings_s: the caller's earlier stages' wall times (s).
        show_timings: print the stages' times on stderr.

    Returns:
        The radiance image and the sidecar (render.json's content).

    Raises:
        InputError: a bad scene, a folder that is not empty (without ``overwrite``) or not writable,
            or one another process writes.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> image, sidecar = sf.render_to_folder(scene, "render", quiet=True)
        >>> import pathlib; sorted(p.name for p in pathlib.Path("render").iterdir())
        ['preview.png', 'radiance.exr', 'render.json', 'scene.toml']
    """
    check_scene(scene)
    prepare_output(check_path("out_dir", out_dir), "render", overwrite=overwrite, inputs=inputs)
    timings = dict(timings_s)
    # Ctrl-C / SIGTERM stop at once: Mitsuba's work runs in a thread the interruption abandons (a render has no step to keep)
    assembly, renderer, radiance, kernels = run_interruptibly(lambda stop: _render(scene, timings, stop, quiet))
    check_image(radiance, scene)

    def sidecar() -> dict[str, Any]:
        """The sidecar, computed while the EXR is written: the parts seen and their means, the notes."""
        t0 = time.perf_counter()
        parts = renderer.part_image()
        notes = dark_image_notes(radiance, parts, assembly)
        for note in notes:
            warnings.warn(note, stacklevel=4)
        notes = notes + fold_notes(assembly.folds, scene.wrinkles)  # these were warned when the scene was assembled
        content = {
            "warnings": notes,
            "scene": scene.to_dict(),
            "seed": scene.render.seed,
            "variant": renderer.variant,
            "units": {"radiance": "W m^-2 sr^-1 per RGB channel", "lengths": "m"},
            "triangles": {name: len(assembly.faces(name)) for name in assembly.parts},
            "parts": {"index": {name: i for i, name in enumerate(parts.names)},
                      "table": {name: {"pixels": int(n), "mean_radiance_w_m2_sr": float(mean)}
                                for name, n, mean in zip(parts.regions, *parts.means(radiance))},
                      "note": "part index -1 is space; pixels count for the part their centre sees"},
            "wrinkle_model": {name: dataclasses.asdict(choice) for name, choice in assembly.lod.items()},
            "fold_fraction": {"parts": dict(assembly.folds), "warn_above": FOLD_WARN_FRACTION,
                              "note": "fraction of a displaced part's faces turned more than 90 deg from the surface under them"},
            "mesh_cache": dict(assembly.cache),
            "kernels": kernels,
            "versions": versions(),
        }
        timings["part_ids"] = time.perf_counter() - t0
        return {**content, "timings_s": timings}

    t0 = time.perf_counter()
    written = write_render(out_dir, radiance, scene.to_toml(), sidecar, write_exr, write_png)
    if show_timings:
        print(timings_table({**timings, "write": time.perf_counter() - t0 - timings["part_ids"]}, assembly.cache, kernels),
              file=sys.stderr)
    say(f"wrote {Path(out_dir) / 'radiance.exr'} (max {radiance.max():.4g} W m^-2 sr^-1) in {timings['render']:.2f} s", quiet)
    return radiance, written


def _render(scene: Scene, timings: dict[str, float], stop: threading.Event,
            quiet: bool) -> tuple[Assembly, Renderer, np.ndarray, dict[str, float]]:
    """The Mitsuba work of :func:`render_to_folder`: assemble, load and render ``scene``, each stage's
    wall time added to ``timings``; ends after the current pass once ``stop`` is set."""
    t0 = time.perf_counter()
    assembly = assemble(scene)
    timings["assemble"] = time.perf_counter() - t0
    say(f"scene: {assembly.triangle_count():,} triangles, assembled in {timings['assemble']:.2f} s", quiet)
    t0 = time.perf_counter()
    renderer = Renderer(assembly)
    timings["load"] = time.perf_counter() - t0
    r = scene.render
    display = None if quiet else Progress(f"render {r.resolution[0]}x{r.resolution[1]} @ {r.spp} spp")

    def progress(done: int, total: int) -> None:
        if stop.is_set():  # abandoned after Ctrl-C: end after this pass
            raise KeyboardInterrupt
        if display is not None:
            display(done, total)

    t0 = time.perf_counter()
    with kernel_log() as kernels, errors_only():  # the render runs on this thread, whose kernels the log counts
        radiance = renderer.render(progress=progress)
    timings["render"] = time.perf_counter() - t0
    return assembly, renderer, radiance, kernels


def timings_table(timings: Mapping[str, float], cache: Mapping[str, str], kernels: Mapping[str, float]) -> str:
    """Where a render's wall time went, one stage a line, with the mesh cache's and Dr.Jit's kernel
    cache's outcome on the lines they explain."""
    notes = {"assemble": "mesh cache: " + (", ".join(f"{k} {v}" for k, v in cache.items()) or "nothing cached"),
             "render": f"{kernels['launched']} kernels, {kernels['compiled']} compiled (not in Dr.Jit's caches); "
                       f"code generation and compilation {kernels['compile_s']:.3f} s"}
    lines = [f"{'stage':<10} {'s':>7}"]
    lines += [f"{stage:<10} {seconds:>7.3f}  {notes.get(stage, '')}".rstrip() for stage, seconds in timings.items()]
    lines.append(f"{'total':<10} {sum(timings.values()):>7.3f}")
    return "\n".join(lines)


def check_image(radiance: np.ndarray, scene: Scene) -> None:
    """Refuse a render with non-finite pixels before anything is written, naming the likely cause."""
    bad = int(np.size(radiance) - np.count_nonzero(np.isfinite(radiance)))
    if bad:
        raise InputError(
            f"the render holds {bad} non-finite values (NaN or inf); nothing was written. Radiance is float32 "
            f"(at most 3.4e38): `sun.irradiance_w_m2` = {scene.sun.irradiance_w_m2:g} times a glint's BRDF may "
            "overflow it, as may a roughness near 0; lower them.")


def dark_image_notes(radiance: np.ndarray, parts: PartImage, assembly: Assembly) -> list[str]:
    """Why a render of a target is all black, in words (empty when some pixel is lit)."""
    if np.any(radiance > 0):
        return []
    if not np.any(parts.ids >= 0):
        return ["the image is black: no pixel centre sees the target (it is outside the view or smaller than a "
                "pixel); move the camera closer, lengthen `camera.focal_length_mm` or check `target.position_m`."]
    towards_sun = -assembly.sun_direction
    phase = math.degrees(math.acos(float(np.clip(towards_sun @ -assembly.camera.forward, -1.0, 1.0))))
    if phase > 90.0:
        return [f"the image is black: the sun is behind the target as the camera sees it (phase angle {phase:.0f} deg), "
                "so only its unlit side is in view; change `sun.direction`."]
    return ["the image is black although the target is in view and faces the sun: its parts reflect nothing towards "
            "the camera at this geometry (a mirror-like part's glints missed); raise `render.spp` or change the view."]


def export_part_stl(scene: Scene, part: str, path: str | Path) -> Path:
    """Write part ``part`` (wrinkled if the scene wrinkles it) as binary STL in the object frame."""
    check_choice("--part", part, scene.parts)
    out = Path(path)
    if out.suffix.lower() != ".stl":
        raise InputError(f"`--out` {str(out)!r} must end in .stl: export-stl writes binary STL.")
    if out.exists():
        raise InputError(f"{str(out)!r} exists; choose a new file name (spacefit never writes over a file it did not make).")
    assembly = assemble(scene)
    with staged_output(out.parent) as stage:
        export_stl(stage / out.name, np.asarray(assembly.object_vertices(part)), assembly.faces(part))
    return out
