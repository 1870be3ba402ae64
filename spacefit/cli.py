"""Command line: ``spacefit render|scene|export-stl [SCENE.toml] --out PATH [--set key=value ...]`` and
``spacefit fit REFERENCE ... --scene SCENE.toml --free NAME[,NAME...] --out DIR [--mask M] [--sensor S]``,
``spacefit fit-light-curve CURVE --scene SCENE.toml --free NAME[,NAME...] --out DIR [--resume]``,
``spacefit sweep SWEEP.toml --out STORE``, ``spacefit sweep STORE --verify``: each command run, its errors and
signals answered in one line and its exit code. Its arguments and exit codes are :mod:`spacefit.cli_parser`'s."""

from __future__ import annotations

import argparse
import errno
import gc
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
    from spacefit.cli_parser import (AT_BOUND, DAMAGED, INTERRUPTED, MISFIT, NO_PROGRESS, NOT_CONVERGED, TERMINATED, UNFINISHED,
                                     UNJUDGED, parser)
    from spacefit.errors import InputError, check_range, shorten
    from spacefit.executors import ClusterError, check_cluster
    from spacefit.output import write_text
    from spacefit.scene.overrides import toml_value

if TYPE_CHECKING:
    from spacefit.fitting.result import FitResult
    from spacefit.fitting.status import Status
    from spacefit.studies.orbit import Site


def _cluster(args: argparse.Namespace) -> int | str | None:
    """The ``cluster`` (:mod:`spacefit.executors`) of ``--workers N`` or ``--scheduler ADDRESS``."""
    if args.workers is not None and args.scheduler is not None:
        raise InputError("give `--workers` or `--scheduler`, not both.")
    cluster, named = (args.workers, "workers") if args.workers is not None else (args.scheduler, "scheduler")
    check_cluster(cluster, named)  # in the user's words, before anything is made
    return cluster


def _sweep(args: argparse.Namespace) -> int:
    """Run ``spacefit sweep``; on Ctrl-C say where the finished points are; a dask sweep that cannot go on exits 1."""
    from spacefit.studies.store import verify_store  # here (main loads them: COMMAND_MODULES): the store's modules, which render never needs
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
    from spacefit.fitting.loop import FitOptions  # here (main loads them: COMMAND_MODULES): JAX and optimistix, which render never needs
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
    from spacefit.pipeline import fit_light_curve_to_folder  # here (main loads them: COMMAND_MODULES): the light-curve readers (astropy, JAX)
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
    from spacefit.fitting.status import Status

    print(format_result(result))
    code = exit_code(result.status)
    if result.status.interrupted:
        print(f"spacefit: interrupted; the best point so far is in {out} (continue with --resume)", file=sys.stderr)
    elif code == NOT_CONVERGED and result.status not in (Status.UNSETTLED, Status.UNSTEPPED):  # a solve that converged
        print(f"spacefit: the fit did not converge ({result.status}); its report is in {out}", file=sys.stderr)
    elif code:
        print(f"spacefit: {result.status}; its report is in {out}", file=sys.stderr)
    return code


def exit_code(status: Status) -> int:
    """The exit code of a fit that ended with ``status``: 0 for a success, else NO_PROGRESS, MISFIT,
    AT_BOUND, UNJUDGED, INTERRUPTED, TERMINATED, or NOT_CONVERGED for the solver's other endings and for
    UNSETTLED and UNSTEPPED (the pixel grid's step short of its fixed point, or not taken)."""
    from spacefit.fitting.status import Status  # deferred, as this module's other fitting imports: render never needs them

    if status.success:
        return 0
    return {Status.NO_PROGRESS: NO_PROGRESS, Status.MISFIT: MISFIT, Status.AT_BOUND: AT_BOUND, Status.UNJUDGED: UNJUDGED,
            Status.INTERRUPTED: INTERRUPTED, Status.TERMINATED: TERMINATED}.get(status, NOT_CONVERGED)


# Each command's modules beyond the scene stack's, loaded by main before it runs (deferred: the fitting stack imports JAX
# and optimistix, 1.5 s, the sweep its studies' modules and the store's, 1 s; render needs none of them).
COMMAND_MODULES = {
    "fit": ("spacefit.fitting.loop", "spacefit.fitting.observation_files", "spacefit.fitting.problem", "spacefit.fitting.report",
            "spacefit.pipeline"),
    "fit-light-curve": ("spacefit.fitting.loop", "spacefit.studies.lightcurve_files", "spacefit.fitting.report", "spacefit.pipeline"),
    "sweep": ("spacefit.studies.sweep", "xarray", "zarr", "dask.array"),
}


# A command's process collects its youngest generation after this many new objects (Python's default 700): JAX's
# tracing makes and drops some 10^6 in an 8-parameter fit, whose 290 young collections led to 26 of the middle
# generation and two full ones, 70 ms of its 5 s; at 20,000, 52 young, 4 middle, no full one, 20 ms; the same peak
# memory (docs/measurements/performance.md, "The collector's thresholds").
PROGRAM_GC_YOUNG = 20_000


def _load(*modules: str, frozen: bool = False) -> None:
    """Import ``modules`` with Ctrl-C and SIGTERM waiting for the end (then raised as KeyboardInterrupt /
    Terminated): a signal inside an extension module's import surfaces as an ImportError traceback.

    ``frozen`` (the process is the command's): the garbage collector is off while they load, and what is loaded
    then is frozen (``gc.freeze``), out of every later collection's scan. The modules live as long as the process;
    a fit's imports leave 350 000 objects (about 1 MiB of them the imports' own garbage, kept), which each full
    collection scanned: 0.1 to 0.3 s each, five or six times in an 8-parameter fit (0.4 to 1.1 s of CPU, one of
    them often in the report), 0.15 s of them during the imports. After them its youngest generation is collected
    every :data:`PROGRAM_GC_YOUNG` new objects, not Python's 700."""
    if frozen:
        gc.disable()
    try:
        with deferred_interrupts() as interrupts:
            for name in modules:
                importlib.import_module(name)
        interrupts.check()
    finally:
        if frozen:
            gc.freeze()
            gc.set_threshold(PROGRAM_GC_YOUNG, *gc.get_threshold()[1:])
            gc.enable()


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
    args = parser(argv[0] if argv else None).parse_args(argv)
    previous = {s: signal.signal(s, _terminate) for s in caught((signal.SIGTERM,))}  # an ignored SIGTERM stays ignored
    try:
        _STARTUP.check()
        t0 = time.perf_counter()
        # deferred: Mitsuba and the scene stack (and the command's own modules), timed as the "imports" stage of
        # --timings (and not loaded by --help); a signal waits for their end (about 1 s): one inside an import leaves Mitsuba half-loaded, and the exit aborts
        _load("spacefit.render_job", "spacefit.scene.toml", *COMMAND_MODULES.get(args.command, ()), frozen=program)
        from spacefit.render_job import export_part_stl, render_to_folder  # here: Mitsuba, not loaded by --help
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
