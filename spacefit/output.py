"""Render outputs: a tone-mapped sRGB preview, the sidecar, and all-or-nothing writing of a folder.

Output folder layout of ``spacefit render``: ``radiance.exr`` (float RGB, W m^-2 sr^-1),
``preview.png`` (8-bit sRGB), ``scene.toml`` (the resolved scene: render it again to get the same
image) and ``render.json`` (the sidecar: scene, seed, tone map, timings, package versions).
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Any

import colour
import numpy as np
from PIL import Image

from spacefit.errors import InputError

PREVIEW_PERCENTILE = 99.5
PACKAGES = ("spacefit", "mitsuba", "drjit", "jax", "numpy", "trimesh", "colour-science", "optimistix")


def preview_scale(radiance: np.ndarray, percentile: float = PREVIEW_PERCENTILE) -> float:
    """Exposure scale (sr m^2 W^-1) mapping the given percentile of lit pixels' maximum channel to 1."""
    peak = radiance.max(axis=-1)
    lit = peak[peak > 0]
    return 1.0 / float(np.percentile(lit, percentile)) if lit.size else 1.0


def to_srgb8(radiance: np.ndarray, scale: float) -> np.ndarray:
    """Linear radiance times ``scale``, clipped to [0, 1], sRGB-encoded (IEC 61966-2-1) to uint8."""
    encoded = colour.cctf_encoding(np.clip(radiance * scale, 0.0, 1.0), function="sRGB")
    return np.round(np.asarray(encoded) * 255.0).astype(np.uint8)


def write_png(path: str | Path, rgb8: np.ndarray) -> None:
    """Write an (h, w, 3) uint8 image as PNG."""
    Image.fromarray(rgb8).save(path, format="PNG")


def versions() -> dict[str, str]:
    """Versions of Python and the packages that decide a render's pixels."""
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


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


@contextmanager
def staged_output(out_dir: str | Path) -> Iterator[Path]:
    """Yield a staging folder; on success its files move into ``out_dir``, on error nothing is left.

    Files already in ``out_dir`` with other names are kept; same names are replaced at the end only.
    """
    out = check_writable(out_dir)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".spacefit-", dir=out))
    try:
        yield stage
        for item in stage.iterdir():
            os.replace(item, out / item.name)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        if created:
            shutil.rmtree(out, ignore_errors=True)
        raise
    shutil.rmtree(stage, ignore_errors=True)


def write_text(path: str | Path, text: str) -> Path:
    """Write a text file all at once (staged, then moved into place)."""
    out = Path(path)
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
    sidecar: dict[str, Any],
    write_exr: Callable[[Path, np.ndarray], None],
) -> Path:
    """Write radiance.exr, preview.png, scene.toml and render.json into ``out_dir`` all at once."""
    scale = preview_scale(radiance)
    with staged_output(out_dir) as stage:
        write_exr(stage / "radiance.exr", radiance)
        write_png(stage / "preview.png", to_srgb8(radiance, scale))
        (stage / "scene.toml").write_text(scene_toml)
        write_json(stage / "render.json", {**sidecar, "preview": {"scale_sr_m2_per_W": scale, "percentile": PREVIEW_PERCENTILE, "encoding": "sRGB IEC 61966-2-1 (colour-science)"}})
    return Path(out_dir)
