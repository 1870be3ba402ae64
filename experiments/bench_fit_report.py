"""The report's share of the ``spacefit fit`` process of ``bench_fit_process.py`` (issue 33's 8-parameter observation
fit): the CPU seconds of importing :mod:`spacefit.fitting.report` after the modules the CLI loads before it (its
share: matplotlib and the figures) and of writing the report folder once (:func:`write_fit_report`: its JSON, FITS and two figures), each in a fresh process, as the fit
process pays them; then each figure's drawing and saving alone, warm (the median of ``--repeats``).
The fit is solved once here and its result handed to the fresh processes as a pickle.
Run: ``.venv/bin/python experiments/bench_fit_report.py [--processes N] [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_fit_process import write_inputs
from studyio import machine

ROOT = Path(__file__).resolve().parent.parent


def solve(folder: Path) -> Path:
    """The fit of ``bench_fit_process``'s inputs, solved in a child process (the CLI's arguments); its result and
    references pickled into ``folder`` / result.pkl."""
    args = write_inputs(folder)
    script = ("import pickle, sys\nimport spacefit.cli, spacefit.fitting.report as report\nwrite = report.write_fit_report\n"
              "def keep(out_dir, result, references, **kw):\n"
              f"    pickle.dump((result, references, kw), open({str(folder / 'result.pkl')!r}, 'wb'))\n"
              "    return write(out_dir, result, references, **kw)\n"
              f"report.write_fit_report = keep\nspacefit.cli.main(['fit', *{args!r}, '--out', {str(folder / 'out')!r}])\n")
    subprocess.run([sys.executable, "-c", script], env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True, capture_output=True)
    return folder / "result.pkl"


def fresh(pickled: Path, out: Path) -> tuple[float, float]:
    """CPU s of importing the report module after the modules the CLI loads before it (its share of the fit's
    imports: matplotlib and the figures), and of writing the report once, in a fresh process."""
    script = ("import pickle, shutil, time\nimport spacefit.render_job, spacefit.scene.toml, spacefit.fitting.loop, "
              "spacefit.fitting.observation_files, spacefit.fitting.problem\n"  # what the CLI loads before the report
              "t = time.process_time()\nfrom spacefit.fitting.report import write_fit_report\n"
              f"imported = time.process_time() - t\nresult, references, kw = pickle.load(open({str(pickled)!r}, 'rb'))\n"
              f"shutil.rmtree({str(out)!r}, ignore_errors=True)\nt = time.process_time()\n"
              f"write_fit_report({str(out)!r}, result, references, **kw)\nprint(imported, time.process_time() - t)\n")
    run = subprocess.run([sys.executable, "-c", script], env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True,
                         capture_output=True, text=True)
    imported, written = map(float, run.stdout.split())
    return imported, written


def warm(pickled: Path, out: Path, repeats: int) -> dict[str, tuple[float, float]]:
    """Each figure's median CPU s to draw (the figure function) and to save (:func:`_save`), warm, in this process."""
    from spacefit.fitting.plots import plot_comparison, plot_convergence
    from spacefit.fitting.report import _save  # the report's own saving

    result, references, _ = pickle.load(open(pickled, "rb"))
    figures = {"convergence": lambda: plot_convergence(result), "comparison": lambda: plot_comparison(result, references)}
    times = {}
    for name, figure in figures.items():
        runs = []
        for _ in range(repeats + 1):  # the first draw pays matplotlib's first-use costs: not counted
            t0 = time.process_time()
            axes = figure()
            t1 = time.process_time()
            _save(axes, out / f"{name}.png")
            runs.append((t1 - t0, time.process_time() - t1))
        times[name] = (statistics.median(r[0] for r in runs[1:]), statistics.median(r[1] for r in runs[1:]))
    return times


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--processes", type=int, default=5, help="fresh processes (their median is the figure)")
    p.add_argument("--repeats", type=int, default=5, help="warm draws of each figure")
    args = p.parse_args()
    print(f"machine: {machine()}; load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        pickled = solve(Path(tmp))
        runs = [fresh(pickled, Path(tmp) / "report") for _ in range(args.processes)]
        print(f"fresh process (median of {args.processes}): import spacefit.fitting.report {statistics.median(r[0] for r in runs):.2f} s CPU, "
              f"write_fit_report {statistics.median(r[1] for r in runs):.2f} s CPU")
        for name, (draw, save) in warm(pickled, Path(tmp), args.repeats).items():
            print(f"{name}.png warm (median of {args.repeats}): figure {draw:.3f} s CPU, draw and save {save:.3f} s CPU")
    print(f"load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
