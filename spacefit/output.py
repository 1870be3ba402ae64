"""Render outputs: a tone-mapped sRGB preview, the sidecar, and all-or-nothing writing of a folder.

Output folder layout of ``spacefit render``: ``radiance.exr`` (float RGB, W m^-2 sr^-1),
``preview.png`` (8-bit sRGB), ``scene.toml`` (the resolved scene: render it again to get the same
image) and ``render.json`` (the sidecar: scene, seed, tone map, timings, package versions).
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import platform
import shutil
import tempfile
import warnings
from collections.abc import Callable, Collection, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from spacefit.errors import InputError
from spacefit.locks import is_lock_file
from spacefit.versions import package_version

PREVIEW_PERCENTILE = 99.5
PACKAGES = ("spacefit", "mitsuba", "drjit", "jax", "numpy", "trimesh", "colour-science", "optimistix")


def preview_scale(radiance: np.ndarray, percentile: float = PREVIEW_PERCENTILE) -> float:
    """Exposure scale (sr m^2 W^-1) mapping the given percentile of lit pixels' maximum channel to 1."""
    peak = functools.reduce(np.maximum, np.moveaxis(radiance, -1, 0))  # radiance.max(axis=-1), 30x faster over 3 channels
    lit = peak[peak > 0]
    return 1.0 / float(np.percentile(lit, percentile)) if lit.size else 1.0


# Rows tone-mapped at a time: the encoding works in float64, a whole 16k image would need 6 GiB.
PREVIEW_ROWS = 256


def to_srgb8(radiance: np.ndarray, scale: float) -> np.ndarray:
    """Linear radiance times ``scale``, clipped to [0, 1], sRGB-encoded (IEC 61966-2-1) to uint8 (NaN: 0)."""
    out = np.zeros(radiance.shape, dtype=np.uint8)
    for top in range(0, radiance.shape[0], PREVIEW_ROWS):
        rows = radiance[top:top + PREVIEW_ROWS] * scale
        lit = rows > 0  # the rest is 0: only lit values are encoded (a target in black space: a few % of the film)
        out[top:top + PREVIEW_ROWS][lit] = np.round(srgb_encode(np.minimum(rows[lit], 1.0)) * 255.0)
    return out


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) of linear values in [0, 1]. Written out rather than
    taken from colour-science, whose import alone costs a render 1.5 s (a test holds them equal)."""
    linear = np.asarray(linear, dtype=float)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(np.maximum(linear, 0.0031308), 1 / 2.4) - 0.055)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """The inverse of :func:`srgb_encode`: linear values of sRGB-encoded values in [0, 1] (IEC 61966-2-1), written
    out for the same reason: colour-science's import (with Matplotlib's and pandas') costs a fit 1.5-4 s."""
    encoded = np.asarray(encoded, dtype=float)
    knee = 12.92 * 0.0031308  # where the encoding's two pieces meet (0.0404500)
    return np.where(encoded <= knee, encoded / 12.92, np.power((np.maximum(encoded, knee) + 0.055) / 1.055, 2.4))


def versions() -> dict[str, str]:
    """Versions of Python and the packages that decide a render's pixels."""
    return {"python": platform.python_version(), **{name: package_version(name) or "not installed" for name in PACKAGES}}


