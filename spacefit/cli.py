"""Command line: ``spacefit render|scene|export-stl [SCENE.toml] --out PATH [--set key=value ...]`` and
``spacefit fit REFERENCE ... --scene SCENE.toml --free NAME[,NAME...] --out DIR [--mask M] [--sensor S]``,
``spacefit fit-light-curve CURVE --scene SCENE.toml --free NAME[,NAME...] --out DIR [--resume]``,
``spacefit sweep SWEEP.toml --out STORE``, ``spacefit sweep STORE --verify``."""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import time
from pathlib import Path
from collections.abc import Sequence
from typing import TYPE_CHECKING

from spacefit.interrupts import Terminated, abandoned, caught, deferred_interrupts

# A Ctrl-C or SIGTERM while the modules below load (0.2 s, seconds under load) waits for their end and
# is answered by main like any other (130 / 143, one line): Python's default would print a traceback.
with deferred_interrupts() as _STARTUP:
    from spacefit.errors import InputError, check_range, shorten
    from spacefit.executors import ClusterError, check_cluster
    from spacefit.output import write_text
    from spacefit.scene.overrides import toml_value
    from spacefit.scene.parameters import PARAMETERS

if TYPE_CHECKING:
    from spacefit.fitting.result import FitResult
    from spacefit.fitting.status import Status
    from spacefit.studies.orbit import Site

# Exit codes of `spacefit fit` that is not a success (its report is written in each case).
NOT_CONVERGED = 3  # the solver stopped without converging (step limit, divergence, NaN)
NO_PROGRESS = 4  # no step lowered the loss: the values are the start
MISFIT = 5  # the residuals exceed the noise: the model or its nuisances miss something
AT_BOUND = 6  # a parameter ended at a bound of its range
UNJUDGED = 9  # the model's own render noise is above the data's: the residuals could not be judged
INTERRUPTED = 130  # 128 + SIGINT, as shells report Ctrl-C
TERMINATED = 143  # 128 + SIGTERM
# The commands that fit, and what their exit codes say.
FITS = ("fit", "fit-light-curve")
FIT_EXIT_CODES = (f"0 converged, 1 file system error, 2 bad input, {NOT_CONVERGED} not converged, {NO_PROGRESS} no progress (no "
                  f"step lowered the loss), {MISFIT} misfit (chi^2/dof beyond its expected range: the model misses something), "
                  f"{AT_BOUND} a parameter at a bound, {UNJUDGED} not judged (the model's render noise above the data's: render "
                  f"with more samples), {INTERRUPTED} Ctrl-C, {TERMINATED} SIGTERM; the report is written for 0, 3 to 6 and 9.")
# Exit codes of `spacefit sweep STORE --verify` that is not a success.
DAMAGED = 7  # a done point failed its checksum, or a variable is missing: rerun the sweep to recompute them
UNFINISHED = 8  # every done point verifies, but some points are not done yet


def _free_help(command: str | None) -> str:
    """Help of ``--free``: the parameter registry, listed only for ``spacefit fit`` and ``fit-light-curve``."""
    text = "parameters to fit, e.g. parts.panels.alpha_x,parts.legs.kd (P: a part's name)"
    if command not in FITS:
        return text + "; see spacefit fit --help"
    return text + ": " + ", ".join(f"{p.pattern} [{p.unit}] {p.bounds.describe()}" for p in PARAMETERS.values())


