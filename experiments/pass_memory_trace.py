"""Where a pass fit's memory goes (issue 33): the 64-parameter pass of ``bench_pass.py`` (panels case, 3
materials and the PSF width shared, 5 own values a frame) at a small size and a few steps, with this
process's resident memory sampled every 20 ms and read at the edges of each batch of renders (the Dr.Jit
side: :func:`spacefit.fitting.frames.run_frames`), so that what grows inside the renders is told from what
grows in the compiled JAX step around them. Prints the peak RSS, the peak inside render batches and
outside them (the solve), and after the solve in the covariance, the pixel grid's renders and step, and the
goodness of fit (the phases a render batch inside them counts as "render"), and the loaded scenes held at the end.
With ``ANALYSE=1`` the solver's step is compiled once more at its first call to print XLA's memory analysis
of it (temporaries, arguments, outputs), RSS before and after its tracing and compilation, and its state's
arrays by kind (this second compilation raises the peak). Figures: docs/measurements/performance-history.md,
"A pass's memory".
Run: ``[ANALYSE=1] python experiments/pass_memory_trace.py [SIZE_PX] [FRAMES] [STEPS]`` (default 64 px, 4 frames, 2 steps).
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import bench_pass  # noqa: E402

import spacefit as sf  # noqa: E402
from spacefit.fitting import frames as frames_module  # noqa: E402


def rss_mib() -> float:
    """This process's resident set size now, MiB."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


class Sampler(threading.Thread):
    """The peak RSS in each phase ("render" inside a batch of renders, "jax" outside), sampled."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.phase, self.peaks, self.events = "setup", {}, []

    def run(self) -> None:
        while True:
            self.peaks[self.phase] = max(self.peaks.get(self.phase, 0.0), rss_mib())
            time.sleep(0.02)


def analyse_steps() -> None:
    """Print the compiled solver step's XLA memory analysis (its arguments, outputs and temporaries) at its first call."""
    import equinox as eqx
    import jax

    from spacefit.fitting import drivers

    class Proxy:
        def __getattr__(self, name):  # type: ignore[no-untyped-def]
            return getattr(eqx, name)

        @staticmethod
        def filter_jit(fn, **kw):  # type: ignore[no-untyped-def]
            jitted, done = eqx.filter_jit(fn, **kw), []

            def call(*args):  # type: ignore[no-untyped-def]
                if not done and getattr(fn, "__name__", "") == "step":
                    done.append(1)
                    before = rss_mib()
                    lowered = jitted.lower(*args)
                    traced = rss_mib()
                    m = lowered.compile().compiled.memory_analysis()
                    print(f"  compiled step: RSS {before:.0f} before tracing, {traced:.0f} traced and lowered, {rss_mib():.0f} compiled; "
                          f"temporaries {m.temp_size_in_bytes / 2**20:.1f} MiB, arguments {m.argument_size_in_bytes / 2**20:.1f}, "
                          f"outputs {m.output_size_in_bytes / 2**20:.1f}", flush=True)
                    groups: dict[str, list[float]] = {}
                    for path, leaf in jax.tree_util.tree_flatten_with_path(args[4])[0]:
                        key = jax.tree_util.keystr(path).split(".consts")[0]
                        group = groups.setdefault(f"{key} {getattr(leaf, 'dtype', '')}", [0, 0.0])
                        group[0] += 1
                        group[1] += getattr(leaf, "nbytes", 0) / 2**20
                    for key, (count, mib) in sorted(groups.items(), key=lambda t: -t[1][1])[:8]:
                        print(f"    state{key}: {count} arrays, {mib:.1f} MiB")
                return jitted(*args)
            return call

    drivers.eqx = Proxy()


def phases(sampler: Sampler) -> None:
    """Mark the phases after the solve: the covariance, the pixel grid's 4x renders and step, the goodness of fit."""
    from spacefit.fitting import conclusion, residuals

    def marked(fn, phase, after=None):  # type: ignore[no-untyped-def]
        def call(*args, **kwargs):  # type: ignore[no-untyped-def]
            sampler.phase = phase
            try:
                return fn(*args, **kwargs)
            finally:
                sampler.phase = after or sampler.phase
        return call

    conclusion.estimate = marked(conclusion.estimate, "covariance", "after")
    residuals.grid_error_models = marked(residuals.grid_error_models, "pixel grid")
    conclusion.judged_goodness = marked(conclusion.judged_goodness, "goodness", "after")


def main() -> None:
    size, n, steps = (int(a) for a in (sys.argv[1:] + ["64", "4", "2"][len(sys.argv) - 1:])[:3])
    sampler = Sampler()
    sampler.start()
    run_frames = frames_module.run_frames

    def traced(executor, fn, specs, *args):  # type: ignore[no-untyped-def]
        before, phase = rss_mib(), sampler.phase
        sampler.phase = "render"
        out = run_frames(executor, fn, specs, *args)
        sampler.events.append((fn.__name__, before, rss_mib(), sampler.peaks.get("jax", 0.0)))
        sampler.phase = phase
        return out

    frames_module.run_frames = traced
    phases(sampler)
    if os.environ.get("ANALYSE"):
        analyse_steps()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "pass"
        rng = np.random.default_rng(3)
        errors = [{"target.attitude_x_deg": float(a), "target.attitude_z_deg": float(b)} for a, b in rng.uniform(-0.3, 0.3, (n, 2))]
        sf.simulate_pass(bench_pass.base(size), sf.arc_pass(n), folder, errors=errors, sensor=bench_pass.SENSOR, spp=64)
        frames = sf.Pass.read(folder / "frames.csv")
        obs = [sf.Observation.from_file(f.file, s) for f, s in zip(frames.frames, frames.scenes(bench_pass.base(size)))]
        free = [*bench_pass.MATERIALS, "image.blur_sigma_px", *[f"{p}@{k}" for k in range(n) for p in bench_pass.PER_FRAME]]
        print(f"{size} px, {n} frames, {len(free)} parameters, {steps} steps; after set-up {rss_mib():.0f} MiB; load {os.getloadavg()[0]:.1f}",
              flush=True)
        sampler.phase = "jax"
        result = sf.fit(obs, free, start=bench_pass.START, render=sf.FitRender(spp=bench_pass.FIT_SPP), max_steps=steps)
        sampler.phase = "end"
    for name, before, after, jax_peak in sampler.events:
        print(f"  {name}: RSS {before:.0f} -> {after:.0f} MiB (peak outside renders so far {jax_peak:.0f})")
    print(f"steps {result.steps}; peak RSS: set-up {sampler.peaks.get('setup', 0):.0f}, in renders {sampler.peaks.get('render', 0):.0f}, "
          f"in JAX {sampler.peaks.get('jax', 0):.0f} MiB; after the solve: "
          + ", ".join(f"{p} {sampler.peaks[p]:.0f}" for p in ("covariance", "pixel grid", "goodness", "after") if p in sampler.peaks)
          + f" MiB; scenes, frames held: {frames_module.loaded_count()}; load {os.getloadavg()[0]:.1f}")
    print("values: " + ", ".join(f"{k} {v!r}" for k, v in result.values.items() if "@" not in k or k.endswith("@0")))


if __name__ == "__main__":
    main()
