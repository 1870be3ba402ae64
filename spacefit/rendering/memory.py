"""How much memory a render needs, and a refusal, before it starts, of one this machine cannot hold; and the
freed memory a long fit's phases leave held, handed back between them."""

from __future__ import annotations

import ctypes
import functools
import os
from collections.abc import Callable

from spacefit.errors import InputError


# Samples traced per pass: bounds the wavefront's memory (about 1 GB on the CPU) on big renders.
MAX_SAMPLES_PER_PASS = 1 << 24
# Bytes a render holds per film pixel: Mitsuba's film (RGB, alpha, weight in float32), the image and
# its copies in NumPy (float32 RGB), the traced pixels' indices (int64, then uint32), the part IDs and
# the preview's tone map (done in row blocks).
BYTES_PER_PIXEL = 92
# Bytes per sample in flight in the wavefront (about 1 GB at MAX_SAMPLES_PER_PASS, measured).
BYTES_PER_SAMPLE = 64
# Samples one Dr.Jit wavefront can hold: its arrays are indexed with 32-bit integers.
MAX_WAVEFRONT = 2**32 - 1


def available_memory_bytes() -> int:
    """Memory the system can still give (MemAvailable of /proc/meminfo; total physical elsewhere)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_memory(width: int, height: int, window_pixels: int, spp: int, split: bool = True) -> int:
    """Estimate a render's peak memory (bytes) and refuse one that would not fit in the machine's.

    Samples are traced in passes of at most :data:`MAX_SAMPLES_PER_PASS` (``split``), so the wavefront is
    bounded and the film's size is what can exceed the memory. A fit's renders (``split`` False) trace
    all ``window_pixels * spp`` samples at once: at most :data:`MAX_WAVEFRONT` (Dr.Jit's 32-bit indices),
    and their memory counts too (at :data:`BYTES_PER_SAMPLE`, a primal render's: an AD render needs more).
    """
    samples = window_pixels * spp
    if not split and samples > MAX_WAVEFRONT:
        raise InputError(f"`spp` = {spp} on the {window_pixels} px a fit renders is {samples:.3g} samples in one wavefront; "
                         f"Dr.Jit traces at most {MAX_WAVEFRONT:.3g} (32-bit indices): lower `spp` or `render.resolution`.")
    estimate = BYTES_PER_PIXEL * width * height + BYTES_PER_SAMPLE * (min(samples, MAX_SAMPLES_PER_PASS) if split else samples)
    limit = available_memory_bytes()
    if estimate > limit:
        raise InputError(f"a {width} x {height} px render at {spp} spp needs about {estimate / 2**30:.1f} GiB and this machine has "
                         f"{limit / 2**30:.1f} GiB available; lower `render.resolution`{'' if split else ' or `spp`'}.")
    return estimate


# A fit's memory besides the rendering's, fitted (2 to 15 % above each peak; the peaks of one run scatter by up to 14 %
# with the allocator's state) to the peak RSS of issue 33's 64-parameter pass (experiments/bench_pass.py: 3 materials and
# the PSF width shared, 5 own values a frame, so 9 columns; each frame's image model, sensor and pixel grid; LM at 16 spp)
# at 12 and 48 frames of 128 x 128 px (920 and 1841 MiB) with the C heap's freed pages handed back between the phases
# (release_freed_memory, below), and at 12, 24 and 48 frames of 64 x 64 px at commit 1022e7d, before that (883, 1010,
# 1265 MiB: above the code's own), stored in experiments/results/pass_memory/ (tests/test_pass.py's CALIBRATION): the
# process with JAX, Mitsuba, a loaded scene and the solver's and covariance's programs, per frame a fixed part (its
# programs' share, scene values and records, the rows-long vectors of the covariance's products, which grow with the
# frames' pixels less than in proportion) and 100 B per pixel for its image and each column (reference, renders,
# Jacobian columns, the pixel grid's renders at 4x), from the growth of 10.6 MiB a frame at 64 x 64 px and 25.6 MiB at
# 128 x 128 px. It puts the 2-column pass of docs/measurements/reliability.md ("Memory per frame") 6 to 37 % above its
# peaks, and a 100-frame pass of 128 x 128 px (2 steps at 4 spp) 7 % above its peak (3386 MiB for 3176).
# With the freed heap handed back around each batch of a pass's renders too (2c682df), the 128 x 128 px pass peaked at
# 997, 1149 and 1713 MiB at 12, 24 and 48 frames (also in CALIBRATION): 6 to 20 % below the estimate, 20 MiB a frame. The Jacobian
# is never held whole (fitting/normal_equations.py): held whole, rows of every frame by the columns of every frame, it
# grew as frames^2, as the pixel grid's derivatives held whole did (4928 MiB at 48 frames of 128 x 128 px).
FIT_BASE_BYTES = 720 * 2**20
FIT_FRAME_BYTES = 11 * 2**20
FIT_FRAME_PIXEL_COLUMN_BYTES = 100
# A fit estimated above this states its size before it starts (a warning; ``spacefit fit`` says every pass's).
LARGE_FIT_BYTES = 2**30


def fit_memory(frames: int, pixels: int, columns: int, spp: int) -> int:
    """Estimate the peak memory (bytes) of a fit of ``frames`` images of ``pixels`` pixels each, each
    frame's renderer seeing ``columns`` free parameters, rendered at ``spp``: the process's base, the
    frames' own memory (:data:`FIT_FRAME_BYTES`, and :data:`FIT_FRAME_PIXEL_COLUMN_BYTES` per pixel for
    the image and each column) and one render's wavefront at a time (:data:`BYTES_PER_SAMPLE`)."""
    per_frame = FIT_FRAME_BYTES + FIT_FRAME_PIXEL_COLUMN_BYTES * pixels * (1 + columns)
    return FIT_BASE_BYTES + frames * per_frame + BYTES_PER_SAMPLE * pixels * spp


def describe_fit(frames: int, width: int, height: int, estimate: int) -> str:
    """A fit's size in words: its frames, their size and its estimated memory."""
    return f"a fit of {frames} frame{'s' * (frames != 1)} of {width} x {height} px needs about {estimate / 2**30:.2f} GiB of memory"


def check_fit_memory(frames: int, width: int, height: int, columns: int, spp: int, *, allow_large: bool = False) -> int:
    """Estimate a fit's peak memory (:func:`fit_memory`, bytes) and, unless ``allow_large``, refuse one
    above the memory this machine has available."""
    estimate = fit_memory(frames, width * height, columns, spp)
    limit = available_memory_bytes()
    if estimate > limit and not allow_large:
        raise InputError(f"{describe_fit(frames, width, height, estimate)} (estimate) and this machine has {limit / 2**30:.2f} GiB "
                         "available; fit fewer frames or fewer pixels, or pass allow_large=True (--large) to run it.")
    return estimate


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim`` (None where the C library has none: musl, macOS, Windows)."""
    try:
        return ctypes.CDLL(None).malloc_trim
    except (AttributeError, OSError):
        return None


def release_freed_memory() -> None:
    """Hand back to the system the pages of the C heap that are freed but held (glibc's ``malloc_trim(0)``; nothing
    where there is none). glibc keeps what a thread frees in that thread's arena for its own later use, and XLA's
    and Dr.Jit's threads each have one: between a joint fit's phases (the solve, the covariance's products, the pixel
    grid's programs) 0.3 to 0.6 GB of a 48-frame pass of 128 x 128 px lay freed in arenas that the next phase's
    threads do not reuse (docs/measurements/performance-history.md, "A pass's memory: programs and the allocator"); so
    within the phases too, around each batch of a pass's renders and each evaluation of its pixel grid's models (the solve's
    peak 980 MiB at 24 frames of 128 x 128 px, 3 steps, where it was 1344: experiments/results/pass_memory/). Changes
    no setting of the allocator; a call costs some milliseconds, and the pages handed back fault in again when reused."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