def check_writable(out_dir: str | Path) -> Path:
    """Fail early (before rendering) if ``out_dir`` cannot be created or written.

    Tries to create a file in the nearest existing folder, which also catches read-only file
    systems where permission bits would let root through.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"output folder {str(out)!r} exists and is not a folder.")
    probe = out if out.exists() else next((p for p in out.parents if p.exists()), Path("."))
    try:
        with tempfile.NamedTemporaryFile(dir=probe, prefix=".spacefit-probe-"):
            pass
    except OSError as err:
        raise InputError(f"output folder {str(out)!r} is not writable ({err.strerror} in {str(probe)!r}).") from None
    return out


STAGE_PREFIX = ".spacefit-stage-"
# The files each command writes into its output folder, and the one that marks it as spacefit's.
RESULT_FILES = {
    "render": ({"radiance.exr", "preview.png", "scene.toml", "render.json"}, "render.json"),
    # residuals.png: written by spacefit fit before 2026-11-29 (now comparison.png's third column); still a fit's file, so
    # --overwrite takes such a folder (and removes it with the previous result's other files the new one does not write)
    "fit": ({"fit.json", "fit.toml", "uncertainty.json", "comparison.png", "convergence.png", "residuals.fits", "residuals.png",
             "checkpoint.json", "frames.csv", "frames.png"}, "fit.json"),
    "light-curve-fit": ({"fit.json", "fit.toml", "uncertainty.json", "convergence.png", "observation0.png", "checkpoint.json"}, "fit.json"),
    "table-fit": ({"fit.json", "report.txt"}, "fit.json"),
}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale_stages(folder: Path, of: str = "") -> list[Path]:
    """Remove the staging folders in ``folder`` (those whose names end in ``of``) left by spacefit
    processes that no longer run (a SIGKILL leaves them), with a warning naming each; return them. A
    stage of a running process is left alone."""
    removed = []
    for stage in folder.glob(f"{STAGE_PREFIX}*") if folder.is_dir() else ():
        pid = stage.name[len(STAGE_PREFIX):].split("-", 1)[0]
        if stage.name.endswith(of) and pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(stage, ignore_errors=True)
            warnings.warn(f"removed {str(stage)!r}, a staging folder left by an interrupted spacefit run.", stacklevel=3)
            removed.append(stage)
    return removed


def _entries(out: Path) -> set[str]:
    """The names in an output folder but staging folders and locks."""
    return {p.name for p in out.iterdir() if not p.name.startswith(STAGE_PREFIX) and not is_lock_file(p.name)}


def previous_result(out_dir: str | Path, command: str) -> frozenset[str]:
    """The files of a previous spacefit ``command`` result in ``out_dir`` (which :func:`prepare_output` checked holds only
    such files) but its checkpoint: those a new result replaces whole (:func:`staged_output`'s ``replaces``)."""
    out = Path(out_dir)
    return frozenset(_entries(out) & RESULT_FILES[command][0] - {"checkpoint.json"}) if out.is_dir() else frozenset()


def _is_result(out: Path, command: str) -> bool:
    """Whether ``out`` holds a previous spacefit ``command`` result: only its files, its marker readable."""
    names, marker = RESULT_FILES[command]
    entries = _entries(out)
    if not entries <= names:
        return False
    if marker not in entries:
        return entries == {"checkpoint.json"}  # a fit killed before its first report
    try:
        return "spacefit" in json.loads((out / marker).read_text()).get("versions", {})
    except (OSError, ValueError, AttributeError):
        return False


def prepare_output(out_dir: str | Path, command: str, *, overwrite: bool = False, resume: bool = False,
                   inputs: tuple[str | Path, ...] = ()) -> Path:
    """Check an output folder before any work: it is new or empty, or holds a previous spacefit result
    of the same command and the user asked to replace it (``overwrite``) or to continue it
    (``resume``); no input file would be written over. Staging folders of dead spacefit processes in
    it are removed (with a warning naming them).

    Raises:
        InputError: naming the folder and what to do.
    """
    if not str(out_dir).strip():
        raise InputError("`--out` must name a folder, got an empty string.")
    out = check_writable(out_dir)
    if out.is_symlink() and not out.exists():
        raise InputError(f"`--out` {str(out)!r} is a symbolic link to {os.readlink(out)!r}, which does not exist: spacefit writes "
                         "into a folder, never through a dangling link; remove the link or choose another folder.")
    names, _ = RESULT_FILES[command]
    for path in inputs:
        p = Path(path)
        if p.exists() and p.resolve().parent == out.resolve() and p.name in names:
            raise InputError(f"input file {str(p)!r} is in the output folder {str(out)!r} and would be written over; "
                             "choose another `--out`.")
    if not out.exists():
        return out
    clean_stale_stages(out)
    if not _entries(out):
        return out
    if not _is_result(out, command):
        foreign = sorted(_entries(out) - names)
        held = (f"files spacefit did not write ({', '.join(foreign[:8])}{', ...' if len(foreign) > 8 else ''})"
                if foreign else f"part of a spacefit {command} result without a readable {RESULT_FILES[command][1]}")
        raise InputError(f"output folder {str(out)!r} holds {held}; choose a new or empty folder.")
    if not (overwrite or resume):
        raise InputError(f"output folder {str(out)!r} holds a previous spacefit {command} result; pass --overwrite "
                         "(overwrite=True) to replace it, or choose a new folder.")
    return out


@contextmanager
def staged_output(out_dir: str | Path, replaces: Collection[str] = ()) -> Iterator[Path]:
    """Yield a staging folder; on success its files move into ``out_dir``, on error nothing is left.

    Files already in ``out_dir`` with other names are kept; same names are replaced at the end only, and the files named
    in ``replaces`` (a previous result's, :func:`previous_result`) that the stage does not hold are removed after them.
    On an error or interruption only what this call created goes: its stage, and ``out_dir`` if
    this call created it and it is still empty (another process may have written there since).
    """
    out = check_writable(out_dir)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}-", dir=out))
    try:
        yield stage
        written = {item.name for item in stage.iterdir()}
        for name in written:
            os.replace(stage / name, out / name)
        for name in set(replaces) - written:
            (out / name).unlink(missing_ok=True)
    except BaseException as err:
        shutil.rmtree(stage, ignore_errors=True)
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()  # only if empty
        if isinstance(err, OSError) and err.errno and not (err.filename and Path(err.filename).parent != stage):
            # name the file of ``out_dir`` that failed (not its staged copy), or the folder when no file is named
            raise type(err)(err.errno, err.strerror, str(out / Path(err.filename).name if err.filename else out)) from None
        raise
    shutil.rmtree(stage, ignore_errors=True)


