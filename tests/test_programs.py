"""A fit's programs, lowered as in a process of its own. Its host arithmetic stays out of JAX: spacefit computes on
concrete values with NumPy and copies them to the device with ``precision.on_device``, so no program of one operation
(``jit(add)``, ``jit(convert_element_type)``, ``jit(stage)`` for JAX 0.10's ``jnp.asarray`` of a NumPy array) is
traced, lowered and read from JAX's cache in every process, 15 to 30 ms each (experiments/fit_programs.py lists each
program a fit lowers). And its programs take their arrays (references, masks, a sensor's factors, the pixel grid's
renders and response matrices) as operands, embedding none as a constant (spacefit.fitting.frame_models's docstring)."""

from __future__ import annotations

import collections
import os
import traceback
import warnings

import equinox
import jax
import jax.monitoring
import jax.numpy as jnp
import lineax
import numpy as np
import optimistix
import pytest
from helpers import write_sphere_fit_case

import spacefit as sf
from spacefit.cli import main
from spacefit.programs import AlikePrograms
from spacefit.rendering.exr import read_exr
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import load_scene

# A program's name that is one operation's: a lax primitive or jax.numpy function run on concrete values (`stage`: the
# program of `jnp.asarray` of a NumPy array in JAX 0.10).
OPERATIONS = {*vars(jax.lax), *vars(jnp), "stage"}

# The single-operation programs a fit may lower, each with where it comes from and why it stays.
ALLOWED = collections.Counter({
    # while the step is traced, optimistix's result (equinox's `RESULTS.promote`: `jnp.asarray(base_offsets)` of its
    # enum's offsets) and lineax's `result == RESULTS.successful` on concrete enum values: not spacefit's code
    ("jit(convert_element_type)", "equinox/_enum.py:promote"): 1,
    ("jit(convert_element_type)", "equinox/_enum.py:__eq__"): 2,
    ("jit(stage)", "equinox/_enum.py:promote"): 1,
    # a pass's Jacobian noise's column J1^T v - J2^T v under by_columns's vmap (Linearisation.difference): the two products
    # are programs of their own, and jitting their difference with them would trace and compile both products once more
    ("jit(subtract)", "spacefit/fitting/uncertainty.py:difference_column"): 1,
})

# The packages whose frames name where a program was asked for.
PACKAGES = [os.path.dirname(m.__file__) for m in (sf, equinox, lineax, optimistix)]

# About 600 DN on the lit sphere in 12 bits: an observation with its sensor, as a user's fit reads one, with a PSF (its
# Fourier filter's frequencies in the model).
SENSOR = sf.Sensor(exposure_time_s=3e-7, gain_dn_per_electron=0.5, bias_dn=50.0, bit_depth=12, full_well_electrons=None,
                   psf_sigma_px=0.5)

# The most bytes of constants one of a fit's programs may embed (JAX's own count, ``jax_captured_constants_warn_bytes``):
# less than one of the test's images (48 x 48 x 3 float32, 27 KiB), more than the mesh's vertices that render the sphere.
CONSTANT_BYTES = 16 * 1024
# JAX's warning when a program embeds more
CONSTANTS_WARNING = "A large amount of constants were captured during lowering"


def _origin() -> str:
    """The innermost frame of spacefit's code or its solvers' in the stack, "package/file.py:function"."""
    for frame in reversed(traceback.extract_stack()):
        for package in PACKAGES:
            if frame.filename.startswith(package + os.sep):
                return f"{os.path.relpath(frame.filename, os.path.dirname(package))}:{frame.name}"
    return "elsewhere"


