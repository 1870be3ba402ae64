"""The fit jobs: reference files (images, a light curve) -> a checkpointed fit -> its report folder
(:func:`fit_to_folder`, :func:`fit_light_curve_to_folder`), and the checkpoint that resumes one (:class:`Checkpoint`).
The render job is :mod:`spacefit.render_job`'s."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.digests import changed, digests
from spacefit.errors import InputError, check_path, check_type
from spacefit.executors import Cluster, cluster_of
from spacefit.fitting.resume import Resume
from spacefit.locks import holding_lock
from spacefit.output import prepare_output, previous_result, staged_output, versions, write_json
from spacefit.progress import Progress, ProgressCallback, say
from spacefit.scene.overrides import parse_override
from spacefit.scene.parameters import scene_keys

if TYPE_CHECKING:
    from spacefit.studies.lightcurve_files import LightCurveFiles
    from spacefit.fitting.loop import FitOptions
    from spacefit.fitting.result import FitResult
    from spacefit.fitting.observation_files import ObservationFiles


@holding_lock("out_dir")
def fit_to_folder(files: ObservationFiles, free: Sequence[str], out_dir: str | Path, options: FitOptions | None = None, *,
                  quiet: bool = False, overwrite: bool = False, resume: bool = False, cluster: Cluster | None = None) -> FitResult:
    """Fit the ``free`` parameters to reference image files; write fit.json, fit.toml, uncertainty.json and the plots to ``out_dir``.

    It runs holding the folder's lock (one writer per folder: a second is refused, naming the folder). The folder is
    checked writable, then every file is read and checked before rendering; on any error nothing is
    left behind.

    Args:
        files: the reference and scene files and how to read them (:class:`ObservationFiles`);
            none of its ``overrides`` may fix a free parameter.
        free: parameter names (:func:`available_parameters`); their start values are the first
            scene's unless ``options.start`` gives them.
        out_dir: output folder of the report (:func:`write_fit_report`).
        options: the settings of :func:`fit` (:class:`FitOptions`;
            None: its defaults), recorded in fit.json's ``inputs.options``.
        quiet: no progress display or messages on stderr.
        overwrite: replace a previous fit report in ``out_dir``.
        resume: continue the interrupted fit whose checkpoint is in ``out_dir`` (same files, free
            parameters and options but the solver's: ``solver``, ``max_steps``, ``start``, ``stop``).
        cluster: where the renders run (:func:`fit`'s ``cluster``: None, this
            process; N local dask workers; a scheduler address; a dask Client).

    Returns:
        The fit's result.

    Example:
        Not run by the tests (an image fit takes minutes)::

            files = sf.ObservationFiles(references=["ref.exr"], scenes=["lander.toml"], sigma=0.01)
            result = sf.fit_to_folder(files, ["parts.legs.kd"], "fit-out", sf.FitOptions(max_steps=20))
            print(sf.format_result(result))
    """
    # deferred: the fitting stack (JAX, optimistix: 1.5 s) and the image files' readers (astropy), which renders never need
    from spacefit.fitting.loop import FitOptions, fit
    from spacefit.fitting.observation_files import ObservationFiles
    from spacefit.imageio import format_sensor_sources

    options = FitOptions() if options is None else options
    check_type("files", files, ObservationFiles, "an sf.ObservationFiles(references, scenes, ...)")
    check_type("options", options, FitOptions, "an sf.FitOptions or None")
    cluster = cluster_of(cluster)
    prepare_output(check_path("out_dir", out_dir), "fit", overwrite=overwrite, resume=resume, inputs=files.files)
    _check_not_fixed(free, files.overrides)
    t0 = time.perf_counter()
    observations = files.load()
    for path, obs in zip(files.references, observations):  # what each file said, and the source of every sensor value
        said = "\n".join([*obs.notes, *([f"{path}: " + format_sensor_sources(obs.sensor, obs.sensor_sources)] if obs.sensor_sources else [])])
        say(said, quiet or not said)
    images = [obs.reference for obs in observations]
    t_read = time.perf_counter() - t0
    inputs = {**files.record(observations), "free": list(free), "options": options.to_dict()}
    read = [*files.files, *(path for obs in observations for path in obs.scene.mesh_files())]

    def solve(resumed: dict[str, Any], progress: ProgressCallback, plumbing: Resume) -> FitResult:
        return fit(observations, free, progress=progress, resume=plumbing, cluster=cluster,
                   **dataclasses.replace(options, **resumed).keywords())

    return _checkpointed_fit(out_dir, "fit", solve, images, inputs=inputs, read=read, label=f"fit {', '.join(free)}",
                             max_steps=options.max_steps, resume=resume, quiet=quiet, t_read=t_read)


@holding_lock("out_dir")
def fit_light_curve_to_folder(files: LightCurveFiles, free: Sequence[str], out_dir: str | Path, *, max_steps: int = 50,
                              start: Mapping[str, float] | None = None, allow_large: bool = False, quiet: bool = False,
                              overwrite: bool = False, resume: bool = False, film_px: int | None = None) -> FitResult:
    """Fit the ``free`` parameters of a rendered target to a light-curve file (:func:`fit_light_curve`);
    write its report (fit.json, fit.toml, uncertainty.json, convergence.png, observation0.png: the
    magnitudes against the model's, ...) to ``out_dir``, as :func:`fit_to_folder` does an image fit's:
    holding the folder's lock, every input checked before rendering, the points' film chosen
    (``film_px``, else the coarsest the magnitudes' errors allow, as :func:`fit_light_curve` chooses it;
    recorded in fit.json's inputs), its size said first, progress,
    a checkpoint after every step (``resume``: continue it, with the same files, free parameters and
    options but ``max_steps`` and ``start``), and nothing left behind on an error.

    Args:
        files: the light-curve and scene files and how to read them (:class:`LightCurveFiles`).
        free: registered parameter names (materials, attitude angles the points do not set).
        out_dir: output folder of the report.
        max_steps, start, allow_large: :func:`fit`'s.
        quiet: no progress display or messages on stderr.
        overwrite: replace a previous light-curve fit report in ``out_dir``.
        resume: continue the interrupted fit whose checkpoint is in ``out_dir``.
        film_px: the width (px) of the points' film over the scene's field of view (None: the coarsest
            their errors allow; the scene's width: its own film).

    Returns:
        The fit's result.

    Example:
        Not run by the tests (a rendered light curve's fit takes minutes)::

            files = sf.LightCurveFiles(curve="curve.csv", scene="lander.toml", sigma_mag=0.05)
            result = sf.fit_light_curve_to_folder(files, ["parts.panels.alpha"], "lc-fit")
    """
    from spacefit.fitting.loop import fit  # deferred: the fitting stack (JAX, optimistix: 1.5 s), which renders never need
    from spacefit.studies.lightcurve_files import LightCurveFiles
    from spacefit.studies.lightcurve_fit import film_for_fit

    check_type("files", files, LightCurveFiles, "an sf.LightCurveFiles(curve, scene, ...)")
    prepare_output(check_path("out_dir", out_dir), "light-curve-fit", overwrite=overwrite, resume=resume, inputs=files.files)
    t0 = time.perf_counter()
    curve = files.load()
    curve = film_for_fit(curve if film_px is None else dataclasses.replace(curve, film_px=film_px), free, start)
    t_read = time.perf_counter() - t0
    inputs = {**files.record(), "free": list(free), "film_px": curve.film_px,
              "options": {"max_steps": max_steps, "start": start, "allow_large": allow_large}}

    def solve(resumed: dict[str, Any], progress: ProgressCallback, plumbing: Resume) -> FitResult:
        given = {"max_steps": max_steps, "start": start, **resumed}
        return fit(curve, free, allow_large=allow_large, progress=progress, resume=plumbing, **given)

    return _checkpointed_fit(out_dir, "light-curve-fit", solve, [], inputs=inputs, read=[*files.files, *curve.scene.mesh_files()],
                             label=f"light-curve fit {', '.join(free)}", max_steps=max_steps, resume=resume, quiet=quiet,
                             t_read=t_read)


def _checkpointed_fit(out_dir: str | Path, command: str, solve: Callable[[dict[str, Any], ProgressCallback, Resume], FitResult],
                      references: Sequence[np.ndarray], *, inputs: dict[str, Any], read: Sequence[str | Path], label: str,
                      max_steps: int, resume: bool, quiet: bool, t_read: float) -> FitResult:
    """Run a fit (``solve``, given the options a resume changes, the progress callback and the checkpoint
    plumbing) with a progress display (``label``) and a checkpoint in ``out_dir``, then write its report
    (:func:`~spacefit.fitting.report.write_fit_report` of ``references``), which replaces the files of a previous
    ``command`` result there whole (:func:`~spacefit.output.previous_result`). ``inputs``: what fit.json
    records and the checkpoint compares on ``resume``; ``read``: the files whose SHA-256 it keeps.
    On an error nothing of this run stays (an interruption keeps the checkpoint)."""
    from spacefit.fitting.problem import SAY_SIZE  # deferred: the fitting stack, which renders never need
    from spacefit.fitting.report import write_fit_report

    display, last = Progress(label), [0, 0]

    def progress(step: int, total: int) -> None:
        last[:] = step, total
        if not quiet:
            display(step, total)

    checkpoint = Checkpoint(Path(out_dir) / CHECKPOINT, inputs, read)
    resumed: dict[str, Any] = {}
    if resume:
        resumed = checkpoint.resume(max_steps)
        say(f"the solve in {out_dir} had ended at step {checkpoint.ended['steps']}; writing its report" if checkpoint.ended
             else f"resuming from step {checkpoint.steps} of the checkpoint in {out_dir}", quiet)

    created, replaces = not Path(out_dir).exists(), previous_result(out_dir, command)
    t0 = time.perf_counter()
    try:
        plumbing = Resume(checkpoint.update, checkpoint.end, checkpoint.ended, checkpoint.history if resume else ())
        said = SAY_SIZE.set(lambda size: say(size, quiet))  # its size, once its inputs are checked, before it renders
        try:
            result = solve(resumed, progress, plumbing)
        finally:
            SAY_SIZE.reset(said)
        edited = changed(checkpoint.digests)  # the files read at the start, read again: a result of files that changed is none
        if edited:
            raise InputError(f"{', '.join(map(repr, edited))} changed while the fit ran (SHA-256 differs from the start's); "
                             "nothing was written: run the fit again on the files as they are now.")
        t_fit = time.perf_counter() - t0
        if not quiet and last[0] < last[1]:
            display(last[0], last[0])  # the solve stopped before its step limit: end the display there
        timings = {"read_inputs": t_read, "setup": t_fit - result.wall_time_s}
        write_fit_report(out_dir, result, references, inputs=inputs, timings_s=timings, replaces=replaces)
    except Exception:
        # an error, not an interruption: nothing of this run stays (an interruption keeps the checkpoint)
        if not resume:
            checkpoint.remove()
        if created:
            with contextlib.suppress(OSError):
                Path(out_dir).rmdir()
        raise
    if not result.status.interrupted:
        checkpoint.remove()
    say(f"wrote {Path(out_dir) / 'fit.json'} and the rest of the report", quiet)
    return result


CHECKPOINT = "checkpoint.json"
# FitOptions a resumed fit may change: how it solves (or whether it may be large), not what it fits.
SOLVE_OPTIONS = ("solver", "max_steps", "start", "stop", "allow_large")


def _problem_of(value: Any, key: str) -> Any:
    """The part of a recorded input that defines the fitting problem (``options`` less how it is solved)."""
    return {k: v for k, v in value.items() if k not in SOLVE_OPTIONS} if key == "options" and isinstance(value, dict) else value


class Checkpoint:
    """The best point of a fit so far and its steps' history, written atomically into its output
    folder after every step, so that an interrupted (even killed) fit can be resumed (``--resume``)
    and end as the uninterrupted one would (``fit``'s ``history``). It records the SHA-256 of every
    file the fit read (``files``: references, scenes, masks, sensor file, flat field, meshes),
    hashed when it is made: a resume compares them by content."""

    def __init__(self, path: Path, inputs: dict[str, Any], files: Sequence[str | Path] = ()) -> None:
        self.path, self.inputs = path, json.loads(json.dumps(inputs, default=str))
        self.digests = digests(files)
        self.best: dict[str, Any] | None = None
        self.steps = 0
        self.history: list[dict[str, Any]] = []  # every step's entry (``Resume.on_step``)
        self.ended: dict[str, Any] | None = None  # the record of a solve that ended (``Resume.on_end``)

    def update(self, entry: dict[str, Any]) -> None:
        """Record one step's history entry (the best point when it is the best so far) and write the file."""
        self.steps += 1
        self.history.append(dict(entry))
        if np.isfinite(entry["loss"]) and (self.best is None or entry["loss"] < self.best["loss"]):
            self.best = {"loss": float(entry["loss"]), "values": dict(entry["values"])}
        if self.best is not None:
            self._write()

    def end(self, record: dict[str, Any]) -> None:
        """Record that the solve has ended (``Resume.on_end``): a fit killed after it resumes to the same report."""
        self.ended = record
        self._write()

    def _write(self) -> None:
        with staged_output(self.path.parent) as stage:
            write_json(stage / self.path.name, {"inputs": self.inputs, "files_sha256": self.digests, "best": self.best,
                                                "steps": self.steps, "history": self.history, "versions": versions(),
                                                **({"ended": self.ended} if self.ended else {})})

    def resume(self, max_steps: int) -> dict[str, Any]:
        """The fit options that continue from the checkpoint: its best values as the start, and the
        steps left of ``max_steps`` (:attr:`history` holds the steps made); for a solve that had ended (:attr:`ended`, passed to ``fit``), its
        end values, so that the report is the one the ended fit would have written.

        Raises:
            InputError: without a checkpoint, or for one made with other inputs (naming them) or
                files whose contents have changed since (naming the files).
        """
        if not self.path.is_file():
            raise InputError(f"there is no checkpoint {str(self.path)!r} to resume from; run without --resume.")
        try:
            saved = json.loads(self.path.read_text())
            best, steps, inputs = saved["best"], int(saved["steps"]), saved["inputs"]
            recorded = dict(saved.get("files_sha256", {}))
        except (OSError, ValueError, KeyError, TypeError) as err:
            raise InputError(f"checkpoint {str(self.path)!r} is unreadable ({err}); run without --resume.") from None
        differ = sorted(k for k in set(inputs) | set(self.inputs) if _problem_of(inputs.get(k), k) != _problem_of(self.inputs.get(k), k))
        if differ:
            raise InputError(f"checkpoint {str(self.path)!r} was made with other {', '.join(differ)}; resume with the "
                             "same references, scenes, free parameters and options, or run without --resume.")
        edited = [path for path, digest in recorded.items() if path in self.digests and self.digests[path] != digest]
        if edited:
            raise InputError(f"checkpoint {str(self.path)!r} was made with other contents of {', '.join(map(repr, edited))} "
                             "(SHA-256 differs: edited since); resume with the files as they were, or run without --resume.")
        self.best, self.steps, self.ended, self.history = best, steps, saved.get("ended"), list(saved.get("history", []))
        if self.ended is not None:  # the solve had ended: its ending is reported again, not solved again
            return {"start": self.ended["values"]}
        return {"start": best["values"], "max_steps": max(max_steps - steps, 1)}

    def remove(self) -> None:
        """Remove the checkpoint once a finished report holds the result."""
        self.path.unlink(missing_ok=True)


def _check_not_fixed(free: Sequence[str], overrides: Sequence[str]) -> None:
    """Refuse an override of a free parameter: the fit would replace it without a word."""
    for text in overrides:
        key = ".".join(parse_override(text)[0])
        for name in free:
            if key == name or key in scene_keys(name):
                raise InputError(
                    f"`{name}` is both free and fixed by the override {text!r}; drop the override "
                    f"(its start value can be given as `start`, --start {name}=VALUE)."
                )