def write_text(path: str | Path, text: str) -> Path:
    """Write a text file all at once (staged, then moved into place). An existing ``path`` that is not a
    regular file (a folder, a device such as /dev/null or /dev/stdout, a pipe) is refused: moving a file
    into place would replace it."""
    out = Path(path)
    if out.exists() and not out.is_file():
        raise InputError(f"{str(out)!r} is not a regular file (a folder, a device or a pipe): spacefit writes a whole new "
                         "file in place of a regular file only; choose a file name.")
    with staged_output(out.parent if str(out.parent) else ".") as stage:
        (stage / out.name).write_text(text)
    return out


def write_json(path: str | Path, data: dict[str, Any]) -> None:
    """Write a strict JSON file (sorted keys, 2-space indent): a non-finite number is written as null,
    and a top-level ``"nonfinite_as_null"`` note says so."""
    plain = json.loads(json.dumps(data, default=_jsonable))  # numpy values -> Python, NaN still a float
    strict, replaced = _finite_or_null(plain)
    if replaced:
        strict["nonfinite_as_null"] = "NaN and infinite numbers are written as null (strict JSON)"
    Path(path).write_text(json.dumps(strict, indent=2, sort_keys=True, allow_nan=False) + "\n")


def _finite_or_null(value: Any) -> tuple[Any, bool]:
    """``value`` with every non-finite float replaced by None, and whether any was."""
    if isinstance(value, float):
        return (value, False) if math.isfinite(value) else (None, True)
    if isinstance(value, dict):
        items = {k: _finite_or_null(v) for k, v in value.items()}
        return {k: v for k, (v, _) in items.items()}, any(r for _, r in items.values())
    if isinstance(value, list):
        items = [_finite_or_null(v) for v in value]
        return [v for v, _ in items], any(r for _, r in items)
    return value, False


def _jsonable(value: Any) -> Any:
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, (np.ndarray, tuple)):
        return list(np.asarray(value).tolist())
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def write_render(
    out_dir: str | Path,
    radiance: np.ndarray,
    scene_toml: str,
    sidecar: Callable[[], dict[str, Any]],
    write_exr: Callable[[Path, np.ndarray], None],
    write_png: Callable[[Path, np.ndarray], None],
) -> dict[str, Any]:
    """Write radiance.exr, preview.png, scene.toml and render.json into ``out_dir`` all at once, through
    the given writers (the rendering package's, :mod:`spacefit.rendering.exr` and :mod:`spacefit.rendering.png`),
    and return the sidecar written. The EXR is written in a thread from the start, meanwhile
    ``sidecar()`` computes the sidecar and the others are written (Mitsuba's encoders release the GIL)."""
    with staged_output(out_dir) as stage:
        with ThreadPoolExecutor(1, thread_name_prefix="spacefit-exr") as pool:  # waits for the EXR, even after an error
            exr = pool.submit(write_exr, stage / "radiance.exr", radiance)
            written = sidecar()
            scale = preview_scale(radiance)
            write_png(stage / "preview.png", to_srgb8(radiance, scale))
            (stage / "scene.toml").write_text(scene_toml)
            written = {**written, "preview": {"scale_sr_m2_per_W": scale, "percentile": PREVIEW_PERCENTILE, "encoding": "sRGB IEC 61966-2-1"}}
            write_json(stage / "render.json", written)
        exr.result()
    return written
