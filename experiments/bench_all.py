"""Every speed figure in one run (``make bench``): the main job's wall time cold and warm, a notebook's
first render (a fresh process: what it waits for), the per-call fixed cost of a fit's frozen renders
(issue 33's 5 ms; measured, and estimated step by step in CPU time), issue 33's other targets (the whole `spacefit fit` process of the 8-parameter observation
fit, the 12-frame pass, the 24-point light curve, a render in a long-running process), forward renders at equal error against plain Mitsuba, the fit of an observation of a sensor (issue 23: 8 parameters at 128 x 128, 32 spp), the
fits' solve times and accuracy, peak memory, and Dr.Jit kernel compilations over a long fit, and
where a CUDA GPU is usable, the default forward render and the panels fit on it against the CPU
(elsewhere it says so). Each section prints the machine's load average (1 min) as it starts.

Each figure comes from a child process, so that its wall time includes the start-up a user pays and
its peak memory (``ru_maxrss`` from ``os.wait4``; tracemalloc cannot see Dr.Jit's allocations) is
its own. "cold" clears spacefit's mesh cache (a fresh ``SPACEFIT_CACHE_DIR``); Dr.Jit's kernel
cache (``~/.drjit``) is left as it is. Run: ``.venv/bin/python experiments/bench_all.py [--full]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from studyio import commit, machine

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
# Long fits: Adam runs all its steps (a tolerance it cannot meet), each one a render and a Jacobian.
# First the process's peak resident memory after step 10 and after the last step (a high-water mark:
# run first), then kernels counted over 5 and 60 steps (Dr.Jit's kernel history grows with the launches).
LONG_FIT = """
import resource
import spacefit as sf
from spacefit.rendering.logs import kernel_log
case = sf.load_case("panels")
scene = case.truth_scene.with_values({"render.resolution": [64, 64], "camera.pixel_pitch_mm": 37.5, "render.spp": 8})
reference = sf.Renderer(scene).render(seed=7)
obs = sf.Observation(scene, reference)
peak = {}
def on_step(h):
    peak[h["step"]] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
sf.fit(obs, list(case.free), solver=sf.Adam(rtol=1e-12), start=case.start, max_steps=STEPS, resume=sf.Resume(on_step=on_step))
last = max(peak)
print(f"peak memory: {peak[10]:.1f} MiB after step 10, {peak[last]:.1f} MiB after step {last} "
      f"({peak[last] / peak[10] - 1:+.2%})")
for steps in (5, 60):
    with kernel_log() as k:
        r = sf.fit(obs, list(case.free), solver=sf.Adam(rtol=1e-12), start=case.start, max_steps=steps)
    print(f"adam {r.steps} steps: {k['launched']} kernels launched, {k['compiled']} compiled ({k['compile_s']:.2f} s)")
"""
# One variant's default forward render (median of 7 after a compiling one; the CPU on 2 threads, as
# on the benchmark machine) and the panels fit of bench_fit.py (LM): "forward <s>", "fit <s> <max |error|>".
VARIANT_RUN = """
import statistics, sys, time
sys.path.insert(0, "experiments")
from bench_fit import run
from spacefit.rendering.backend import dr
import spacefit as sf
variant = sys.argv[1]
dr.set_thread_count(2)
renderer = sf.Renderer(sf.load_scene(None, {"render.variant": variant, "render.deterministic": False}))
renderer.render(seed=0)
times = []
for seed in range(1, 8):
    t0 = time.perf_counter()
    renderer.render(seed=seed)
    times.append(time.perf_counter() - t0)
print(f"forward {statistics.median(times):.5f}")
row = run(sf.load_case("panels").with_values({"render.variant": variant}), "lm", 40)
print(f"fit {row['wall_s']:.3f} {max(abs(e) for e in row['errors'].values()):.5f}")
"""
# A notebook's first render: a fresh process imports spacefit and renders the default scene; each
# stage timed (imports, Mitsuba's variant, the scene's assembly and load, the render), the Dr.Jit
# kernels compiled (0 when its disk cache ~/.drjit holds them) and the heavy modules it imported.
FIRST_RENDER = """
import sys, time
t0 = time.perf_counter()
import spacefit as sf
t1 = time.perf_counter()
from spacefit.rendering.backend import variant_scope
from spacefit.rendering.logs import kernel_log
from spacefit.rendering.renderer import Renderer
t2 = time.perf_counter()
scene = sf.load_scene(None)
with variant_scope(scene.render.variant):
    t3 = time.perf_counter()
    renderer = Renderer(scene)
    t4 = time.perf_counter()
    with kernel_log() as k:
        renderer.render()
    t5 = time.perf_counter()
