"""Issue 34 item 1: a 24-point light curve of the default lander at 300 px, rendered by Blender Cycles,
fitted for three materials from 1.15 x the truth, five times in a row, from Python and from the command line.

``make``: the lander (wrinkles off: Cycles gets spacefit's flat-shaded meshes) on a 300 x 300 px film over
the default field of view (8 mm pitch, 20 spp), turned about z through 24 points with the sun's elevation
swinging 10 to 50 deg; each point exported (:func:`spacefit.rendering.cycles.export_view`, box filter: the
flux is the film's sum whatever the filter) and rendered by Cycles at ``--cycles-spp`` (``cycles_light_curve.py``
in ``.venv-peers``: ``make peers``); the irradiance is the sum of mean-RGB radiance x pixel solid angle, the
magnitudes V plus 0.05 mag normal noise (seed 0). Writes ``scene.toml`` (at the truth), ``curve.csv`` (the
magnitude, its error, the attitude and the sun as a vector by components: geometry as scene values of
two kinds) and ``truth.json``, with each point's Cycles over spacefit ratio (spacefit at 300 px, 80 spp),
to ``data/lightcurve-cycles-300`` (the slow test's case); the exports to ``experiments/results/lightcurve_300``.

``fit``: ``--runs`` fits in a row, ``--how python`` (``sf.fit_light_curve``, its progress on stderr,
its checkpoints counted through ``sf.Resume(on_step=...)``) or ``--how cli`` (``spacefit fit-light-curve``
in a subprocess; ``--kill-at-step K`` kills the first run with SIGKILL once its checkpoint holds K steps
and resumes it with ``--resume``); each run's values, errors, z against the truth, steps, verdict, film,
wall time and load are appended to ``experiments/results/lightcurve_300/fits.jsonl`` as it ends.

Run: ``.venv/bin/python experiments/lightcurve_300.py make`` then
``.venv/bin/python experiments/lightcurve_300.py fit --how python --runs 5`` (and ``--how cli``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from studyio import commit, machine

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data" / "lightcurve-cycles-300"  # the light curve and its truth (make)
OUT = ROOT / "experiments" / "results" / "lightcurve_300"  # the Cycles exports (not kept) and the fits' log
PEER_PYTHON = ROOT / ".venv-peers" / "bin" / "python"
FREE = ("parts.legs.kd", "parts.body.alpha_x", "parts.panels.eta")
SIGMA_MAG = 0.05
START_FACTOR = 1.15
POINTS = 24


def lander():
    """The default lander, wrinkles off, on a 300 x 300 px film over the default field of view, 20 spp."""
    import spacefit as sf

    return sf.default_scene().with_values({"render.resolution": [300, 300], "camera.pixel_pitch_mm": 8.0, "render.spp": 20,
                                           "wrinkles.enabled": False})


def turning(count: int) -> list[dict[str, float]]:
    """``count`` points of the lander turned about z once, the sun's elevation swinging 10 to 50 deg."""
    angles = np.linspace(0.0, 360.0, count, endpoint=False)
    return [{"target.attitude_z_deg": float(a), "sun.elevation_deg": 30.0 + 20.0 * math.sin(math.radians(a))} for a in angles]


