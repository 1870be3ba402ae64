"""A simulated pass: frame geometry along an arc over the target, and each frame rendered and observed
by a sensor into a folder with its frame table (the pass a fit then reads back, :mod:`spacefit.fitting.passes`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from astropy.table import Table

from spacefit.errors import InputError, check_count
from spacefit.formation import observe
from spacefit.imageio import RENDER_SPP_KEY, write_observation
from spacefit.rendering.exr import write_exr
from spacefit.rendering.renderer import render
from spacefit.scene.assembly import assemble
from spacefit.scene.parameters import scene_value
from spacefit.fitting.passes import COMPONENTS, VECTOR_KEYS, Pass
from spacefit.scene.schema import Scene


def arc_pass(n: int, *, range_m: float = 25.0, zenith_deg: tuple[float, float] = (4.0, 16.0),
             azimuth_deg: tuple[float, float] = (0.0, 40.0), sun_elevation_deg: tuple[float, float] = (82.0, 78.0),
             sun_azimuth_deg: float = 200.0) -> list[dict[str, Any]]:
    """The scene values of ``n`` frames of a synthetic pass: an observer at ``range_m`` from the
    origin, looking at it, moving evenly from (zenith angle, azimuth) = (``zenith_deg[0]``,
    ``azimuth_deg[0]``) to the second values, and the sun's elevation changing evenly between
    ``sun_elevation_deg``'s (azimuth fixed). By default the observer crosses the panels' glint
    (the sun's mirror direction, 10 deg from the zenith at azimuth 20 deg) half-way. Each frame: ``camera.position_m``, ``camera.look_at_m``
    (the origin), ``sun.elevation_deg``, ``sun.azimuth_deg``.

    Args:
        n: the number of frames, >= 1.
        range_m: the observer's distance from the origin (m).
        zenith_deg, azimuth_deg: the observer's first and last direction (deg).
        sun_elevation_deg: the sun's first and last elevation (deg).
        sun_azimuth_deg: the sun's azimuth (deg).

    Returns:
        One dict of scene values per frame, for :func:`simulate_pass` or ``Scene.with_values``.

    Raises:
        InputError: ``n`` < 1 or a value out of range.

    Example:
        >>> import spacefit as sf
        >>> frames = sf.arc_pass(3)
        >>> sorted(frames[0])
        ['camera.look_at_m', 'camera.position_m', 'sun.azimuth_deg', 'sun.elevation_deg']
    """
    check_count("n", n)
    out = []
    for s in np.linspace(0.0, 1.0, n) if n > 1 else [0.0]:
        theta = math.radians(zenith_deg[0] + s * (zenith_deg[1] - zenith_deg[0]))
        phi = math.radians(azimuth_deg[0] + s * (azimuth_deg[1] - azimuth_deg[0]))
        position = [range_m * math.sin(theta) * math.cos(phi), range_m * math.sin(theta) * math.sin(phi), range_m * math.cos(theta)]
        out.append({"camera.position_m": [round(v, 9) for v in position], "camera.look_at_m": [0.0, 0.0, 0.0],
                    "sun.elevation_deg": round(sun_elevation_deg[0] + s * (sun_elevation_deg[1] - sun_elevation_deg[0]), 9),
                    "sun.azimuth_deg": sun_azimuth_deg})
    return out


def simulate_pass(scene: Scene, frames: Sequence[Mapping[str, Any]], out_dir: str | Path, *,
                  truth: Mapping[str, Any] | None = None, errors: Sequence[Mapping[str, float]] = (),
                  sensor: Any = None, spp: int = 256, seed: int = 7, interval_s: float = 10.0) -> Pass:
    """Simulate a pass and write it: per frame k an observation ``frame<k>.fits`` (DN through
    ``sensor``'s model, :func:`observe`, the sensor in its header and
    sidecar) or, without a sensor, ``frame<k>.exr`` (radiance), rendered at ``spp`` from ``scene``
    with ``frames[k]``'s values (the FITS card or EXR attribute ``RENDSPP`` says ``spp``), ``truth`` (every frame) and ``errors[k]`` (the frame's own
    departures from its nominal values, e.g. ``{"target.attitude_x_deg": 0.2}``, added to the
    nominal); and ``frames.csv``, the frame table of the nominal values (without the errors), times
    ``interval_s`` apart.

    Returns:
        The :class:`Pass` read back from ``frames.csv``.

    Raises:
        InputError: a value refused by the scene, ``errors`` not one per frame, an existing ``out_dir``.

    Args:
        scene: the scene of every frame.
        frames: each frame's scene values (:func:`arc_pass`).
        out_dir: a new folder.
        truth: values every frame takes (the true parameters).
        errors: per frame, departures from its nominal values.
        sensor: a :class:`Sensor` for DN frames (FITS), or None for radiance (EXR).
        spp: the frames' samples per pixel.
        seed: the first frame's seed (and the noise's).
        interval_s: the time between frames (s).

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> frames = sf.simulate_pass(scene, sf.arc_pass(2), "pass", spp=4)
        >>> [frame.file.name for frame in frames.frames]
        ['frame0.exr', 'frame1.exr']
    """
    errors = list(errors) or [{}] * len(frames)
    if len(errors) != len(frames):
        raise InputError(f"`errors` must give one mapping per frame ({len(frames)}), got {len(errors)}.")
    out = Path(out_dir)
    if out.exists():
        raise InputError(f"`out_dir` {str(out)!r} exists; simulate_pass writes a new folder.")
    nominal = [scene.with_values({**dict(truth or {}), **dict(f)}) for f in frames]
    true = [s.with_values({name: scene_value(s, name) + dx for name, dx in e.items()}) for s, e in zip(nominal, errors)]
    out.mkdir(parents=True)
    columns: dict[str, list[Any]] = {"file": [], "time": []}
    for k, s in enumerate(true):
        radiance = render(s.with_values({"render.spp": spp, "render.seed": seed + k}))
        if sensor is None:
            name = f"frame{k}.exr"
            write_exr(out / name, radiance, header={RENDER_SPP_KEY: spp})
        else:
            name = f"frame{k}.fits"
            write_observation(out / name, observe(radiance, sensor, assemble(s).intrinsics, seed=seed + k), sensor, render_spp=spp)
        columns["file"].append(name)
        columns["time"].append(k * interval_s)
    keys = list(dict.fromkeys(key for f in frames for key in f))
    for key in keys:
        cells = [f[key] for f in frames]
        if key in VECTOR_KEYS:
            for c, axis in enumerate(COMPONENTS):
                columns[f"{key}.{axis}"] = [float(v[c]) for v in cells]
        else:
            columns[key] = cells
    Table(columns).write(out / "frames.csv")
    return Pass.read(out / "frames.csv")