heavy = [m for m in ("jax", "xarray", "dask", "matplotlib", "scipy", "trimesh", "optimistix") if m in sys.modules]
print(f"import spacefit {t1 - t0:.2f} s, import Dr.Jit and Mitsuba {t2 - t1:.2f} s, Mitsuba's variant {t3 - t2:.2f} s, "
      f"assemble and load {t4 - t3:.2f} s, render {t5 - t4:.2f} s ({k['launched']} kernels, {k['compiled']} compiled, "
      f"{k['compile_s']:.2f} s); in all {t5 - t0:.2f} s; heavy modules imported: {heavy or 'none'}")
"""
# Issue 33's targets, each printed with its target by its own script: the 8-parameter observation fit as a whole
# `spacefit fit` process, the 12-frame pass (reduced to 64 x 64 px frames unless --full: 128 px, 12, 48 and 100
# frames, an hour or more on 2 cores), the 24-point light curve at 0.5 % a point, and a render in a long-running
# process against one in a fresh process.
ISSUE_33 = (("bench_fit_process.py", "the 8-parameter observation fit, whole `spacefit fit` process"),
            ("bench_pass.py", "the 12-frame pass in one process"),
            ("bench_light_curve.py", "a 24-point light curve of the default lander at 0.5 % a point"),
            ("bench_long_process.py", "a render in a long-running process"))
CUDA_PROBE = "from spacefit.rendering.backend import dr; print(dr.has_backend(dr.JitBackend.CUDA))"


def child(args: list[str], env: dict[str, str] | None = None) -> tuple[float, float, str]:
    """Run a command; its wall time (s), peak resident memory (MiB) and output."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, cwd=ROOT, env={**os.environ, **(env or {})}, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(args)} failed ({proc.returncode}):\n{out[-2000:]}")
    return wall, usage.ru_maxrss / 1024, out


# The main job's floor: Python with Dr.Jit and Mitsuba's LLVM variant set as spacefit sets it (its AD
# integrators from the disk cache of their rewrites, spacefit.rendering.syntax_cache), nothing else.
FLOOR = "import spacefit.rendering.backend as b; b.mi.set_variant('llvm_ad_rgb')"


