"""The command line's interface: each command's arguments (:func:`parser`, whose help ``spacefit --help`` prints
and docs/reference/cli.md shows) and the exit codes they document. Running the commands is :mod:`spacefit.cli`'s."""

from __future__ import annotations

import argparse

from spacefit.scene.parameters import PARAMETERS

# Exit codes of `spacefit fit` that is not a success (its report is written in each case).
NOT_CONVERGED = 3  # the solver stopped without converging (step limit, divergence, NaN), or the pixel grid's step did not settle
NO_PROGRESS = 4  # no step lowered the loss: the values are the start
MISFIT = 5  # the residuals exceed the noise: the model or its nuisances miss something
AT_BOUND = 6  # a parameter ended at a bound of its range
UNJUDGED = 9  # the model's own render noise is above the data's: the residuals could not be judged
INTERRUPTED = 130  # 128 + SIGINT, as shells report Ctrl-C
TERMINATED = 143  # 128 + SIGTERM
# The commands that fit, and what their exit codes say.
FITS = ("fit", "fit-light-curve")
FIT_EXIT_CODES = (f"0 converged, 1 file system error, 2 bad input, {NOT_CONVERGED} not converged (or the pixel grid's step not settled or "
                  f"not taken), {NO_PROGRESS} no progress (no "
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


def parser(command: str | None = "fit") -> argparse.ArgumentParser:
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
                            "convergence.png, residuals.fits",
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