@pytest.fixture(scope="module")
def fit_programs(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[tuple[str, str]], list[str]]:
    """The programs a small observation fit lowers, each (name, origin: :func:`_origin`), and JAX's warnings of the
    constants any embeds past :data:`CONSTANT_BYTES`: its image nuisances free, so that the pixel grid's programs run."""
    tmp_path = tmp_path_factory.mktemp("fit")
    case = write_sphere_fit_case(tmp_path, subdivisions=2, size=48, spp=4)
    dn = sf.observe(read_exr(case / "ref.exr"), SENSOR, assemble(load_scene(case / "scene.toml")).intrinsics, seed=3)
    sf.write_observation(case / "obs.fits", dn, SENSOR)
    lowered = []

    def listener(event: str, seconds: float, **kwargs: object) -> None:
        if event == "/jax/core/compile/jaxpr_to_mlir_module_duration":
            lowered.append((str(kwargs.get("fun_name")), _origin()))

    jax.clear_caches()  # every program the fit runs lowered again, as in a process of its own
    jax.monitoring.register_event_duration_secs_listener(listener)
    limit, frames = jax.config.jax_captured_constants_warn_bytes, jax.config.jax_captured_constants_report_frames
    jax.config.update("jax_captured_constants_warn_bytes", CONSTANT_BYTES)
    jax.config.update("jax_captured_constants_report_frames", 12)  # the warning says where each was captured
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            main(["fit", str(case / "obs.fits"), "--scene", str(case / "scene.toml"), "--free",
                  "parts.sphere.kd,image.blur_sigma_px,image.shift_x_px", "--out", str(tmp_path / "run"), "--max-steps", "3",
                  "--spp", "2", "--quiet"])
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
        jax.config.update("jax_captured_constants_warn_bytes", limit)
        jax.config.update("jax_captured_constants_report_frames", frames)
    return lowered, [str(w.message) for w in caught if CONSTANTS_WARNING in str(w.message)]


def test_a_fit_lowers_no_program_of_one_operation_from_spacefit(fit_programs):
    lowered, _ = fit_programs
    # the listener heard the fit's own programs, by name and origin, those whose arrays are operands (spacefit.programs:
    # the pixel grid's, the scene values') among them
    assert len(lowered) >= 10 and ("jit(_near_weighted)", "spacefit/fitting/uncertainty.py:<lambda>") in lowered
    assert sum(origin.startswith("spacefit/programs.py:") for _, origin in lowered) >= 3
    single = collections.Counter((name, origin) for name, origin in lowered if name.removeprefix("jit(").removesuffix(")") in OPERATIONS)
    assert single - ALLOWED == collections.Counter(), f"single-operation programs from the fit's host code: {single - ALLOWED}"


def test_a_fit_s_programs_embed_no_array_as_a_constant(fit_programs):
    """JAX warns of each program that embeds more than CONSTANT_BYTES of constants (an array it closes over): none does."""
    _, embedded = fit_programs
    assert embedded == [], "\n\n".join(embedded)


def test_a_program_compiled_ahead_runs_with_no_trace_and_gives_the_same_bits():
    """AlikePrograms.compile_ahead: the key's program compiled for arguments shaped as those given (their values unused),
    not run; the call with the key then traces, lowers and compiles nothing (JAX's own events), runs the program
    compiled ahead and gives the plain call's outputs bit for bit; another key of its kind shares the compiled program."""
    weights = np.linspace(0.5, 2.0, 12)  # an array the function closes over: an operand of its program
    events: list[str] = []

    def listener(event: str, seconds: float, **kwargs: object) -> None:
        events.append(event)

    def fn(a: jax.Array, b: jax.Array) -> tuple[jax.Array, jax.Array]:
        return jnp.sin(a * weights) @ b, jnp.cumsum(a)

    a, b = np.arange(12.0) / 7, np.ones(12) / 3
    plain = AlikePrograms()("plain", fn, a, b)
    ahead = AlikePrograms()
    ahead.compile_ahead("k", fn, np.zeros(12), np.zeros(12))
    assert isinstance(ahead._programs[ahead._kinds["k"]], jax.stages.Compiled)
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        out = ahead("k", fn, a, b)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert not [e for e in events if e.endswith(("trace_duration", "mlir_module_duration", "compile_duration"))], events
    for got, want in zip(out, plain):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    np.testing.assert_array_equal(np.asarray(ahead("other", fn, b, a)[0]), np.asarray(AlikePrograms()("x", fn, b, a)[0]))
    assert ahead._traced["other"][0] is ahead._traced["k"][0]  # the other key's kind: the program compiled ahead