def make(cycles_spp: int) -> None:
    from spacefit.geometry.frames import Intrinsics, pixel_solid_angles
    from spacefit.precision import float64
    from spacefit.rendering.cycles import export_view
    from spacefit.rendering.exr import read_exr
    from spacefit.scene.assembly import assemble
    from spacefit.scene.parameters import scene_value
    from spacefit.studies.lightcurve import SUN_MAGNITUDES
    from spacefit.studies.lightcurve_fit import RenderedLightCurve

    OUT.mkdir(parents=True, exist_ok=True)
    DATA.mkdir(parents=True, exist_ok=True)
    scene, points = lander(), turning(POINTS)
    exports = OUT / "cycles_points"
    for i, p in enumerate(points):
        folder = exports / f"point{i:02d}"
        if not (folder / "scene.json").is_file():
            export_view(assemble(scene.with_values({**p, "render.filter": "box"})), folder)
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    subprocess.run([str(PEER_PYTHON), str(ROOT / "experiments" / "cycles_light_curve.py"), str(exports), "--spp", str(cycles_spp)],
                   check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    print(f"Cycles: {time.perf_counter() - t0:.0f} s, load {load0:.1f} -> {os.getloadavg()[0]:.1f}", flush=True)
    omega = pixel_solid_angles(Intrinsics.from_scene(scene))
    cycles = np.array([np.sum(read_exr(exports / f"point{i:02d}" / "cycles.exr")[..., :3].mean(axis=-1) * omega) for i in range(POINTS)])
    truth = [scene_value(scene, n) for n in FREE]
    ours = float64(lambda: np.asarray(RenderedLightCurve(scene.with_values({"render.spp": 80}), points, np.zeros(POINTS), SIGMA_MAG, seed=5)
                                      .block(FREE).model(np.asarray(truth), 0)))()
    magnitude = SUN_MAGNITUDES["V"] - 2.5 * np.log10(cycles / scene.sun.irradiance_w_m2)
    observed = magnitude + SIGMA_MAG * np.random.default_rng(0).standard_normal(POINTS)
    rows = ["magnitude,magnitude_sigma,target.attitude_z_deg,sun.direction.x,sun.direction.y,sun.direction.z"]
    for m, p in zip(observed, points):
        sun = scene.with_values({"sun.elevation_deg": p["sun.elevation_deg"]}).sun.direction
        rows.append(",".join(repr(float(v)) for v in (m, SIGMA_MAG, p["target.attitude_z_deg"], *sun)))
    (DATA / "curve.csv").write_text("\n".join(rows) + "\n")
    (DATA / "scene.toml").write_text(scene.to_toml())
    ratio = cycles / ours
    (DATA / "truth.json").write_text(json.dumps({"free": dict(zip(FREE, truth)), "sigma_mag": SIGMA_MAG, "cycles_spp": cycles_spp,
                                                "cycles_irradiance_w_m2": cycles.tolist(), "spacefit_irradiance_w_m2": ours.tolist(),
                                                "cycles_over_spacefit": ratio.tolist(), "commit": commit()}, indent=1))
    print(f"Cycles / spacefit per point: mean {ratio.mean():.4f}, sd {ratio.std(ddof=1):.4f}, min {ratio.min():.4f}, max {ratio.max():.4f}")


def fit_once(how: str, run: int, kill_at: int | None) -> dict:
    truth = json.loads((DATA / "truth.json").read_text())["free"]
    start = {n: START_FACTOR * v for n, v in truth.items()}
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    record: dict = {"how": how, "run": run, "commit": commit(), "machine": machine(), "load_start": round(load0, 2)}
    if how == "python":
        import spacefit as sf
        from spacefit.fitting.problem import SAY_SIZE
        from spacefit.studies.lightcurve_files import LightCurveFiles

        curve = LightCurveFiles(DATA / "curve.csv", DATA / "scene.toml").load()
        checkpoints: list[int] = []
        said = SAY_SIZE.set(lambda words: print(words, file=sys.stderr, flush=True) or record.setdefault("size", words))
        try:
            result = sf.fit_light_curve(curve.scene, list(FREE), curve.points, curve.magnitude, curve.magnitude_sigma, start=start,
                                        resume=sf.Resume(on_step=lambda entry: checkpoints.append(entry["step"])))
        finally:
            SAY_SIZE.reset(said)
        report = {"values": result.values, "stderr": result.stderr, "steps": result.steps, "status": str(result.status),
                  "success": result.success, "chi2_dof": result.goodness.chi2_dof, "verdict": result.goodness.line()}
        record["checkpoints"] = len(checkpoints)
    else:
        out = OUT / "cli" / f"run{run}"
        command = [sys.executable, "-m", "spacefit.cli", "fit-light-curve", str(DATA / "curve.csv"), "--scene", str(DATA / "scene.toml"),
                   "--free", ",".join(FREE), "--out", str(out), "--overwrite", *(a for n, v in start.items() for a in ("--start", f"{n}={v}"))]
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        if kill_at is not None:
            child = subprocess.Popen(command, env=env)
            checkpoint = out / "checkpoint.json"
            while child.poll() is None:
                try:
                    if len(json.loads(checkpoint.read_text())["history"]) >= kill_at:
                        child.send_signal(signal.SIGKILL)
                        break
                except (OSError, ValueError, KeyError):
                    pass
                time.sleep(0.5)
            child.wait()
            record["killed_at_s"], record["killed_rc"] = round(time.perf_counter() - t0, 1), child.returncode
            command = [*command, "--resume"]
        record["rc"] = subprocess.run(command, env=env).returncode
        fitted = json.loads((out / "fit.json").read_text())
        report = {k: fitted.get(k) for k in ("values", "stderr", "steps", "status", "success")}
        report["film_px"] = fitted["inputs"].get("film_px")
    record.update(report)
    record["z"] = {n: (report["values"][n] - truth[n]) / report["stderr"][n] for n in FREE}
    record["wall_s"], record["load_end"] = round(time.perf_counter() - t0, 1), round(os.getloadavg()[0], 2)
    return record


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="what", required=True)
    m = sub.add_parser("make")
    m.add_argument("--cycles-spp", type=int, default=128)
    f = sub.add_parser("fit")
    f.add_argument("--how", choices=("python", "cli"), required=True)
    f.add_argument("--runs", type=int, default=5)
    f.add_argument("--kill-at-step", type=int)
    args = p.parse_args()
    if args.what == "make":
        make(args.cycles_spp)
        return
    for run in range(args.runs):
        record = fit_once(args.how, run, args.kill_at_step if run == 0 else None)
        with open(OUT / "fits.jsonl", "a") as log:
            log.write(json.dumps(record) + "\n")
        print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
