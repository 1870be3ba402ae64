"""Named mutants: plausible one-line bugs in the physics, camera, bridge and uncertainty code, each
of which some test must catch (``make mutants``; not part of ``make test``).

Each mutant names a file, an exact snippet of it, the snippet's replacement, and the tests that
should fail. The script copies the checkout (tracked and untracked, not ignored files) to a
temporary folder once, then for each mutant writes the mutated file there, runs only that mutant's
tests with ``-x -q`` and restores the file: the checkout itself is never changed. A snippet that is
no longer in its file, or not exactly once, is reported as stale: update the mutant.

Usage: python tools/mutants.py [NAME ...] [--list] [--no-baseline]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The covariance code's module.
COVARIANCE = "spacefit/fitting/uncertainty.py"
FRAMES = "spacefit/geometry/frames.py"
RENDERER = "spacefit/rendering/renderer.py"
MITSUBA_SCENE = "spacefit/rendering/mitsuba_scene.py"
MITSUBA_MATERIALS = "spacefit/rendering/materials.py"
BRIDGE = "spacefit/rendering/bridge.py"
DRJIT_SCENE = "spacefit/rendering/drjit_scene.py"
WM = "spacefit/geometry/wm.py"
# A mutant whose tests run longer than this is counted as killed (the suite would hang on it).
TIMEOUT_S = 900

CONVENTIONS = "tests/test_conventions.py"
UNCERTAINTY = "tests/test_uncertainty.py"
PROPERTIES = "tests/test_properties.py"
PHYSICS = "tests/test_physics.py"
PLUMBING = "tests/test_error_plumbing.py"
SENSITIVITY = "spacefit/studies/sensitivity.py"


@dataclass(frozen=True)
class Mutant:
    name: str
    path: str
    original: str
    replacement: str
    tests: tuple[str, ...]


MUTANTS = (
    # no global state left behind: Mitsuba's variant is the caller's again after spacefit renders
    Mutant("variant-left-at-spacefits", "spacefit/rendering/backend.py", "back = _caller_variant", "back = None",
           ("tests/test_api.py::test_spacefit_gives_the_callers_mitsuba_variant_back",)),
    # a render's fixed cost: the system libLLVM searched once per process, not per render
    Mutant("libllvm-searched-per-render", "spacefit/rendering/backend.py", "@functools.cache  # the file system's search",
           "# the file system's search", ("tests/test_api.py::test_a_render_asks_the_file_system_nothing",)),
    # a point's images taken again only at that point and seed index
    Mutant("outside-last-images-of-another-point", "spacefit/fitting/outside.py",
           "images = last[1] if last is not None and last[0] == point else None", "images = last[1] if last is not None else None",
           ("tests/test_outside.py::test_a_point_s_images_are_rendered_once_per_seed_index",)),
    # Mitsuba's rewritten integrators read from the disk only while their source is the one rewritten
    Mutant("syntax-cache-ignores-the-source", "spacefit/rendering/syntax_cache.py", "\"source\": source, ",
           "", ("tests/test_syntax_cache.py::test_a_changed_source_is_rewritten_again",)),
    # a deterministic render: its samples traced on all threads, added into the film on one in their order
    Mutant("deterministic-splat-in-parallel", RENDERER, "        with render_threads(deterministic):\n            splat(block, position, rgb)",
           "        with render_threads(False):\n            splat(block, position, rgb)",
           ("tests/test_render.py::test_a_deterministic_render_is_the_render_wholly_on_one_thread_bit_for_bit",)),
    # a background job's ignored SIGINT stays ignored; a scene never replaces a device, a pipe or a folder
    Mutant("ignored-signal-caught", "spacefit/interrupts.py", "if signal.getsignal(s) is not signal.SIG_IGN)", ")",
           ("tests/test_interrupts.py::test_a_signal_the_process_ignores_stays_ignored_in_fits_sweeps_and_renders",)),
    Mutant("scene-written-over-a-device", "spacefit/output.py", "if out.exists() and not out.is_file():", "if False:",
           ("tests/test_reliability.py::test_a_scene_written_over_a_pipe_or_a_folder_is_refused_and_leaves_it_as_it_was",)),
    # a render of cached displaced vertices reads their triangles, not the whole refinement
    Mutant("refinement-read-to-test-membership", "spacefit/scene/assembly.py", "        return name in self._sources\n",
           "        return name in self._sources and self[name] is not None\n",
           ("tests/test_speed.py::test_a_refinement_held_in_memory_says_so_and_one_not_needed_is_not_read",)),
    # a lock's start time as psutil reads it, without psutil: in seconds, not clock ticks
    Mutant("lock-start-time-in-ticks", "spacefit/locks.py", "return boot + ticks / os.sysconf(\"SC_CLK_TCK\")", "return boot + ticks",
           ("tests/test_locks.py::test_this_process_as_a_holder_is_what_psutil_reads_of_it",)),
    # a camera set the way a user thinks: the field kept across resolutions, an exposure at its fraction of full scale
    Mutant("fov-pitch-ignores-the-resolution", "spacefit/scene/optics.py", "math.tan(math.radians(camera.fov_deg) / 2.0) / render.resolution[0]",
           "math.tan(math.radians(camera.fov_deg) / 2.0) / 48", ("tests/test_camera.py",)),
    Mutant("exposure-counts-the-bias-as-signal", "spacefit/formation.py", "fraction * (sensor.saturation_dn - sensor.bias_dn) / level",
           "fraction * sensor.saturation_dn / level", ("tests/test_sensor.py",)),
    # camera and frames (thesis section 3.2)
    Mutant("euler-order", FRAMES, "return r1 @ r2 @ r3", "return r3 @ r2 @ r1", (CONVENTIONS,)),
    Mutant("r1-turns-the-other-way", FRAMES, "xp.stack([zero, xp.cos(a), xp.sin(a)]), xp.stack([zero, -xp.sin(a), xp.cos(a)])",
           "xp.stack([zero, xp.cos(a), -xp.sin(a)]), xp.stack([zero, xp.sin(a), xp.cos(a)])", (CONVENTIONS, "tests/test_camera.py")),
    Mutant("camera-looks-along-plus-z", FRAMES, "r[:, 1], -r[:, 2])", "r[:, 1], r[:, 2])", (CONVENTIONS,)),
    Mutant("look-at-up-flipped", FRAMES, "np.cross(right, forward), forward)", "np.cross(forward, right), forward)",
           ("tests/test_camera.py",)),
    Mutant("roll-turns-the-other-way", FRAMES, "return c * right - s * up, c * up + s * right",
           "return c * right + s * up, c * up - s * right", ("tests/test_camera.py",)),
    Mutant("fit-roll-counts-the-scene-roll-twice", "spacefit/rendering/values.py", "jnp.deg2rad(x[index[ROLL]] - view[ROLL])",
           "jnp.deg2rad(x[index[ROLL]])", ("tests/test_nuisance.py",)),
    # a rigid pose by the camera and the sun: their motion the pose's inverse, the wrinkles' vertices still moved
    Mutant("pose-by-view-moves-the-camera-with-the-target", "spacefit/rendering/values.py", "turn = to_world[:3, :3] @ rotation.T",
           "turn = rotation @ to_world[:3, :3].T", ("tests/test_pose_by_view.py",)),
    Mutant("pose-by-view-with-the-wrinkles-free", "spacefit/rendering/values.py", " and not any(n in names for n in GEOMETRY)", "",
           ("tests/test_pose_by_view.py",)),
    Mutant("per-observation-nuisance-ignored", "spacefit/fitting/nuisance.py", "for candidate in (Name(name, k), name):",
           "for candidate in (name,):", ("tests/test_nuisance.py",)),
    Mutant("per-observation-pose-rendered-by-the-others", "spacefit/fitting/params.py", "ref.observation not in (None, k)",
           "ref.observation not in (None, k + 1)", ("tests/test_nuisance.py",)),
    Mutant("per-observation-pose-starts-at-the-first-scene", "spacefit/fitting/problem.py", "images[ref.observation or 0].scene",
           "images[0].scene", ("tests/test_nuisance.py",)),
    Mutant("principal-point-sign", FRAMES, "self.width / 2 + self.principal_offset[0]",
           "self.width / 2 - self.principal_offset[0]", (CONVENTIONS,)),
    Mutant("v-runs-up", FRAMES, "v = v0 - intrinsics.focal_px", "v = v0 + intrinsics.focal_px", (CONVENTIONS,)),
    Mutant("fov-from-height", FRAMES, "np.arctan(self.width * self.pixel_pitch", "np.arctan(self.height * self.pixel_pitch",
           (CONVENTIONS,)),
    Mutant("pixel-pitch-in-microns", "spacefit/geometry/frames.py", "c.pixel_pitch_mm * 1e-3", "c.pixel_pitch_mm * 1e-6",
           (CONVENTIONS,)),
    Mutant("mitsuba-principal-point-sign", MITSUBA_SCENE, '"principal_point_offset_x": -intr.principal_offset[0]',
           '"principal_point_offset_x": intr.principal_offset[0]', (CONVENTIONS,)),
    # materials and the renderer's BSDFs (thesis section 2.3)
    Mutant("alpha-u-v-swapped", MITSUBA_MATERIALS, '"alpha_u": m.alpha_x, "alpha_v": m.alpha_y,',
           '"alpha_u": m.alpha_y, "alpha_v": m.alpha_x,', (PHYSICS,)),
    Mutant("beckmann-for-ggx", MITSUBA_MATERIALS, '"distribution": m.distribution,', '"distribution": "beckmann",', (PHYSICS,)),
    Mutant("fresnel-k-dropped", MITSUBA_MATERIALS, '"eta": _spectrum(m.eta), "k": _spectrum(m.k)}\n',
           '"eta": _spectrum(m.eta), "k": 0.0}\n', (PHYSICS, PROPERTIES)),
    Mutant("kd-over-pi-twice", MITSUBA_MATERIALS, '{"type": "diffuse", "reflectance": {"type": "rgb", "value": _rgb_list(m.kd)}}',
           '{"type": "diffuse", "reflectance": {"type": "rgb", "value": [v / 3.141592653589793 for v in _rgb_list(m.kd)]}}', (PHYSICS,)),
    Mutant("path-depth-off-by-one", MITSUBA_SCENE, "max_depth = s.render.depth + 1", "max_depth = s.render.depth", (PHYSICS,)),
    Mutant("default-distribution-beckmann", "spacefit/materials/conductor.py",
           'distribution: str = "ggx"\n\n    def __post_init__(self) -> None:', 'distribution: str = "beckmann"\n\n    def __post_init__(self) -> None:',
           (PHYSICS, PROPERTIES)),
    # W-M height field (thesis eq. 2-1)
    Mutant("wm-G-exponent-sign", WM, "scale = L * (G / L) ** (D - 2.0)", "scale = L * (G / L) ** (2.0 - D)",
           ("tests/test_wm.py", PROPERTIES)),
    Mutant("wm-scale-weights-sign", WM, "weights = jnp.power(gamma, (D - 3.0) * n)", "weights = jnp.power(gamma, (3.0 - D) * n)",
           ("tests/test_wm.py",)),
    Mutant("wm-rms-variance-not-halved", WM, "xp.sqrt(0.5 * math.log(gamma) * xp.sum(", "xp.sqrt(math.log(gamma) * xp.sum(",
           ("tests/test_wm.py",)),
    Mutant("wm-G-from-rms-exponent", WM, "** (1.0 / (D - 2.0))", "** (D - 2.0)", (PROPERTIES,)),
    # the JAX / Dr.Jit seam and the parameters
    Mutant("fd-column-one-sided-step", BRIDGE, "(up - down) / (2.0 * self.steps[j])", "(up - down) / self.steps[j]",
           ("tests/test_bridge.py::test_jacobian_columns_match_finite_differences",)),
    Mutant("forward-derivative-with-primal-seed", BRIDGE,
           "for k, t in tangents.items()} for j in ad], seed_grad)))", "for k, t in tangents.items()} for j in ad], seed)))",
           (CONVENTIONS,)),
    Mutant("backward-with-primal-seed", BRIDGE, "scene.backward(v, c, seed_grad)", "scene.backward(v, c, seed)", (CONVENTIONS,)),
    # a render's seed is an operand of its recordings: another seed replays them
    Mutant("forward-seed-literal", DRJIT_SCENE, "derivative(self.renderer.scene, self._integrator, dr.opaque(mi.UInt32, seed), count,",
           "derivative(self.renderer.scene, self._integrator, mi.UInt32(seed), count,",
           ("tests/test_frozen.py::test_a_new_seed_is_replayed_not_recorded_again",)),
    # a Jacobian's forward-mode columns share one primal pass, and each is the column rendered alone
    Mutant("forward-columns-each-own-primal-pass", DRJIT_SCENE, "            if key not in states:\n", "            if True:\n",
           ("tests/test_frozen.py::test_a_jacobians_columns_share_one_primal_pass_and_are_each_columns_own_render",)),
    # a forward-mode column survives a profiler holding PRB's frames (a pass on dask died of it), and leaves no AD state behind
    Mutant("forward-attaches-every-value", DRJIT_SCENE, "if np.any(np.asarray(t) != 0) and differentiable(", "if differentiable(",
           ("tests/test_bridge_scope.py::test_a_material_column_is_the_same_with_prb_frames_held",)),
    Mutant("forward-tried-once", DRJIT_SCENE, "FORWARD_ATTEMPTS = 2", "FORWARD_ATTEMPTS = 1",
           ("tests/test_bridge_scope.py::test_a_vertex_column_is_rendered_again_when_a_sample_held_its_branch",)),
    Mutant("forward-leaves-values-attached-on-error", DRJIT_SCENE, "        finally:\n            self._set(values)\n\n    def _render_forward",
           "        finally:\n            pass\n\n    def _render_forward",
           ("tests/test_bridge_scope.py::test_other_render_errors_are_not_repeated_and_leave_the_values_detached",)),
    # a fit's one-off costs: programs made ahead on a thread, the collector's threshold in a command's process
    Mutant("compiled-ahead-not-used", "spacefit/programs.py", "            self._traced[key] = (self._programs[kind], *self._traced[key][1:])\n",
           "            pass\n", ("tests/test_programs.py::test_a_program_compiled_ahead_runs_with_no_trace_and_gives_the_same_bits",)),
    Mutant("ahead-error-dropped", "spacefit/fitting/frame_models.py", "        yield\n        done.result()\n", "        yield\n        done.exception()\n",
           ("tests/test_pixel_grid.py::test_the_grid_step_compiles_its_last_programs_on_a_thread_beside_the_iterations_and_raises_its_error",)),
    Mutant("program-gc-threshold-default", "spacefit/cli.py", "gc.set_threshold(PROGRAM_GC_YOUNG, *gc.get_threshold()[1:])",
           "gc.set_threshold(700, *gc.get_threshold()[1:])",
           ("tests/test_fit_cli.py::test_the_program_s_modules_load_with_the_collector_off_and_are_frozen_out_of_its_scans",)),
    # an image fit's solver state: its Jacobian's columns held, not its model's linearisation
    Mutant("held-columns-tangent-unapplied", "spacefit/fitting/normal_equations.py",
           "        return r, jnp.reshape(t @ columns, r.shape)\n", "        return r, jnp.reshape(columns[0], r.shape)\n",
           ("tests/test_normal_equations.py::test_a_residual_with_held_columns_is_linearised_as_its_columns_alone",
            "tests/test_drivers.py::test_a_solve_holding_the_jacobians_columns_takes_the_same_steps")),
    Mutant("held-columns-never", "spacefit/fitting/loop.py", "columns_held=all_shared(column_owners(fp, s.problem.blocks)))",
           "columns_held=False)", ("tests/test_outside.py::test_the_solver_steps_the_same_on_renders_made_first",)),
    Mutant("primal-kept-whatever-the-seed", DRJIT_SCENE, "return seed, digest.digest()", "return 0, digest.digest()",
           ("tests/test_stopping.py::test_history_flags_match_the_loss_sequence",)),
    Mutant("no-better-point-after-any-two-rejections", "spacefit/fitting/stopping.py",
           "abs(last[-1] - last[-2]) < self.noise", "abs(last[-1] - last[-2]) >= 0.0",
           ("tests/test_stopping.py::test_consecutive_rejections_below_the_relative_tolerance_stop_the_solve",)),
    # a pass: each frame's scene from its table row, each frame's Jacobian on its own rows
    Mutant("frame-vector-components-reversed", "spacefit/fitting/passes.py",
           "[cell(cols[parts[c]][i]) for c in COMPONENTS]", "[cell(cols[parts[c]][i]) for c in reversed(COMPONENTS)]",
           ("tests/test_pass.py::test_each_frames_scene_equals_one_built_by_hand",)),
    Mutant("frame-jacobian-on-another-frame", "spacefit/fitting/render_batches.py",
           "for J, idx in zip(jacobians, seen))", "for J, idx in zip(jacobians, [s[::-1] for s in seen]))",
           ("tests/test_pass.py::test_a_reduced_pass_recovers_each_frames_attitude",)),
    # a pass's frames share a process's loaded scene: each sets its own camera and sun; the loaded scenes are bounded
    Mutant("frame-on-shared-scene-keeps-the-last-view", "spacefit/fitting/frames.py",
           "return tuple(n for n in (*VIEW, *(POSE if spec.view_pose else ())) if n not in spec.names)", "return ()",
           ("tests/test_pass.py::test_the_frames_of_a_pass_share_one_loaded_scene_and_render_as_on_their_own",)),
    Mutant("loaded-scenes-one-past-the-bound", "spacefit/fitting/frames.py",
           "while len(self.stages) >= self.max_scenes:", "while len(self.stages) > self.max_scenes:",
           ("tests/test_pass.py::test_a_process_keeps_at_most_max_scenes_loaded_dropping_the_least_recently_used",)),
    # ... and its compiled functions, each frame's view an operand: one program per loaded scene, not one per frame
    Mutant("frames-compile-a-program-each", "spacefit/fitting/frames.py", "name = (stage, spec.fd_steps)",
           "name = (key, spec.fd_steps)", ("tests/test_pass.py::test_the_frames_of_a_pass_compile_once_not_once_per_frame",)),
    # ... and its normal equations, one direction per kind of own value: a shared row of an own column from the shared column
    Mutant("own-column-shared-row-from-the-mixed-direction", "spacefit/fitting/normal_equations.py",
           "jnp.where(shared[:, None], shared_rows, 0.0)", "jnp.where(shared[:, None], taken, 0.0)",
           ("tests/test_normal_equations.py::test_gram_of_frames_own_columns_is_the_dense_product",)),
    Mutant("logistic-inverse-width", "spacefit/fitting/params.py", "p = (x - self.lo) / (self.hi - self.lo)\n        return jnp.log(p)",
           "p = (x - self.lo) / self.hi\n        return jnp.log(p)", (PROPERTIES,)),
    Mutant("sun-to-world-towards-the-sun", "spacefit/scene/conversions.py", 'return -xp.stack([xp.cos(el) * xp.cos(az)',
           'return xp.stack([xp.cos(el) * xp.cos(az)', (CONVENTIONS,)),
    # noise weights and the uncertainty
    Mutant("residual-over-sigma-squared", "spacefit/fitting/losses.py", "fixed = jnp.asarray(1.0 / s,",
           "fixed = jnp.asarray(1.0 / s**2,", (UNCERTAINTY,)),
    Mutant("covariance-plain-inverse", COVARIANCE, "cov = bread @ (meat + 0.5 * jacobian_noise) @ bread",
           "cov = bread", (UNCERTAINTY,)),
    Mutant("covariance-uniform-noise", COVARIANCE, "cov = bread @ (meat + 0.5 * jacobian_noise) @ bread",
           "cov = s2 * bread", (UNCERTAINTY,)),
    Mutant("covariance-no-hc1-factor", COVARIANCE, "d, offset = mean * math.sqrt(informative / dof), problem.pixels", "d, offset = mean * 1.0, problem.pixels",
           (UNCERTAINTY,)),
    Mutant("covariance-counts-black-sky", COVARIANCE, "informative = int(((probe != 0) | (r != 0)).sum())",
           "informative = len(r)", (UNCERTAINTY,)),
    Mutant("covariance-one-jacobian", COVARIANCE, "r_alt, J2 = problem.linearised(xj, 1)",
           "r_alt, J2 = problem.linearised(xj, 0)", (UNCERTAINTY,)),
    Mutant("covariance-undetermined-finite", COVARIANCE, "touched = np.any(np.abs(eigvec[:, tiny]) > 1e-6, axis=1)",
           "touched = np.zeros(len(x), dtype=bool)", (UNCERTAINTY,)),
    Mutant("covariance-no-jacobian-noise", COVARIANCE, "problem, x) + jacobian_noise\n", "problem, x)\n", (UNCERTAINTY,)),
    Mutant("render-noise-per-pixel", COVARIANCE, "sizes = [2 * noise_reach_px(problem, x, k) + 1 for k in", "sizes = [1 for k in", (UNCERTAINTY,)),
    Mutant("debias-with-the-fits-own-seed", COVARIANCE, "correction = -bread @ (0.5 * lin.adjoint(r_alt, r))",
           "correction = -bread @ (0.5 * lin.adjoint(r, r_alt))", (UNCERTAINTY,)),
    Mutant("unknown-noise-meat-of-the-fits-own-render", COVARIANCE, "_unknown_noise_draw(problem, mean, r, informative, dof)",
           "_unknown_noise_draw(problem, r, r, informative, dof)",
           ("tests/test_uncertainty.py::test_two_jacobians_enter_as_their_symmetrised_cross_product",)),
    Mutant("stand-out-untrimmed", "spacefit/fitting/goodness.py", "robust_spread = _trimmed_mean(r[counted] ** 2) / robust if",
           "robust_spread = spread if",
           ("tests/test_goodness.py::test_without_a_known_noise_an_observation_whose_residuals_stand_out_is_named",)),
    Mutant("stand-out-at-five", "spacefit/fitting/goodness.py", "STANDS_OUT = 3.0", "STANDS_OUT = 5.0",
           ("tests/test_goodness.py::test_without_a_known_noise_an_observation_whose_residuals_stand_out_is_named",)),
    # the render-seed check (issue 34): the fit's own renders' error measured against fresh seeds, its excess carried
    Mutant("render-seed-shift-of-one-own-render", "spacefit/fitting/render_seeds.py",
           "return step(sum(fresh) / len(fresh) - 0.5 * (own[0] + own[1]))", "return step(sum(fresh) / len(fresh) - own[1])",
           ("tests/test_render_seeds.py",)),
    Mutant("render-seed-excess-not-carried", COVARIANCE, "cov = cov + np.diag(seed_excess(shift, np.diag(modelled)))", "cov = cov",
           ("tests/test_render_seeds.py",)),
    Mutant("render-seed-excess-over-the-whole-error", "spacefit/fitting/render_seeds.py",
           "return np.maximum(0.0, shift**2 / (1.0 + 2.0 / len(FRESH)) - modelled)",
           "return np.maximum(0.0, shift**2 / (1.0 + 2.0 / len(FRESH)) - 4.0 * modelled)", ("tests/test_render_seeds.py",)),
    Mutant("poorly-determined-against-the-value", "spacefit/fitting/value_warnings.py", "max(abs(values[i]), parameter(name).scale, 1e-12)",
           "max(abs(values[i]), 1e-12)", (UNCERTAINTY,)),
    # observations from files (issue 10): masks and grey images
    Mutant("mask-ignored", "spacefit/fitting/losses.py", "keep = 1.0 if mask is None else",
           "keep = 1.0 if True else", ("tests/test_observations.py",)),
    Mutant("grey-reference-three-copies", "spacefit/fitting/observations/image.py", "        ref = ref[..., None]\n",
           "        ref = np.repeat(ref[..., None], 3, axis=-1)\n", ("tests/test_observations.py",)),
    Mutant("fisher-times-s2", COVARIANCE, "np.clip(eigval, 0.0, None) / s2", "np.clip(eigval, 0.0, None) * s2", (UNCERTAINTY,)),
    Mutant("map-covariance-transposed", COVARIANCE, "out = T @ np.where(np.isfinite(cov), cov, 0.0) @ T.T",
           "out = T.T @ np.where(np.isfinite(cov), cov, 0.0) @ T", (UNCERTAINTY,)),
    # observation files and the sensor as observers calibrate it (issue 18)
    Mutant("fits-roworder-ignored", "spacefit/imageio/fits.py", 'return stated, "header ROWORDER", notes',
           'return "bottom-up", "header ROWORDER", notes', ("tests/test_imageio.py",)),
    Mutant("header-rdnoise-dropped", "spacefit/imageio/fits.py", '"read_noise_electrons": ("RDNOISE", "READNOIS", "RON"),',
           '"read_noise_electrons": ("READNOIS", "RON"),', ("tests/test_imageio.py",)),
    # files and key languages refuse what they cannot use (issue 20)
    Mutant("fits-cube-planes-unchecked", "spacefit/imageio/fits.py", "    if data.shape[0] not in CHANNELS:", "    if False:",
           ("tests/test_file_inputs.py",)),
    Mutant("mask-nan-means-use", "spacefit/imageio/reading.py",
           "bad = ~np.isin(values, [0, *use]) if values.dtype != bool else np.zeros(values.shape, bool)",
           "bad = np.zeros(values.shape, bool)", ("tests/test_file_inputs.py",)),
    Mutant("string-is-a-number", "spacefit/errors.py", "    if isinstance(value, (str, bytes)):", "    if False:",
           ("tests/test_file_inputs.py",)),
    Mutant("vignetting-applied-when-off", "spacefit/sensor.py",
           "return (not self.calibrated) if self.vignetting is None else self.vignetting", "return True", ("tests/test_sensor.py",)),
    Mutant("psf-integrated-over-the-pixel-again", "spacefit/formation.py", "sigma_px**2 * (jnp.asarray(fx) ** 2 + jnp.asarray(fy) ** 2))",
           "sigma_px**2 * (jnp.asarray(fx) ** 2 + jnp.asarray(fy) ** 2)) * jnp.sinc(fx) * jnp.sinc(fy)",
           ("tests/test_sensor.py", "tests/test_nuisance.py::test_blur_is_the_sensors_continuous_gaussian_and_keeps_the_light")),
    # back faces, closed meshes and folded wrinkles (issues 11 and 13)
    # one vocabulary, checked everywhere (issue 18 item 7)
    Mutant("set-values-unchecked", RENDERER, "scene = scene_with_values(self.current_scene, given)  # refused",
           "scene = self.current_scene  # refused", ("tests/test_vocabulary.py",)),
    Mutant("sun-elevation-resets-the-azimuth", "spacefit/scene/registered.py",
           "angles = (values.get(n, get(scene, n)) for n in names)", "angles = (values.get(n, 0.0) for n in names)",
           ("tests/test_vocabulary.py",)),
    Mutant("part-typo-without-suggestion", "spacefit/scene/sections.py", "close = closest(path[1], parts)", "close = None",
           ("tests/test_vocabulary.py",)),
    Mutant("back-faces-one-sided", MITSUBA_MATERIALS, 'return {"type": "twosided", "bsdf": entry.bsdf(material)}',
           "return entry.bsdf(material)", ("tests/test_back_faces.py",)),
    Mutant("closed-check-without-merging", "spacefit/geometry/mesh.py", "    closed.merge_vertices(merge_tex=True, merge_norm=True)\n",
           "", ("tests/test_mesh_io.py",)),
    Mutant("fold-against-own-base-face", "spacefit/geometry/wrinkle.py", "ref.normals[movable][nearest]) < 0.0",
           "ref.normals[ref.faces[:, 0]]) < 0.0", ("tests/test_mli_default.py",)),
    # the error plumbing (issue 18): Monte Carlo errors, warnings, the render noise's reach, resumable sweeps
    Mutant("mc-error-population-std", SENSITIVITY, "samples.std(axis=0, ddof=1)", "samples.std(axis=0, ddof=0)",
           (PLUMBING,)),
    Mutant("mc-error-not-over-sqrt-n", SENSITIVITY, "ddof=1) / math.sqrt(samples.shape[0])", "ddof=1)", (PLUMBING,)),
    Mutant("t-quantile-n-degrees-of-freedom", SENSITIVITY, "CONFIDENCE / 2.0, seeds - 1))", "CONFIDENCE / 2.0, seeds))",
           (PLUMBING,)),
    Mutant("t-quantile-one-sided", SENSITIVITY, "t.ppf(0.5 + CONFIDENCE / 2.0,", "t.ppf(CONFIDENCE,", (PLUMBING,)),
    # figures and tables (issue 24): the chart's steps, the crop, a part table with a masked NaN, exact zeros
    Mutant("sensitivity-chart-by-value", SENSITIVITY, "((p.bounds.hi - p.bounds.lo) / 10.0,", "(abs(self.at[name]) / 10.0,",
           ("tests/test_plots.py",)),
    Mutant("figures-never-crop", "spacefit/plotting.py", "return target_box(images) if crop else", "return None or",
           ("tests/test_plots.py",)),
    # the comparison's residual column is residuals.fits's picture (grey where not fitted); the convergence figure's own layout
    Mutant("comparison-residual-not-the-fit-s", "spacefit/fitting/plots.py",
           "fitted = k < len(result.residuals) and np.ndim(result.residuals[k]) == 3", "fitted = False",
           ("tests/test_plots.py::test_the_comparison_s_residual_column_is_the_fit_s_residuals_on_a_symmetric_scale_in_their_unit",)),
    Mutant("convergence-columns-without-the-parameters-labels", "spacefit/fitting/plots.py",
           "gap = overhang + PAD_PT + max(", "gap = overhang + PAD_PT + 0 * max(",
           ("tests/test_plots.py::test_the_convergence_figure_s_labels_are_whole_and_apart_for_any_count_of_parameters",)),
    Mutant("part-means-count-masked-nan", "spacefit/rendering/parts.py", "counted = self.ids >= 0 if used is None else (self.ids >= 0) & np.asarray(used, dtype=bool)",
           "counted = self.ids >= 0",
           ("tests/test_api.py::test_part_image_and_table_match_the_parts_lit_pixels",)),
    Mutant("exact-zero-called-noise", SENSITIVITY, "return (self.d_mean_radiance == 0.0) & (self.d_mean_radiance_se == 0.0)",
           "return np.zeros_like(self.resolved)", ("tests/test_plots.py",)),
    Mutant("correlation-warning-positive-only", "spacefit/fitting/value_warnings.py", "if abs(corr[i, j]) > CORRELATION_WARN:",
           "if corr[i, j] > CORRELATION_WARN:", (PLUMBING,)),
    Mutant("psf-widths-added-linearly", COVARIANCE, "sigma = math.hypot(blur, 0.0 if i is None else float(x[i]))",
           "sigma = blur + (0.0 if i is None else float(x[i]))", (PLUMBING,)),
    Mutant("pixel-grid-moves-not-scaled-to-fine-pixels", "spacefit/fitting/fine_models.py", "x_fine = x_fine.at[i].multiply(factor)",
           "x_fine = x_fine.at[i].multiply(1)", ("tests/test_pixel_grid.py::test_a_resolved_image_has_no_pixel_grid_error_and_a_point_has_one",)),
    Mutant("pixel-grid-tent-as-box", "spacefit/fitting/fine_models.py", '"tent": lambda t: np.clip(1.0 - np.abs(t), 0.0, None)}',
           '"tent": lambda t: (np.abs(t) <= 0.5).astype(float)}',
           ("tests/test_pixel_grid.py::test_a_box_pixel_averages_its_own_fine_pixels_and_a_tent_weighs_its_neighbours_by_their_overlap",)),
    Mutant("pixel-grid-step-not-iterated", "spacefit/fitting/fixed_point.py", "while len(gs) < steps:",
           "while len(gs) < 1:",
           ("tests/test_pixel_grid.py::test_the_grid_step_is_the_fixed_point_of_the_step_and_carries_a_third_of_the_coarser_models_step",)),
    Mutant("pixel-grid-shortfall-without-feedback", "spacefit/fitting/pixel_grid.py",
           "short = np.linalg.solve(np.eye(len(x)) - feedback,", "short = np.linalg.solve(np.eye(len(x)),",
           ("tests/test_pixel_grid.py::test_a_fixed_point_not_reached_in_its_evaluations_is_flagged_with_each_values_distance",)),
    Mutant("real-fft-transfer-without-its-hermitian-part", "spacefit/formation.py",
           "hermitian = 0.5 * (transfer(fy, half) + jnp.conj(transfer(_negated(fy), _negated(half))))", "hermitian = transfer(fy, half)",
           ("tests/test_nuisance.py::test_blur_and_shift_by_the_real_fft_is_the_complex_ffts_to_the_round_off_with_its_derivatives",)),
    Mutant("pixel-grid-fine-pad-in-sensor-pixels", "spacefit/fitting/fine_models.py", "max(PAD_PX, math.ceil(factor * (",
           "max(PAD_PX, math.ceil(1 * (", ("tests/test_pixel_grid.py::test_the_fine_models_black_sky_covers_its_blur_and_shift_at_the_fine_scale_and_a_reach_past_it_fails",)),
    Mutant("pixel-grid-fine-model-past-its-pad-kept", "spacefit/fitting/fine_models.py",
           "finer = jnp.where(reach_px(x_fine, moves) > pad, jnp.nan, finer)", "finer = finer",
           ("tests/test_pixel_grid.py::test_the_fine_models_black_sky_covers_its_blur_and_shift_at_the_fine_scale_and_a_reach_past_it_fails",)),
    Mutant("pixel-grid-whole-step-carried", "spacefit/fitting/pixel_grid.py", "REMAINDER_RATIO * step(each.mean(axis=0) - coarser)",
           "step(each.mean(axis=0))",
           ("tests/test_pixel_grid.py::test_the_grid_step_is_the_fixed_point_of_the_step_and_carries_a_third_of_the_coarser_models_step",)),
    Mutant("pixel-grid-feedback-transposed", "spacefit/fitting/pixel_grid.py", "feedback[:, j] = moved",
           "feedback[j, :] = moved",
           ("tests/test_pixel_grid.py::test_the_fixed_point_moves_with_the_fits_estimate_by_the_inverse_of_one_less_the_steps_feedback",)),
    # a joint fit's batched renders, evaluated eagerly, wait for their callback: work queued on their images held every
    # XLA CPU slot the callback's own renders needed (a light-curve fit hung in its verdict)
    Mutant("batched-render-not-waited-for", "spacefit/fitting/render_batches.py",
           "return jax.block_until_ready(jax.pure_callback(primal_cb, images, x, seeds, vmap_method=\"sequential\"))",
           "return jax.pure_callback(primal_cb, images, x, seeds, vmap_method=\"sequential\")",
           ("tests/test_render_batches.py::test_batched_renders_evaluated_eagerly_wait_for_their_callback_before_work_is_queued_on_them",)),
    # ... its iterations past the finer models' black sky: a flagged result (UNSTEPPED, the values and reach named), not a traceback
    Mutant("pixel-grid-past-black-sky-raised", COVARIANCE, "except PastBlackSky as past:", "except ArithmeticError as past:",
           ("tests/test_fit_cli.py::test_a_pixel_grid_step_past_its_black_sky_is_flagged_with_the_fits_own_values_and_errors",)),
    Mutant("pixel-grid-unstepped-not-a-verdict", "spacefit/fitting/status.py", "    if unstepped:\n", "    if False:\n",
           ("tests/test_pixel_grid.py::test_a_step_past_the_black_sky_records_each_images_values_and_reach_and_the_fit_is_unstepped",)),
    Mutant("pixel-grid-black-sky-reach-not-its-growth", "spacefit/fitting/pixel_grid.py", "r[1] - r[0] > PAD_MARGIN_PX", "r[1] > PAD_MARGIN_PX",
           ("tests/test_pixel_grid.py::test_a_step_past_the_black_sky_records_each_images_values_and_reach_and_the_fit_is_unstepped",)),
    # ... an image's derivatives taken in the values it reads: its own and the shared ones
    Mutant("pixel-grid-changes-kept-past-a-shared-value", "spacefit/fitting/residuals.py", "o in (-1, k) for o in owners", "o == k for o in owners",
           ("tests/test_pass.py::test_the_pixel_grids_derivatives_are_each_frames_in_its_own_and_the_shared_values",)),
    Mutant("render-noise-spread-without-sensor-psf", "spacefit/fitting/residuals.py",
           "blur = 0.0 if obs.sensor is None else psf_rms_px(", "blur = 0.0 if True else psf_rms_px(", (PLUMBING,)),
    Mutant("light-curve-first-seed-only", "spacefit/studies/lightcurve.py", "mean, se = mean_and_error(samples) if",
           "mean, se = (samples[0], mean_and_error(samples)[1]) if", ("tests/test_lightcurve.py",)),
    Mutant("sweep-done-before-data", "spacefit/studies/store.py",
           '    for name in names:\n        group[name][index] = result[name]\n',
           '    group["done"][index] = True\n    for name in names:\n        group[name][index] = result[name]\n',
           (PLUMBING,)),
    # stores that cannot lie (issue 20): a done point is trusted only when its data match its checksum
    Mutant("done-without-checksum-check", "spacefit/studies/store.py",
           "point_checksum([v[local] for v, _ in data], index) == stored[local]", "True", ("tests/test_store_integrity.py",)),
    Mutant("sweep-marks-done-after-a-mesh-edit", "spacefit/studies/sweep.py",
           "if watch is not None and (edited := watch.check()):", "if False:", ("tests/test_store_integrity.py",)),
    # the fit's verdicts (spacefit/fitting/goodness.py, status.py, conclusion.py)
    Mutant("misfit-threshold-flipped", "spacefit/fitting/goodness.py", "bool(chi2_dof > limit)", "bool(chi2_dof < limit)",
           ("tests/test_goodness.py",)),
    Mutant("no-progress-start-corrected", "spacefit/fitting/conclusion.py", "estimate(s, x, correct=steps.moved)", "estimate(s, x)",
           ("tests/test_fit_cli.py",)),
    Mutant("rounding-decrease-accepted", "spacefit/fitting/stopping.py", "loss < below)", "loss < self.best)",
           ("tests/test_stopping.py",)),
    Mutant("no-progress-check-removed", "spacefit/fitting/status.py", "    if not moved:\n        return Status.NO_PROGRESS\n", "",
           ("tests/test_goodness.py",)),
    Mutant("dof-miscounted", "spacefit/fitting/goodness.py", "dof = max(values - n_free, 1)", "dof = max(values, 1)",
           ("tests/test_goodness.py",)),
    # the verdict render (issue 21): judged at more samples than the fit's, the references' own render noise counted
    Mutant("verdict-on-the-fits-samples", "spacefit/fitting/judging.py", "k = verdict_factor(2.0 * goodness(r, noise, 0, True).render_noise, max(spps))",
           "k = 1", ("tests/test_goodness.py",)),
    Mutant("zero-residuals-left-out", "spacefit/fitting/goodness.py", "counted |= np.ravel(np.asarray(fitted, dtype=bool))",
           "counted = counted", ("tests/test_goodness.py",)),
    Mutant("model-dips-below-the-bias", "spacefit/formation.py", "jnp.maximum(electrons(radiance), 0.0)", "electrons(radiance)",
           ("tests/test_goodness.py",)),
    Mutant("reference-render-noise-ignored", "spacefit/fitting/judging.py", "return spp / reference_spp if reference_spp else 0.0", "return 0.0",
           ("tests/test_goodness.py",)),
    # a resumed fit goes on with its stop rule's record (the checkpoint's history)
    Mutant("resume-forgets-the-history", "spacefit/pipeline.py", "checkpoint.history if resume else ())", "())",
           ("tests/test_resume.py",)),
    # locks: a dead holder's lock must be broken, a live one's never
    Mutant("dead-lock-holder-runs", "spacefit/locks.py", "except psutil.NoSuchProcess:\n            return False",
           "except psutil.NoSuchProcess:\n            return True", ("tests/test_locks.py",)),
    Mutant("reused-pid-holds-the-lock", "spacefit/locks.py", "\n                    and abs(process.create_time() - self.started) < START_TOLERANCE_S)",
           ")", ("tests/test_locks.py",)),
    # interruptions as promised (issue 20): Ctrl-C during a render, worker deaths, a resumed fit that had ended
    Mutant("render-in-the-main-thread", "spacefit/interrupts.py",
           "    if threading.current_thread() is not threading.main_thread():\n        return work(stop)\n    box",
           "    if True:\n        return work(stop)\n    box", ("tests/test_interrupts.py::test_a_signal_stops_the_waiting_caller_and_tells_the_work_to_end",)),
    Mutant("worker-deaths-not-retried", "spacefit/studies/cluster.py", "if lost >= retries:", "if lost >= 0:",
           ("tests/test_interrupts.py::test_a_point_whose_worker_dies_is_retried_then_named",)),
    Mutant("ended-fit-solved-again", "spacefit/fitting/loop.py", "    if resume.ended is not None:\n", "    if False:\n",
           ("tests/test_interrupts.py::test_a_fit_killed_after_its_solve_resumes_to_the_same_report",)),
    # every error in the user's terms (issue 20): the camera's derived quantities, the far clip, the fit's seeds
    Mutant("field-of-view-unchecked", "spacefit/scene/optics.py", "        if fov > MAX_FOV_DEG:", "        if fov > 180.0:",
           ("tests/test_reliability.py",)),
    Mutant("mitsuba-default-far-clip", MITSUBA_SCENE, '        "far_clip": FAR_CLIP_M,\n', "", ("tests/test_reliability.py",)),
    Mutant("negative-fit-seed-passes", "spacefit/rendering/derivatives.py",
           "check_count(name, value, 0, MAX_SEED,", "check_count(name, value, -(2**40), MAX_SEED,", ("tests/test_reliability.py",)),
    # BRDF tables and light curves as observations (issue 22)
    Mutant("smith-g1-without-alpha", "spacefit/materials/conductor.py", "xy = (alpha_x * v[..., 0]) ** 2 + (alpha_y * v[..., 1]) ** 2",
           "xy = v[..., 0] ** 2 + v[..., 1] ** 2", ("tests/test_brdf_tables.py",)),
    # Oren-Nayar (issue 31): the JAX BRDF and spacefit's own Mitsuba plugin
    Mutant("oren-nayar-b-without-its-cosine", "spacefit/materials/oren_nayar.py",
           "return kd / jnp.pi * (a + b * azimuthal / jnp.maximum(wi[..., 2], wo[..., 2]))", "return kd / jnp.pi * (a + b * azimuthal)",
           ("tests/test_oren_nayar.py",)),
    Mutant("oren-nayar-plugin-a-of-sigma", MITSUBA_MATERIALS, "a = 1.0 - 0.5 * s2 / (s2 + 0.33)", "a = 1.0 - 0.5 * s2 / (s2 + 0.09)",
           ("tests/test_oren_nayar.py", "tests/test_brdf_tables.py")),
    Mutant("shadow-on-the-sun-side", "spacefit/studies/orbit.py", "return (along < 0) & (across < EARTH_RADIUS_M)",
           "return across < EARTH_RADIUS_M", ("tests/test_observed_lightcurves.py", "tests/test_lightcurve_files.py")),
    Mutant("table-fit-writes-into-a-foreign-folder", "spacefit/fitting/report.py",
           'prepare_output(check_path("out_dir", out_dir), "table-fit", overwrite=check_flag("overwrite", overwrite))',
           'check_path("out_dir", out_dir)', ("tests/test_brdf_tables.py",)),
    # one observation model (issue 31): a table without stated errors scales its errors by its own residuals
    Mutant("value-observation-errors-not-scaled", COVARIANCE,
           "d[rows] = math.sqrt(float(r[rows] @ r[rows]) / max(rows.stop - rows.start - len(block.known), 1))", "d[rows] = 1.0",
           ("tests/test_joint_fit.py",)),
    Mutant("light-curve-sun-directions-not-normalised", "spacefit/studies/lightcurve_observations.py", "fields[name] = unit",
           "fields[name] = v", ("tests/test_observed_lightcurves.py",)),
    Mutant("tabulated-offset-unsigned", "spacefit/materials/tabulated.py", "return jnp.where(jnp.sum(delta * beta0, axis=-1) < 0, -d, d)",
           "return d", ("tests/test_brdf_tables.py",)),
    Mutant("tabulated-incidences-reversed", "spacefit/materials/tabulated.py", "jnp.interp(theta, grid, jnp.eye(len(grid))[k])",
           "jnp.interp(theta, grid, jnp.eye(len(grid))[-1 - k])", ("tests/test_observed_lightcurves.py",)),
    # the traced mask (issue 23): conservative rasterisation, and the second dilation the tent's weights need
    Mutant("silhouette-tests-pixel-centres-only", "spacefit/rendering/silhouette.py",
           "slack = 0.5 * (np.abs(nx) + np.abs(ny)) + EPS_PX", "slack = EPS_PX", ("tests/test_silhouette.py",)),
    # the large triangles' squares in batches: each square's offset within its own triangle's box
    Mutant("mask-batch-offsets-from-the-first-batch", "spacefit/rendering/silhouette.py",
           "np.repeat(ends[first:last] - squares[first:last] - (ends[first] - squares[first]), squares[first:last])",
           "np.repeat(ends[first:last] - squares[first:last], squares[first:last])",
           ("tests/test_silhouette.py::test_large_triangles_mark_the_squares_they_touch_in_batches_as_one_by_one",)),
    Mutant("mask-dilated-once", "spacefit/rendering/silhouette.py", "return dilate(lit, reach), lit", "return lit, lit",
           ("tests/test_silhouette.py",)),
    # the main job's shortcuts (issue 23): the preview encodes only the lit values, the small boxes are clipped to the film
    Mutant("preview-drops-the-dimmest-lit-values", "spacefit/output.py", "lit = rows > 0", "lit = rows > 1e-3",
           ("tests/test_render.py::test_the_preview_encodes_every_pixel_as_the_whole_image_formula_does",)),
    Mutant("mask-boxes-unclipped-right", "spacefit/rendering/silhouette.py", "np.minimum(x1, w - 1) + 1", "x1 + 1",
           ("tests/test_silhouette.py::test_small_triangles_mark_their_boxes_clipped_to_the_film",)),
    Mutant("multijitter-rounds-silently", "spacefit/scene/sampling.py", "    if sampler == \"multijitter\":\n        return spp % root == 0\n",
           "", ("tests/test_sampler.py",)),
    # the documentation site: the front page shows the render; a page's link to another resolves
    Mutant("docs-front-picture-a-thumbnail", "docs/index.md", ":width: 320px", ":width: 32px", ("tests/test_docs.py",)),
    Mutant("docs-link-to-a-missing-page", "docs/getting-started.md", "([](how-to/render.md))", "([](how-to/rendering.md))",
           ("tests/test_docs.py",)),
    # issue 34's survivors, each now caught by a test of its own (their files moved since: the verdict's
    # plumbing is judging.py, the value observations' s^2 uncertainty.py, the light curve's sigma lightcurve_fit.py)
    Mutant("image-scale-divides", "spacefit/fitting/nuisance.py", 'image = values["image.scale"] * image',
           'image = image / values["image.scale"]', ("tests/test_nuisance.py::test_the_image_scale_multiplies_the_render",)),
    Mutant("neighbour-correlation-over-rows", "spacefit/fitting/goodness.py", ".reshape(shape).mean(axis=-1)", ".reshape(shape).mean(axis=0)",
           ("tests/test_goodness.py::test_the_neighbour_correlation_is_taken_over_each_pixels_channel_mean",)),
    Mutant("misfit-at-three-sigma", "spacefit/fitting/goodness.py", "MISFIT_SIGMAS = 5.0", "MISFIT_SIGMAS = 3.0",
           ("tests/test_goodness.py::test_the_misfit_margin_is_five_standard_deviations",)),
    # a solver that descends the loss it is judged by, or stops at once and says why (issue 34, item 3) ...
    Mutant("no-stop-before-the-solve-moved", "spacefit/fitting/stopping.py",
           "        last = [loss for loss in self.rejected[-REJECTED_PATIENCE:] if math.isfinite(loss)]\n",
           "        if not self.decreases:\n            return False\n"
           "        last = [loss for loss in self.rejected[-REJECTED_PATIENCE:] if math.isfinite(loss)]\n",
           ("tests/test_stopping.py::test_from_the_start_three_rejections_within_the_tolerance_stop_the_solve",)),
    Mutant("best-point-again-accepted-by-its-rounding", "spacefit/fitting/stopping.py",
           "if not (new_point and math.isfinite(loss)", "if not (math.isfinite(loss)",
           ("tests/test_stopping.py::test_from_the_start_three_rejections_within_the_tolerance_stop_the_solve",)),
    Mutant("deviance-below-the-bias-as-above", "spacefit/fitting/losses.py", "f * (1 - f) * _psi(w)", "f * (1 - f) * _phi(w)",
           ("tests/test_noise_model.py::test_the_descended_residual_is_the_quasi_deviance_whose_gradient_is_the_weighted_difference",)),
    # ... and verdicts that say what they can hide (item 4)
    Mutant("detectable-effect-without-dof", "spacefit/fitting/goodness.py", "math.sqrt((limit - expected) * dof / power)",
           "math.sqrt((limit - expected) / power)",
           ("tests/test_goodness.py::test_the_verdict_states_the_smallest_effect_it_could_see_and_one_just_above_it_is_a_misfit",)),
    Mutant("judged-spp-k-not-2k", "spacefit/fitting/judging.py", "judged = 2 * k", "judged = k",
           ("tests/test_goodness.py::test_the_verdict_renders_twice_at_the_factor_a_single_renders_noise_asks",)),
    Mutant("verdict-factor-of-the-means-noise", "spacefit/fitting/judging.py", "verdict_factor(2.0 * goodness(", "verdict_factor(goodness(",
           ("tests/test_goodness.py::test_the_verdict_renders_twice_at_the_factor_a_single_renders_noise_asks",)),
    Mutant("mean-noise-whole-difference", "spacefit/fitting/judging.py", "half = [(a - b) / 2 for", "half = [(a - b) for",
           ("tests/test_goodness.py::test_the_render_noise_of_the_mean_of_two_renders_is_half_their_difference",)),
    Mutant("frame-goodness-own-parameters-only", "spacefit/fitting/judging.py", "Name(name).observation in (None, k))",
           "Name(name).observation == k)",
           ("tests/test_goodness.py::test_each_observations_goodness_counts_the_shared_and_its_own_free_parameters",)),
    Mutant("value-goodness-dof-not-reduced", "spacefit/fitting/judging.py", "len(block.known), block.noise_known", "0, block.noise_known",
           ("tests/test_goodness.py::test_each_observations_goodness_counts_the_shared_and_its_own_free_parameters",)),
    Mutant("value-s2-over-n", COVARIANCE, "max(rows.stop - rows.start - len(block.known), 1)", "max(rows.stop - rows.start, 1)",
           ("tests/test_uncertainty.py::test_a_value_observation_without_errors_has_its_noise_from_s2_over_n_minus_p",)),
    Mutant("pass-wide-sensor-over-frames", "spacefit/fitting/observation_files.py", "{**(self.sensor_values or {}), **own}",
           "{**own, **(self.sensor_values or {})}",
           ("tests/test_file_inputs.py::test_a_frames_own_sensor_values_win_over_the_pass_wide_ones",)),
    Mutant("shared-scene-keyed-without-pose", "spacefit/fitting/frames.py",
           "*(POSE_KEYS.items() if spec.view_pose or set(spec.names) & set(POSE) else ())", "*POSE_KEYS.items()",
           ("tests/test_pass.py::test_frames_share_a_loaded_scene_across_target_poses_only_when_they_set_the_pose",)),
    Mutant("cached-jacobian-keyed-by-x-alone", "spacefit/fitting/frames.py",
           "point = np.asarray([seed, seed_grad], dtype=np.float64).tobytes() + np.asarray(x, dtype=np.float64).tobytes()",
           "point = np.asarray(x, dtype=np.float64).tobytes()",
           ("tests/test_pass.py::test_a_frames_cached_jacobian_is_keyed_by_its_seeds_too",)),
    Mutant("egain-alias-dropped", "spacefit/imageio/fits.py", '("GAIN", "EGAIN")', '("GAIN",)',
           ("tests/test_imageio.py::test_the_egain_alias_is_read_as_the_gain",)),
    Mutant("psf-reach-one-sigma", "spacefit/psf.py", "math.ceil(GAUSSIAN_RADIUS_SIGMA * sensor.psf_sigma_px + airy)",
           "math.ceil(sensor.psf_sigma_px + airy)",
           ("tests/test_sensor.py::test_the_psf_reaches_five_sigma_and_its_widths_add_in_quadrature",)),
    Mutant("psf-rms-widths-added-linearly", "spacefit/psf.py", "widths.append(math.hypot(sensor.psf_sigma_px, airy))",
           "widths.append(sensor.psf_sigma_px + airy)",
           ("tests/test_sensor.py::test_the_psf_reaches_five_sigma_and_its_widths_add_in_quadrature",)),
    Mutant("light-curve-sigma-times-1086", "spacefit/studies/lightcurve_fit.py", "float) / MAGNITUDE_PER_LN", "float) * MAGNITUDE_PER_LN",
           ("tests/test_lightcurve.py::test_a_magnitudes_error_is_ln_es_over_1086",)),
    Mutant("pass-seeds-seed-plus-i", "spacefit/rendering/sample_passes.py", "return (seed + i * 0x9E3779B1) % (1 << 32)", "return (seed + i) % (1 << 32)",
           ("tests/test_render.py::test_a_renders_pass_seeds_are_not_another_seeds",)),
    # a program's arrays are its operands (spacefit.programs): embedded as constants, the fit's test hears JAX's warning
    Mutant("program-arrays-embedded", "spacefit/programs.py", "return jaxpr_as_fun(ClosedJaxpr(jaxpr, arrays))(",
           "return jaxpr_as_fun(traced)(", ("tests/test_programs.py::test_a_fit_s_programs_embed_no_array_as_a_constant",)),
)


def copy_checkout(dest: Path) -> None:
    """Tracked and untracked files that git does not ignore: the tree the tests see, without .venv or outputs."""
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        if (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)


def run_tests(tree: Path, tests: tuple[str, ...], timeout_s: float = TIMEOUT_S) -> tuple[int | None, str]:
    """pytest's exit code (None on timeout after ``timeout_s``) and the first failing test, run in the copy."""
    env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONDONTWRITEBYTECODE": "1"}
    # -m "": the tests a mutant names run whatever their marks (pyproject's addopts leaves the slow ones out)
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-m", "", *tests]
    try:
        out = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return None, f"timeout after {timeout_s:.0f} s"
    failed = [line.split(" ", 1)[1].split(" - ")[0] for line in out.stdout.splitlines() if line.startswith(("FAILED ", "ERROR "))]
    return out.returncode, failed[0] if failed else out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="run only these mutants (default: all)")
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--no-baseline", action="store_true", help="skip the check that the targeted tests pass unmutated")
    args = parser.parse_args()
    known = {m.name for m in MUTANTS}
    if unknown := [n for n in args.names if n not in known]:
        parser.error(f"unknown mutants {unknown}; --list shows them")
    mutants = [m for m in MUTANTS if not args.names or m.name in args.names]
    if args.list:
        for m in mutants:
            print(f"{m.name:38s} {m.path:30s} {' '.join(m.tests)}")
        return 0

    with tempfile.TemporaryDirectory(prefix="spacefit-mutants-") as tmp:
        tree = Path(tmp)
        copy_checkout(tree)
        if not args.no_baseline:
            targets = tuple(dict.fromkeys(t for m in mutants for t in m.tests))
            # every mutant's tests at once: the budget of one mutant per ten of them
            code, first = run_tests(tree, targets, TIMEOUT_S * max(1, len(mutants) / 10))
            if code != 0:
                print(f"the targeted tests fail without any mutant ({first}); fix them first", file=sys.stderr)
                return 2
        rows = []
        for m in mutants:
            path = tree / m.path
            source = path.read_text()
            if source.count(m.original) != 1:
                rows.append((m, "stale", 0.0, f"snippet found {source.count(m.original)} times in {m.path}"))
                continue
            t0 = time.perf_counter()
            try:
                path.write_text(source.replace(m.original, m.replacement))
                code, first = run_tests(tree, m.tests)
            finally:
                path.write_text(source)
            # pytest exits 1 when a test fails and 2 when a module no longer imports (both kill the
            # mutant); 3-5 are pytest's own errors or no tests collected: the mutant's entry is wrong
            status = "killed" if code in (1, 2, None) else "SURVIVED" if code == 0 else f"error {code}"
            rows.append((m, status, time.perf_counter() - t0, first))
            print(f"{m.name:38s} {status:8s} {rows[-1][2]:6.1f} s  {first}", flush=True)

    killed = sum(r[1] == "killed" for r in rows)
    print(f"\nscore: {killed} / {len(rows)} mutants killed")
    for m, status, _, detail in rows:
        if status != "killed":
            print(f"  {status}: {m.name} ({m.path}): {detail}")
    return 0 if killed == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
