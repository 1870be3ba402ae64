"""The parameter registry as data: every entry's getter and setter agree with the scene file, the
group tuples come from the entries, values are range-checked by name, the registry and the light
modules (sensor, image files, scene files, renderer) import no JAX,
and the package's module-level imports have no circle."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import spacefit as sf
from spacefit.scene.parameters import ATTITUDE, GEOMETRY, IMAGE, JOINT, MOVES_VERTICES, NUISANCES, PARAMETERS, PER_OBSERVATION, POSITION, ROLL, SUN_ANGLES, check_value, parameter, scene_keys, scene_value, scene_with_values
from spacefit.scene.entries import GROUPS

ROOT = Path(__file__).resolve().parents[1]


def test_the_registry_imports_neither_jax_nor_mitsuba():
    code = ("import sys, spacefit.scene.parameters as p, spacefit.studies.lightcurve\n"
            "s = spacefit.load_case('panels').scene()\n"
            "p.scene_with_values(s, {'sun.elevation_deg': 10.0, 'target.attitude_z_deg': 1.0, 'parts.panels.alpha': 0.2})\n"
            "p.parameter_table()\n"
            "print(sorted(m for m in ('jax', 'jaxtyping', 'mitsuba', 'drjit', 'optimistix') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("module", ["spacefit.sensor", "spacefit.imageio", "spacefit.scene.toml", "spacefit.rendering.renderer",
                                    "spacefit.rendering.drjit_scene"])
def test_the_light_modules_import_no_jax(module):
    """Reading a sensor file or a FITS image, loading a scene and rendering (derivative renders too: DrJitScene) load no
    JAX: only the fitting seam (spacefit.fitting, the image formation included) and the rendering bridge do."""
    code = f"import sys, {module}\nprint(sorted(m for m in sys.modules if m.split('.')[0] in ('jax', 'jaxtyping')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_group_tuples_come_from_the_entries():
    assert all(p.groups <= set(GROUPS) for p in PARAMETERS.values())
    assert GEOMETRY == ("wrinkles.D", "wrinkles.G", "wrinkles.rms_m")
    assert SUN_ANGLES == ("sun.elevation_deg", "sun.azimuth_deg")
    assert ATTITUDE == tuple(f"target.attitude_{a}_deg" for a in "xyz")
    assert POSITION == tuple(f"target.position_{a}_m" for a in "xyz")
    assert ROLL == "camera.roll_deg"
    assert MOVES_VERTICES == (*GEOMETRY, *ATTITUDE, *POSITION, ROLL)
    assert IMAGE == ("image.scale", "image.offset_w_m2_sr", "image.blur_sigma_px", "image.shift_x_px", "image.shift_y_px")
    assert set(NUISANCES) == set(PER_OBSERVATION) == {*IMAGE, *ATTITUDE, *POSITION, ROLL}
    assert JOINT == (SUN_ANGLES, ATTITUDE, POSITION)


def _moved(name: str, before: float) -> float:
    """A valid value of ``name`` away from ``before``."""
    bounds = PARAMETERS[parameter(name).pattern].bounds
    if np.isfinite(bounds.hi):
        return before + 0.3 * (bounds.hi - before)
    return before * 1.3 if bounds.lo >= 0 else before + 0.7


def test_every_getter_reads_what_its_setter_wrote_and_nothing_else_moves():
    """For every parameter of a scene with wrinkles: set a value away from the scene's through the
    setter, read it back through the getter; every other parameter keeps its value (the siblings of
    a joint value too), except those that set the same scene value or, for the wrinkles, depend on it."""
    scene = sf.load_case("panels").scene().with_values({"wrinkles.enabled": True, "sun.direction": [0.3, -0.2, -0.9]})
    names = [n for n in sf.available_parameters(scene) if n not in IMAGE]
    for name in names:
        value = _moved(name, scene_value(scene, name))
        moved = scene_with_values(scene, {name: value})
        assert scene_value(moved, name) == pytest.approx(value, rel=1e-9, abs=1e-12), name
        for other in names:
            joint = any({name, other} <= set(g) for g in JOINT)
            if other == name or (scene_keys(name) & scene_keys(other) and not joint) or {name, other} <= set(GEOMETRY):
                continue
            assert scene_value(moved, other) == pytest.approx(scene_value(scene, other), rel=1e-9, abs=1e-12), (name, other)
    body = scene_with_values(scene, {"parts.body.alpha": 0.2})
    assert body.parts["body"].material.alpha_x == body.parts["body"].material.alpha_y == 0.2


def test_joint_values_keep_their_siblings():
    scene = sf.load_case("panels").scene()
    moved = scene_with_values(scene, {"sun.elevation_deg": 20.0})
    assert scene_value(moved, "sun.elevation_deg") == pytest.approx(20.0)
    assert scene_value(moved, "sun.azimuth_deg") == pytest.approx(scene_value(scene, "sun.azimuth_deg"))
    moved = scene_with_values(scene, {"target.attitude_y_deg": 3.0})
    assert moved.target.attitude_deg == pytest.approx([scene.target.attitude_deg[0], 3.0, scene.target.attitude_deg[2]])


def test_an_observations_own_values_set_its_scene_only():
    scene = sf.load_case("panels").scene()
    values = {"target.attitude_z_deg@0": 1.5, "target.attitude_z_deg@1": -2.0, "camera.roll_deg@1": 0.4, "image.scale@1": 1.1,
              "parts.panels.alpha_x": 0.2}
    first, second = (scene_with_values(scene, values, observation=k) for k in (0, 1))
    assert first.target.attitude_deg[2] == pytest.approx(1.5) and first.camera.roll_deg == scene.camera.roll_deg
    assert second.target.attitude_deg[2] == pytest.approx(-2.0) and second.camera.roll_deg == pytest.approx(0.4)
    assert scene_value(first, "parts.panels.alpha_x") == scene_value(second, "parts.panels.alpha_x") == pytest.approx(0.2)
    with pytest.raises(sf.InputError, match="target.attitude_z_deg@0"):
        scene_with_values(scene, {"target.attitude_z_deg@0": 1.0})  # no observation: a scene has none


@pytest.mark.parametrize("name, value, match", [
    ("parts.panels.kd", 1.5, r"`parts\.panels\.kd` must be in \[0, 1\], got 1\.5"),
    ("sun.elevation_deg", 120.0, r"`sun\.elevation_deg` must be in \[-90, 90\] deg, got 120"),
    ("parts.panels.alpha_x", 0.0, r"\[0\.0001, 1\]"),
    ("sun.irradiance_w_m2", float("nan"), "finite"),
])
def test_check_value_names_the_argument_the_value_and_the_range(name, value, match):
    with pytest.raises(sf.InputError, match=match):
        check_value(name, value)
    assert check_value("parts.panels.kd", 1.0) == 1.0 and check_value("sun.elevation_deg", -90) == -90.0
    with pytest.raises(sf.InputError, match=r"`parts\.legs\.kd`.*got -0\.1"):
        check_value("parts.P.kd", -0.1, "parts.legs.kd")