def _parser(command: str | None = "fit") -> argparse.ArgumentParser:
    """The command line's parser; ``command`` (the first argument) decides whether ``fit --free``'s
    help lists the parameter registry."""
    p = argparse.ArgumentParser(prog="spacefit", description="Simulate and fit images of space targets.")
    overrides = argparse.ArgumentParser(add_help=False)
    overrides.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                           help="set a scene value by scene-file key or parameter name, e.g. --set camera.focal_length_mm=5000 "
                                "or --set sun.elevation_deg=30 (repeatable)")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", parents=[overrides],
                       help="render a scene to radiance.exr, preview.png, scene.toml, render.json")
    r.add_argument("scene", nargs="?", help="scene TOML file (default: the thesis's Table 4-2 scene)")
    r.add_argument("--out", required=True, help="output folder (new, empty, or a previous render with --overwrite)")
    r.add_argument("--overwrite", action="store_true", help="replace a previous render in --out")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    r.add_argument("--timings", action="store_true", help="print where the time went (also in render.json: timings_s)")
    w = sub.add_parser("scene", parents=[overrides],
                       help="write the resolved scene (defaults: Table 4-2) as TOML to start from")
    w.add_argument("scene", nargs="?", help="scene TOML file to resolve (default: the thesis's scene)")
    w.add_argument("--out", required=True, help="TOML file to write (not an existing file unless --overwrite)")
    w.add_argument("--overwrite", action="store_true", help="replace an existing file (never the input scene)")
    e = sub.add_parser("export-stl", parents=[overrides], help="write a part (wrinkled body by default) as binary STL")
    e.add_argument("scene", nargs="?", help="scene TOML file (default: the thesis's scene)")
    e.add_argument("--part", default="body")
    e.add_argument("--out", required=True, help="STL file to write")
    f = sub.add_parser("fit", parents=[overrides],
                       help="fit scene parameters to reference images: fit.json, fit.toml, uncertainty.json, comparison.png, "
                            "convergence.png, residuals.fits, residuals.png",
                       description="Fit free scene parameters to reference images: radiance (EXR, FITS) or "
                                   "DN (FITS, 16-bit PNG / TIFF) with their sensor's noise model. "
                                   "--set applies to every scene. The report's first line is the verdict. Exit codes: "
                                   + FIT_EXIT_CODES)
    f.add_argument("references", nargs="*", metavar="REFERENCE",
                   help="reference images fitted jointly: .exr radiance (W m^-2 sr^-1); .fits radiance (BUNIT "
                        "'W m-2 sr-1') or DN; .png / .tif DN (give --response unless spacefit wrote them)")
    f.add_argument("--pass", dest="frames", metavar="FRAMES.csv|.ecsv|.fits",
                   help="fit a pass: a frame table (file, time, each frame's sun, camera, target attitude, sensor values; "
                        "docs/reference/passes.md) in place of REFERENCE; --scene is the pass's one scene")
    f.add_argument("--per-frame", metavar="NAME[,NAME...]",
                   help="with --pass: parameters each frame has its own of, e.g. target.attitude_x_deg,image.scale")
    f.add_argument("--large", action="store_true", help="run a fit (a pass of many frames) whose estimated memory, said "
                   "before it starts, is more than this machine has available")
    f.add_argument("--workers", type=int, metavar="N", help="render on a local dask cluster of N worker processes")
    f.add_argument("--scheduler", metavar="ADDRESS", help="render on the dask scheduler at ADDRESS (tcp://host:8786)")
    f.add_argument("--scene", dest="scenes", action="append", required=True, metavar="SCENE.toml",
                   help="scene of the references: one for all, or one per reference in order (repeatable)")
    f.add_argument("--free", required=True, metavar="NAME[,NAME...]", help=_free_help(command))
    f.add_argument("--out", required=True, metavar="DIR", help="output folder (new, empty, or a previous fit with --overwrite)")
    f.add_argument("--overwrite", action="store_true", help="replace a previous fit report in --out")
    f.add_argument("--resume", action="store_true", help="continue the interrupted fit whose checkpoint is in --out")
    f.add_argument("--solver", metavar="lm|gn|dogleg|bfgs|adam", help="solver with its default tolerances (default lm)")
    f.add_argument("--loss", metavar="pixel|pyramid|stats", help="loss (default pixel)")
    f.add_argument("--resolution", nargs=2, type=int, metavar=("W", "H"),
                   help="render every scene at W x H px; the references must have that size")
    f.add_argument("--spp", type=int, metavar="N", help="samples per pixel of the fit's renders (default: the scene's)")
    f.add_argument("--spp-grad", type=int, metavar="N", help="samples per pixel of derivative renders (default: --spp)")
    f.add_argument("--max-steps", type=int, metavar="N", help="solver step limit (default 50)")
    f.add_argument("--stop", metavar="noise|tolerance",
                   help="stop also when a step would gain less than the loss's Monte Carlo noise or the trial steps "
                        "find no lower loss (noise, default), or on the solver's tolerances alone")
    f.add_argument("--start", action="append", default=[], metavar="NAME=VALUE",
                   help="start value of a free parameter (default: the first scene's value; repeatable)")
    f.add_argument("--sigma", type=float, metavar="S",
                   help="noise standard deviation of radiance references, W m^-2 sr^-1 (residuals are divided by it)")
    f.add_argument("--mask", dest="masks", action="append", default=[], metavar="MASK",
                   help="mask image (FITS, PNG, TIFF; 0 = leave the pixel out, 1 or full scale = use it): one for all references, or one per "
                        "reference in order (repeatable); saturated pixels are left out in any case")
    f.add_argument("--sensor", metavar="SENSOR.json|.toml",
                   help="sf.Sensor fields (JSON or TOML) of the camera of DN references: they replace those of a "
                        "file's own sensor (FITS header or spacefit sidecar), or describe one that names none")
    f.add_argument("--sensor-value", dest="sensor_values", action="append", default=[], metavar="FIELD=VALUE",
                   help="one sf.Sensor field of DN references, e.g. --sensor-value read_noise_electrons=3.2 (TOML value; "
                        "repeatable): it replaces the file's and the sensor file's")
    f.add_argument("--sensor-defaults", metavar="illustrative",
                   help="fill the sensor values that no file or option gives with the illustrative defaults (otherwise "
                        "a missing value is refused)")
    f.add_argument("--row-order", metavar="top-down|bottom-up",
                   help="how the rows of FITS references run, whatever their headers say (default: as ROWORDER or "
                        "a WCS states, else the FITS standard, bottom-up, with a note)")
    f.add_argument("--flat", metavar="FLAT", help="flat-field image (FITS, PNG, TIFF) of DN references: the detector's relative "
                                                  "response, multiplying the expected signal above the bias")
    f.add_argument("--unit", metavar="radiance|DN", help="require the references to hold this unit")
    f.add_argument("--response", metavar="linear|srgb",
                   help="how PNG / TIFF values encode light: linear DN or sRGB-encoded (spacefit's own files say)")
    f.add_argument("--quiet", action="store_true", help="no progress output (the fitted values are still printed)")
    c = sub.add_parser("fit-light-curve", parents=[overrides],
                       help="fit scene parameters of a rendered target to a light curve: fit.json, fit.toml, uncertainty.json, "
                            "convergence.png, observation0.png",
                       description="Fit free scene parameters of a rendered target (materials, attitude angles the points do not "
                                   "set) to observed magnitudes, each point rendered at its own geometry (sf.fit_light_curve). "
                                   "--set applies to the scene. The report's first line is the verdict. Exit codes: " + FIT_EXIT_CODES)
    c.add_argument("curve", metavar="CURVE",
                   help="light-curve file: a point table (.csv, .ecsv, .fits: magnitude, optionally magnitude_sigma, and each "
                        "point's geometry as scene values, e.g. target.attitude_z_deg, sun.elevation_deg, camera.position_m.x, .y, "
                        ".z; docs/reference/light-curves.md), or any light curve sf.read_light_curve reads (geometry in the target's "
                        "frame, or seen from --site)")
    c.add_argument("--scene", required=True, metavar="SCENE.toml", help="scene of the target; its values are the start")
    c.add_argument("--free", required=True, metavar="NAME[,NAME...]", help=_free_help(command))
    c.add_argument("--out", required=True, metavar="DIR", help="output folder (new, empty, or a previous light-curve fit with --overwrite)")
    c.add_argument("--overwrite", action="store_true", help="replace a previous light-curve fit report in --out")
    c.add_argument("--resume", action="store_true", help="continue the interrupted fit whose checkpoint is in --out")
    c.add_argument("--max-steps", type=int, default=50, metavar="N", help="solver step limit (default 50)")
    c.add_argument("--start", action="append", default=[], metavar="NAME=VALUE",
                   help="start value of a free parameter (default: the scene's value; repeatable)")
    c.add_argument("--band", metavar="V|AB532", help="the magnitudes' band (default: the file's, else V)")
    c.add_argument("--sigma-mag", type=float, metavar="S", help="the magnitudes' error (mag) where the file states none")
    c.add_argument("--site", metavar="LAT,LON[,HEIGHT_M]",
                   help="the observer (deg, deg, m) of a light curve whose geometry is seen from a site")
    c.add_argument("--large", action="store_true", help="run a fit whose estimated memory, said before it starts, is more than "
                   "this machine has available")
    c.add_argument("--film-px", type=int, metavar="N", help="render the points on a film N px wide over the scene's field of view "
                   "(default: the coarsest the magnitudes' errors allow, said with the fit's size; the scene's width: its own film)")
    c.add_argument("--quiet", action="store_true", help="no progress output (the fitted values are still printed)")
    s = sub.add_parser("sweep", parents=[overrides], help="render a sweep of scene values into a resumable Zarr store",
                       description="Render a scene at every point of a sweep file's axes into a Zarr store, point by "
                                   "point; rerun the same command to finish an interrupted sweep. --set applies to the scene.")
    s.add_argument("sweep", metavar="SWEEP.toml", help="sweep file: scene, [axes], options (docs/reference/sweeps.md); "
                                                       "with --verify, the store to check")
    s.add_argument("--out", metavar="STORE", help="Zarr store folder (new, or this sweep's to finish it)")
    s.add_argument("--verify", action="store_true",
                   help=f"check a store (given in place of SWEEP.toml: spacefit sweep STORE --verify) without rendering: read back every done point and compare "
                        f"its checksum; exit 0 when every point is done and verified, {DAMAGED} when a point failed or a "
                        f"variable is missing (rerun the sweep to recompute them), {UNFINISHED} when points are left to compute")
    s.add_argument("--large", action="store_true", help="run a sweep of more than a million points, or whose store may "
                                                       "not fit on its disk (its size is printed first)")
    s.add_argument("--overwrite", action="store_true", help="replace a store that holds another sweep")
    s.add_argument("--workers", type=int, metavar="N", help="run on a local dask cluster of N worker processes")
    s.add_argument("--scheduler", metavar="ADDRESS", help="run on the dask scheduler at ADDRESS (tcp://host:8786)")
    s.add_argument("--quiet", action="store_true", help="no size estimate and no progress bar")
    return p