def main_job(repeats: int) -> None:
    """``spacefit render`` of the default scene: cold (empty mesh cache) once, then warm, each warm run in
    turn with the floor (:data:`FLOOR`); the stages its ``--timings`` table does not hold (Python's start-up,
    NumPy and the command line's modules, the exit) are the whole process's wall time less the table's total."""
    print(f"\n## spacefit render, default scene (wall s, whole process; peak MiB; {load()})")
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        env = {"SPACEFIT_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
        render = [sys.executable, "-m", "spacefit.cli", "render", "--quiet", "--overwrite", "--timings", "--out", out]
        wall, peak, text = child(render, env)
        print(f"cold (mesh cache empty): {wall:.2f} s, {peak:.0f} MiB\n{text.strip()}")
        runs, floors = [], []
        for _ in range(repeats):
            runs.append(child(render, env))
            floors.append(child([sys.executable, "-c", FLOOR], env)[0])
        walls = sorted(r[0] for r in runs)
        outside = sorted(w - float(out.split("total", 1)[1].split()[0]) for w, _, out in runs)
        print(f"warm: median {statistics.median(walls):.2f} s (target 0.5 s; min {walls[0]:.2f}, max {walls[-1]:.2f}, {repeats} runs), "
              f"{runs[-1][1]:.0f} MiB; outside the stages below (start-up, NumPy and the CLI's modules, exit): median "
              f"{statistics.median(outside):.2f} s; the floor (Python, Dr.Jit, Mitsuba's variant): median "
              f"{statistics.median(floors):.2f} s (min {min(floors):.2f})\n{runs[-1][2].strip()}")


def load() -> str:
    """The machine's load average over the last minute, for each section's heading."""
    return f"load {os.getloadavg()[0]:.1f}"


def first_render(repeats: int) -> None:
    """A notebook's first render (:data:`FIRST_RENDER`), each in a fresh process, mesh cache warm."""
    print(f"\n## a notebook's first render, default scene (fresh process; {load()})")
    runs = [child([sys.executable, "-c", FIRST_RENDER], {"PYTHONPATH": str(ROOT)}) for _ in range(repeats)]
    walls = sorted(r[0] for r in runs)
    print(f"whole process: median {statistics.median(walls):.2f} s (min {walls[0]:.2f}, max {walls[-1]:.2f}, {repeats} runs)\n"
          f"{runs[-1][2].strip()}")


def gpu_against_cpu() -> None:
    """The default forward render and the panels fit with ``cuda_ad_rgb`` against ``llvm_ad_rgb`` on 2
    threads, where a CUDA GPU is usable (each variant in its own process)."""
    env = {"PYTHONPATH": str(ROOT)}
    if child([sys.executable, "-c", CUDA_PROBE], env)[2].strip() != "True":
        print(f"\n## GPU: no CUDA GPU usable here; cuda_ad_rgb not measured ({load()})")
        return
    print("\n## GPU (cuda_ad_rgb) against the CPU (llvm_ad_rgb, 2 threads)")
    runs = {}
    for variant in ("llvm_ad_rgb", "cuda_ad_rgb"):
        lines = dict(line.split(" ", 1) for line in child([sys.executable, "-c", VARIANT_RUN, variant], env)[2].splitlines()
                     if line.startswith(("forward ", "fit ")))
        runs[variant] = (float(lines["forward"]), *map(float, lines["fit"].split()))
        forward, fit, error = runs[variant]
        print(f"{variant}: default forward render {forward * 1e3:.1f} ms, panels fit (LM) {fit:.2f} s, largest error {error:.2%}")
    cpu, gpu = runs["llvm_ad_rgb"], runs["cuda_ad_rgb"]
    print(f"GPU / CPU time: forward {gpu[0] / cpu[0]:.3f}, fit {gpu[1] / cpu[1]:.3f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--full", action="store_true", help="the forward study at full size (1024 spp references, spp 4-64) "
                   "and the pass at its targets' size (128 px; 12, 48, 100 frames)")
    p.add_argument("--repeats", type=int, default=5, help="warm runs of the main job")
    p.add_argument("--long-fit-steps", type=int, default=500)
    p.add_argument("--start-up", action="store_true", help="the main job and a notebook's first render only (a minute)")
    args = p.parse_args()
    print(f"machine: {machine()}, commit {commit()}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"load average {os.getloadavg()[0]:.1f}")
    main_job(args.repeats)
    first_render(args.repeats)
    if args.start_up:
        return
    wall, peak, text = child([sys.executable, str(HERE / "bench_fixed_cost.py")], {"PYTHONPATH": str(ROOT)})
    print(f"\n## per-call fixed cost of a fit's renders (bench_fixed_cost.py; {wall:.0f} s; {load()} at the end)\n{text.strip()}")
    wall, peak, text = child([sys.executable, str(HERE / "profile_frozen_call.py")], {"PYTHONPATH": str(ROOT)})
    print(f"\n## a frozen call's steps, CPU time outside the kernels whatever the load (profile_frozen_call.py; {wall:.0f} s; "
          f"{load()} at the end)\n{text.strip()}")
    for script, what in ISSUE_33:
        wall, peak, text = child([sys.executable, str(HERE / script), *(["--full"] if args.full and script == "bench_pass.py" else [])],
                                 {"PYTHONPATH": str(ROOT)})
        print(f"\n## {what} ({script}; {wall:.0f} s; {load()} at the end)\n{text.strip()}")
    wall, peak, text = child([sys.executable, str(HERE / "bench_fit.py"), "--observed"], {"PYTHONPATH": str(ROOT)})
    print(f"\n## the fit of an observation (bench_fit.py --observed; {wall:.0f} s whole process with its truth's "
          f"render, peak {peak:.0f} MiB; {load()})\n{text.strip()}")
    with tempfile.TemporaryDirectory() as out:
        forward = [sys.executable, str(HERE / "forward_pareto.py"), "--methods", "--out", out, *(["--full"] if args.full else [])]
        wall, peak, text = child(forward)
        print(f"\n## forward renders at equal error (600 px, depth 2; {wall:.0f} s, {peak:.0f} MiB; {load()} at the end)")
        # interpolations the sweep's spp cannot bracket are NaN: left out
        print("\n".join(line[line.index("{"):] for line in text.splitlines() if "{'view'" in line and "nan" not in line))
    wall, peak, text = child([sys.executable, str(HERE / "bench_fit.py")])
    print(f"\n## fits (bench_fit.py; {wall:.0f} s whole process, peak {peak:.0f} MiB; {load()} at the end)\n{text.strip()}")
    wall, peak, text = child([sys.executable, "-c", LONG_FIT.replace("STEPS", str(args.long_fit_steps))],
                             {"PYTHONPATH": str(ROOT)})
    print(f"\n## a long fit: peak memory and Dr.Jit kernels ({wall:.0f} s, peak {peak:.0f} MiB; {load()} at the end)\n{text.strip()}")
    gpu_against_cpu()


if __name__ == "__main__":
    main()