def _cluster(args: argparse.Namespace) -> int | str | None:
    """The ``cluster`` (:mod:`spacefit.executors`) of ``--workers N`` or ``--scheduler ADDRESS``."""
    if args.workers is not None and args.scheduler is not None:
        raise InputError("give `--workers` or `--scheduler`, not both.")
    cluster, named = (args.workers, "workers") if args.workers is not None else (args.scheduler, "scheduler")
    check_cluster(cluster, named)  # in the user's words, before anything is made
    return cluster


def _sweep(args: argparse.Namespace) -> int:
    """Run ``spacefit sweep``; on Ctrl-C say where the finished points are; a dask sweep that cannot go on exits 1."""
    _load("spacefit.studies.sweep", "xarray", "zarr", "dask.array")  # deferred: the studies' modules and the store's (1 s), which render never needs
    from spacefit.studies.store import verify_store
    from spacefit.studies.sweep import read_sweep_file, sweep

    if args.verify:
        report = verify_store(args.sweep)
        print(report)
        return DAMAGED if report.damaged else UNFINISHED if report.missing else 0
    if args.out is None:
        raise InputError("`--out` STORE is required to run a sweep (or pass --verify to check the store SWEEP.toml names).")
    scene, axes, options = read_sweep_file(args.sweep, args.overrides)
    try:
        sweep(scene, axes, store=args.out, overwrite=args.overwrite, cluster=_cluster(args), allow_large=args.large, quiet=args.quiet, **options)
    except ClusterError as err:
        print(f"spacefit: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as stop:
        print(f"spacefit: interrupted; every finished point is in {args.out} (rerun the same command to finish)", file=sys.stderr)
        return TERMINATED if isinstance(stop, Terminated) else INTERRUPTED
    except OSError as err:
        if err.errno and not err.filename:  # Zarr names no file: the store is where it failed
            raise OSError(err.errno, err.strerror, args.out) from None
        raise
    return 0


def _start_values(items: Sequence[str]) -> dict[str, float]:
    """``--start NAME=VALUE`` arguments as parameter name -> start value."""
    out = {}
    for text in items:
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise InputError(f"`--start` takes NAME=VALUE, got {text!r}.")
        try:
            number = float(value)
        except ValueError:
            raise InputError(f"`--start {name.strip()}` must be a number, got {value.strip()!r}.") from None
        out[name.strip()] = check_range(f"--start {name.strip()}", number)
    return out


def _sensor_values(items: Sequence[str]) -> dict[str, object]:
    """``--sensor-value FIELD=VALUE`` arguments as sensor field -> value (a TOML value; ``null``: None)."""
    out: dict[str, object] = {}
    for text in items:
        name, sep, value = text.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise InputError(f"`--sensor-value` takes FIELD=VALUE, got {text!r}.")
        try:
            out[name.strip()] = None if value.strip() == "null" else toml_value(value)
        except ValueError:
            raise InputError(f"`--sensor-value {text}`: {value.strip()!r} is not a number, true / false, null or [list].") from None
    return out


def _fit(args: argparse.Namespace) -> int:
    """Run ``spacefit fit``; exit code 0 when the fit succeeded, else the verdict's (:func:`exit_code`)."""
    # deferred: the fitting stack imports JAX and optimistix (1.5 s), which render never needs
    _load("spacefit.fitting.loop", "spacefit.fitting.observation_files", "spacefit.fitting.problem", "spacefit.fitting.report")
    from spacefit.fitting.loop import FitOptions  # here: JAX and optimistix, which render never needs
    from spacefit.fitting.observation_files import ObservationFiles
    from spacefit.fitting.problem import FitRender
    from spacefit.pipeline import fit_to_folder

    reading = dict(overrides=args.overrides, resolution=args.resolution, sigma=args.sigma, masks=args.masks,
                   sensor_file=args.sensor, sensor_values=_sensor_values(args.sensor_values) or None,
                   sensor_defaults=args.sensor_defaults, row_order=args.row_order, flat=args.flat, unit=args.unit,
                   response=args.response)
    free = [name.strip() for name in args.free.split(",")]
    if (args.frames is None) == (not args.references):
        raise InputError("give the reference images or `--pass FRAMES` (a frame table), one of the two.")
    if args.frames is not None:
        from spacefit.fitting.passes import Pass  # deferred: astropy's tables

        if len(args.scenes) != 1:
            raise InputError(f"`--pass` takes one `--scene`, the pass's (each frame's values are in its table); got {len(args.scenes)}.")
        frames = Pass.read(args.frames)
        files = frames.observation_files(args.scenes[0], **{k: v for k, v in reading.items() if k != "masks" or v})
        free += frames.per_frame([name.strip() for name in args.per_frame.split(",")]) if args.per_frame else []
    else:
        if args.per_frame:
            raise InputError("`--per-frame` goes with `--pass` (for references, free `NAME@k` by index).")
        files = ObservationFiles(args.references, args.scenes, **reading)
    render = FitRender(**{k: v for k, v in (("spp", args.spp), ("spp_grad", args.spp_grad)) if v is not None})
    given = {"solver": args.solver, "loss": args.loss, "max_steps": args.max_steps, "stop": args.stop}
    options = FitOptions(start=_start_values(args.start) or None, render=render, allow_large=args.large,
                         **{k: v for k, v in given.items() if v is not None})
    result = fit_to_folder(files, free, args.out, options, quiet=args.quiet, overwrite=args.overwrite, resume=args.resume,
                           cluster=_cluster(args))
    return _verdict(result, args.out)


def _fit_light_curve(args: argparse.Namespace) -> int:
    """Run ``spacefit fit-light-curve``; exit code 0 when the fit succeeded, else the verdict's (:func:`exit_code`)."""
    # deferred: the fitting stack imports JAX and optimistix (1.5 s), which render never needs
    _load("spacefit.fitting.loop", "spacefit.studies.lightcurve_files", "spacefit.fitting.report")
    from spacefit.pipeline import fit_light_curve_to_folder  # here: with the light-curve readers (astropy, JAX) loaded above
    from spacefit.studies.lightcurve_files import LightCurveFiles

    files = LightCurveFiles(args.curve, args.scene, overrides=args.overrides, band=args.band, site=_site(args.site),
                            sigma_mag=args.sigma_mag)
    free = [name.strip() for name in args.free.split(",")]
    result = fit_light_curve_to_folder(files, free, args.out, max_steps=args.max_steps, start=_start_values(args.start) or None,
                                       allow_large=args.large, quiet=args.quiet, overwrite=args.overwrite, resume=args.resume,
                                       film_px=args.film_px)
    return _verdict(result, args.out)


def _site(text: str | None) -> Site | None:
    """``--site LAT,LON[,HEIGHT_M]`` as an sf.Site (None: not given)."""
    if text is None:
        return None
    from spacefit.studies.orbit import Site  # deferred: with the light-curve readers

    try:
        numbers = [float(v) for v in text.split(",")]
    except ValueError:
        numbers = []
    if len(numbers) not in (2, 3):
        raise InputError(f"`--site` takes LAT,LON or LAT,LON,HEIGHT_M (deg, deg, m), got {text!r}.")
    return Site(*numbers)


def _verdict(result: FitResult, out: str) -> int:
    """Print a fit's result and say where its report is; its exit code (:func:`exit_code`)."""
    from spacefit.fitting.report import format_result  # deferred: loaded with the fit

    print(format_result(result))
    code = exit_code(result.status)
    if result.status.interrupted:
        print(f"spacefit: interrupted; the best point so far is in {out} (continue with --resume)", file=sys.stderr)
    elif code == NOT_CONVERGED:
        print(f"spacefit: the fit did not converge ({result.status}); its report is in {out}", file=sys.stderr)
    elif code:
        print(f"spacefit: {result.status}; its report is in {out}", file=sys.stderr)
    return code


def exit_code(status: Status) -> int:
    """The exit code of a fit that ended with ``status``: 0 for a success, else NO_PROGRESS, MISFIT,
    AT_BOUND, UNJUDGED, INTERRUPTED, TERMINATED, or NOT_CONVERGED for the solver's other endings."""
    from spacefit.fitting.status import Status  # deferred, as this module's other fitting imports: render never needs them

    if status.success:
        return 0
    return {Status.NO_PROGRESS: NO_PROGRESS, Status.MISFIT: MISFIT, Status.AT_BOUND: AT_BOUND, Status.UNJUDGED: UNJUDGED,
            Status.INTERRUPTED: INTERRUPTED, Status.TERMINATED: TERMINATED}.get(status, NOT_CONVERGED)


def _load(*modules: str) -> None:
    """Import ``modules`` with Ctrl-C and SIGTERM waiting for the end (then raised as KeyboardInterrupt /
    Terminated): a signal inside an extension module's import surfaces as an ImportError traceback."""
    with deferred_interrupts() as interrupts:
        for name in modules:
            importlib.import_module(name)
    interrupts.check()


def _terminate(signum: int, frame: object) -> None:
    raise Terminated()


def _ended(code: int, program: bool = False) -> int:
    """``code``, or the process ended at once with it: while an interrupted render still runs in the
    background (:func:`~spacefit.interrupts.abandoned`: Python's exit would wait for it, then abort), or
    after a render or a fit run as the program (``program``), its folder written, its cluster closed and
    its lock released: Python's shutdown would free every module and Mitsuba's objects one by one (0.07 s
    after a render; 1.7-3.5 s after a fit, JAX's own shutdown about 1 s of it) with nothing left to do,
    unless a profiler or tracer (cProfile, coverage) runs, which writes its report at the exit."""
    if (program and sys.getprofile() is None and sys.gettrace() is None) or abandoned():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _write_scene(args: argparse.Namespace, text: str) -> None:
    out = Path(args.out)
    if args.scene and out.exists() and out.resolve() == Path(args.scene).resolve():
        raise InputError(f"`--out` {args.out!r} is the input scene; spacefit never writes over its input.")
    if out.exists() and not args.overwrite:
        raise InputError(f"{args.out!r} exists; pass --overwrite to replace it, or choose a new file name.")
    write_text(out, text)


# What a write error means, in words.
WRITE_ERRORS = {errno.EFBIG: "past the file-size limit, ulimit -f", errno.ENOSPC: "the disk is full",
                errno.EDQUOT: "past the disk quota"}


def file_system_error(err: OSError) -> str:
    """An OSError in one line: the file and the cause, in words."""
    if err.errno is None or err.strerror is None:
        return str(err)
    where = f" on {err.filename!r}" if err.filename else ""
    hint = f" ({WRITE_ERRORS[err.errno]})" if err.errno in WRITE_ERRORS else ""
    return f"file system error{where}: {err.strerror}{hint}."


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code: 0, 1 for a file system error, 2 for bad input, for a
    fit 3 not converged, 4 no progress, 5 misfit, 6 a parameter at a bound, 9 not judged (:func:`exit_code`), for
    ``sweep --verify`` 7 a damaged store and 8 an unfinished one, 130 for
    Ctrl-C and 143 for SIGTERM (one line, no traceback). Run as the program (no ``argv``), a render
    that succeeded and a fit that wrote its report end the process at once (:func:`_ended`)."""
    program = argv is None
    argv = sys.argv[1:] if program else list(argv)
    args = _parser(argv[0] if argv else None).parse_args(argv)
    previous = {s: signal.signal(s, _terminate) for s in caught((signal.SIGTERM,))}  # an ignored SIGTERM stays ignored
    try:
        _STARTUP.check()
        t0 = time.perf_counter()
        # deferred: Mitsuba and the scene stack, timed as the "imports" stage of --timings (and not loaded by --help);
        # a signal waits for their end (about 1 s): one inside an import leaves Mitsuba half-loaded, and the exit aborts
        _load("spacefit.pipeline", "spacefit.scene.toml")
        from spacefit.pipeline import export_part_stl, render_to_folder  # here: Mitsuba, not loaded by --help
        from spacefit.scene.toml import load_scene

        imports_s = time.perf_counter() - t0

        if args.command == "fit":
            return _ended(_fit(args), program)
        if args.command == "fit-light-curve":
            return _ended(_fit_light_curve(args), program)
        if args.command == "sweep":
            return _sweep(args)
        scene = load_scene(args.scene, args.overrides)
        if args.command == "render":
            render_to_folder(scene, args.out, quiet=args.quiet, overwrite=args.overwrite,
                             inputs=(args.scene,) if args.scene else (), timings_s={"imports": imports_s},
                             show_timings=args.timings)
            return _ended(0, program)
        elif args.command == "scene":
            _write_scene(args, scene.to_toml())
        else:
            print(export_part_stl(scene, args.part, args.out))
    except InputError as err:
        # one line, whatever the message quotes (a key typed with a newline in it, say)
        print(f"spacefit: error: {shorten(str(err), 2000)}".replace("\n", "\\n"), file=sys.stderr)
        return 2
    except OSError as err:
        print(f"spacefit: error: {file_system_error(err)}", file=sys.stderr)
        return 1
    except Terminated:
        print("spacefit: terminated; nothing half-written was left behind", file=sys.stderr)
        return _ended(TERMINATED)
    except KeyboardInterrupt:
        print("spacefit: interrupted; nothing half-written was left behind", file=sys.stderr)
        return _ended(INTERRUPTED)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    return 0


if __name__ == "__main__":
    sys.exit(main())
