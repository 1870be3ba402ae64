"""Fuzz tests (hypothesis): the public API and the command line given random values.

Wrong types, NaN and infinities, negatives, huge numbers, strings, None, nested lists and random
keys, alone or next to valid values. The only outcomes allowed are ``sf.InputError`` (for the
command line exit 2 and one line, no traceback) or a correct result: a scene that passes the
checks renders (at 8 x 8 px, 1 spp: finite, non-negative radiance). The fast tests draw 40
examples each from a fixed seed; ``-m slow`` draws ten times as many, new ones each run.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import small_scene, write_plate_obj
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import spacefit as sf
from spacefit.cli import main
from spacefit.scene.parameters import scene_value

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning", "ignore::RuntimeWarning")

FAST = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large])
SLOW = settings(FAST, max_examples=400, derandomize=False)

# Values of every wrong kind, and numbers at the edges.
EDGES = [0, -1, 1e-300, 5e-324, 1e300, -1e300, math.nan, math.inf, -math.inf, 2**31, 2**32, 2**63, -(2**63), 2**64, 10**30,
         "1", "nan", "true", "", "physical", "auto", "plate"]
SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(), st.text(max_size=6), st.sampled_from(EDGES))
JUNK = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4), st.tuples(inner, inner, inner),
                                                     st.dictionaries(st.text(max_size=6), inner, max_size=2)), max_leaves=6)
FACTORS = st.one_of(st.sampled_from([0.0, -1.0, 1e-300, 1e-9, 1e-3, 0.5, 1.0, 2.0, 1e3, 1e9, 1e300]), st.floats(-1e6, 1e6),
                    st.floats(0.25, 4.0), st.floats(0.9, 1.1))
# Positive numbers over 40 decades, for the camera's derived quantities.
LOG_UNIFORM = st.floats(-20, 20).map(lambda e: 10.0**e)


def near(default: Any) -> st.SearchStrategy:
    """Values of the kind of ``default``, from plausible to absurd."""
    if isinstance(default, bool):
        return st.booleans()
    if isinstance(default, int):
        return st.one_of(st.integers(-3, 70), st.integers(0, 2**33), st.just(default))
    if isinstance(default, float):
        return st.builds(lambda f: default * f if default else f, FACTORS)
    if isinstance(default, str):
        return st.one_of(st.just(default), st.text(max_size=10), st.sampled_from(["auto", "tent", "multijitter", "prb", "geometry"]))
    if isinstance(default, (list, tuple)):
        items = [near(d) for d in default] if default else [st.floats(-10, 10)] * 3
        return st.one_of(st.tuples(*items).map(list), st.lists(items[0], max_size=5))
    return JUNK


@pytest.fixture(scope="module")
def plate(tmp_path_factory) -> dict[str, Any]:
    """An 8 x 8 px plate filling the view: its scene, scene file and a reference image of it."""
    d = tmp_path_factory.mktemp("fuzz")
    scene = small_scene(write_plate_obj(d / "plate.obj"), {"material": "white_paint", "kd": 0.5},
                        render={"resolution": [8, 8], "spp": 1})
    (d / "scene.toml").write_text(scene.to_toml())
    sf.write_exr(d / "ref.exr", sf.render(scene))
    keys = {}
    for section, table in scene.to_dict().items():
        for key, value in table.items():
            for sub, v in (value.items() if section == "parts" else [(None, value)]):
                keys[f"{section}.{key}" + (f".{sub}" if sub else "")] = v
    keys.update({name: scene_value(scene, name) for name in sf.available_parameters(scene)})
    return {"scene": scene, "toml": d / "scene.toml", "ref": d / "ref.exr", "keys": keys, "dir": d}


def outcome(call: Callable[[], Any]) -> Any:
    """The call's result, or None if it raised :class:`sf.InputError` (with a message); any other exception fails."""
    try:
        return call()
    except sf.InputError as err:
        assert str(err).strip() and "Traceback" not in str(err)
        return None


def renders(scene: sf.Scene) -> None:
    """A scene that passed its checks renders at 8 x 8 px, 1 spp: finite, non-negative radiance (or an
    InputError about the view, which only the geometry shows)."""
    w, h = scene.render.resolution
    small = scene.with_values({"render.resolution": [min(w, 8), min(h, 8)], "render.spp": 1})
    image = outcome(lambda: sf.render(small))
    event("rendered" if image is not None else "refused by the view")
    if image is not None:
        assert image.shape == (min(h, 8), min(w, 8), 3) and np.all(np.isfinite(image)) and np.all(image >= 0)


def scene_values(data: st.DataObject, keys: dict[str, Any]) -> dict[Any, Any]:
    """One to three scene values: known keys with plausible or absurd values, or random keys."""
    names = sorted(keys)
    known = st.sampled_from(names).flatmap(lambda k: st.tuples(st.just(k), st.one_of(near(keys[k]), near(keys[k]), JUNK)))
    pairs = st.one_of(known, known, known, st.tuples(st.one_of(st.text(max_size=12), SCALARS), JUNK))
    return dict(data.draw(st.lists(pairs, min_size=1, max_size=3)))


def check_scene_values(plate: dict[str, Any], data: st.DataObject) -> None:
    """Scene.with_values with random keys and values: refused, or the scene renders."""
    values = scene_values(data, plate["keys"])
    scene = outcome(lambda: plate["scene"].with_values(values))
    if scene is not None:
        renders(scene)


def check_camera(plate: dict[str, Any], data: st.DataObject) -> None:
    """The camera's values over many decades: the derived field of view, pixel angle and clipping are checked."""
    values = {"camera.focal_length_mm": data.draw(LOG_UNIFORM), "camera.pixel_pitch_mm": data.draw(LOG_UNIFORM),
              "render.resolution": data.draw(st.tuples(st.integers(1, 16384), st.integers(1, 16384)).map(list)),
              "camera.position_m": [0.0, 0.0, data.draw(st.one_of(LOG_UNIFORM, st.floats(-1e5, 1e5)))],
              "camera.principal_offset_px": data.draw(st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)).map(list))}
    scene = outcome(lambda: plate["scene"].with_values(values))
    if scene is not None:
        w, h = scene.render.resolution
        if w * h <= 64 * 64:
            image = outcome(lambda: sf.render(scene.with_values({"render.spp": 1})))
            event("rendered at its size" if image is not None else "refused by the view")
            assert image is None or (np.all(np.isfinite(image)) and np.all(image >= 0))
        else:
            renders(scene)



SECTIONS = {sf.RenderSettings: "render", sf.CameraSettings: "camera", sf.SunSettings: "sun", sf.TargetSettings: "target",
            sf.WrinkleSettings: "wrinkles"}


def check_constructors(plate: dict[str, Any], data: st.DataObject) -> None:
    """Every public class built with random keyword values: refused or built (a scene section then renders)."""
    keys = plate["keys"]
    cls = data.draw(st.sampled_from([*SECTIONS, sf.FitRender, sf.FitOptions, sf.Sensor, sf.Intrinsics, sf.Adam, sf.Lambert,
                                     sf.Conductor, sf.Mirror, sf.ObservationFiles]))
    fields = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else ["learning_rate"]
    chosen = data.draw(st.lists(st.sampled_from(fields), min_size=1, max_size=3, unique=True))
    kwargs = {}
    for name in chosen:
        default = keys.get(f"{SECTIONS.get(cls, '')}.{name}", JUNK)
        kwargs[name] = data.draw(JUNK if default is JUNK else st.one_of(near(default), JUNK))
    try:
        made = outcome(lambda: cls(**kwargs))
    except TypeError as err:  # a required argument left out: Python's own call error, no value checked
        assert "required positional argument" in str(err), err
        return
    if made is not None and cls in SECTIONS:
        scene = outcome(lambda: plate["scene"].replace(**{SECTIONS[cls]: made}))
        if scene is not None:
            renders(scene)




def fit_arguments(data: st.DataObject, plate: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """Observations and fit keywords, each valid or random; at least one random, so that few fits run."""
    scene = plate["scene"]
    valid = {"observations": sf.Observation(scene.with_values({"parts.plate.kd": 0.3}), sf.read_exr(plate["ref"])),
             "free": ["parts.plate.kd"], "start": {"parts.plate.kd": 0.4}, "render": sf.FitRender(spp=1),
             "max_steps": 1, "solver": "lm", "loss": "pixel", "stop": "noise", "wrinkle_coordinates": "rms"}
    odd = {"free": st.one_of(JUNK, st.lists(st.sampled_from(sorted(plate["keys"])), max_size=2)),
           "start": st.one_of(JUNK, st.dictionaries(st.sampled_from(["parts.plate.kd", "parts.plate.kx"]), JUNK, max_size=2)),
           "observations": st.one_of(JUNK, st.lists(st.just(valid["observations"]), max_size=2))}
    bad = data.draw(st.lists(st.sampled_from(sorted(valid)), min_size=1, max_size=3, unique=True))
    args = {k: (data.draw(odd.get(k, JUNK)) if k in bad else v) for k, v in valid.items()}
    return args.pop("observations"), args


def check_fit(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.fit with some arguments random: refused, or finite fitted values."""
    observations, kwargs = fit_arguments(data, plate)
    free = kwargs.pop("free")
    result = outcome(lambda: sf.fit(observations, free, **kwargs))
    if result is not None:
        assert all(math.isfinite(v) for v in result.values.values())


ARRAYS = st.one_of(
    JUNK,
    st.tuples(st.sampled_from([(8, 8, 3), (8, 8), (8, 8, 1), (8, 8, 2), (3, 5), (8,), (), (0, 8, 3), (8, 8, 4)]),
              st.sampled_from([0.1, 0.0, -1.0, math.nan, math.inf, 1e39]),
              st.sampled_from([np.float32, np.float64, np.int64, bool, complex, object])).map(
        lambda t: np.full(t[0], t[1]).astype(t[2]) if t[2] is not bool else np.ones(t[0], bool)),
)


def check_observation(plate: dict[str, Any], data: st.DataObject) -> None:
    """An Observation's reference, sigma and mask, through the fit's set-up (every check of sf.fit, no render)."""
    from spacefit.fitting.problem import setup

    reference, sigma, mask = data.draw(ARRAYS), data.draw(st.one_of(st.none(), ARRAYS)), data.draw(st.one_of(st.none(), ARRAYS))
    obs = outcome(lambda: sf.Observation(plate["scene"], reference, sigma=sigma, mask=mask))
    if obs is not None:
        s = outcome(lambda: setup(obs, ["parts.plate.kd"]))
        assert s is None or s.problem.references[0].shape[:2] == (8, 8)


def check_sensor(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.Sensor, sf.Intrinsics, sf.observe and sf.expected_dn."""
    radiance, value = data.draw(ARRAYS), data.draw(JUNK)
    field = data.draw(st.sampled_from(["gain_dn_per_electron", "bit_depth", "exposure_time_s", "bias_dn", "psf_sigma_px"]))
    intrinsics = data.draw(st.one_of(st.just((0.05, 5e-5, 8, 8)), st.tuples(JUNK, JUNK, JUNK, JUNK)))
    seed = data.draw(st.one_of(st.integers(0, 10), JUNK))
    sensor = outcome(lambda: sf.Sensor(**{field: value}))
    intr = outcome(lambda: sf.Intrinsics(*intrinsics))
    if sensor is not None and intr is not None:
        dn = outcome(lambda: sf.observe(radiance, sensor, intr, seed))
        if dn is not None:
            assert dn.shape == np.shape(radiance) and np.all(dn >= 0)
        mean = outcome(lambda: sf.expected_dn(radiance, sensor, intr))
        assert mean is None or np.all(np.isfinite(mean))


def check_studies(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.sensitivity, sf.light_curve and sf.sweep with random arguments (at least one, so that few run)."""
    scene = plate["scene"]
    study = data.draw(st.sampled_from(["sensitivity", "light_curve", "sweep", "jacobian", "render_function"]))
    if study == "sensitivity":
        names = data.draw(st.one_of(JUNK, st.just(["parts.plate.kd"])))
        seeds = data.draw(st.one_of(JUNK, st.integers(-2, 3)))
        spp = data.draw(st.one_of(st.none(), JUNK))
        outcome(lambda: sf.sensitivity(scene, names, seeds=seeds, spp=spp, quiet=True))
    elif study == "light_curve":
        which = data.draw(st.sampled_from(["phase_deg", "attitude_deg", "times_s"]))
        kwargs = {which: data.draw(st.one_of(JUNK, st.lists(st.floats(), min_size=1, max_size=2)))}
        for name in data.draw(st.lists(st.sampled_from(["seeds", "observer_range_m", "spin_rate_deg_s", "sun", "observer",
                                                         "band", "axis"]), max_size=2, unique=True)):
            kwargs[name] = data.draw(JUNK)
        outcome(lambda: sf.light_curve(scene, quiet=True, **kwargs))
    elif study == "sweep":
        axes = data.draw(st.one_of(JUNK, st.dictionaries(st.sampled_from(sorted(plate["keys"])), JUNK, min_size=1, max_size=2)))
        store = Path(tempfile.mkdtemp(dir=plate["dir"])) / "store"
        outcome(lambda: sf.sweep(scene, axes, store=store, quiet=True, derivatives=data.draw(st.one_of(st.just(()), JUNK))))
    else:
        free = data.draw(st.one_of(JUNK, st.just(["parts.plate.kd"])))
        seeds = data.draw(st.tuples(st.one_of(st.integers(-1, 3), JUNK), st.one_of(st.integers(-1, 3), JUNK)))
        spp = data.draw(st.one_of(st.none(), JUNK))
        call = sf.jacobian if study == "jacobian" else sf.render_function
        outcome(lambda: call(scene, free, spp=spp, seed=seeds[0], seed_grad=seeds[1]))


TOML_TEXT = st.one_of(
    st.text(max_size=12),
    JUNK.map(repr),
    st.sampled_from(["nan", "inf", "-inf", "1e999", "-1", "0", "true", "'x'", "[1, 2]", "[[1]]", "{a = 1}", "1e-320", "9" * 40]),
    st.floats().map(repr),
)


def command_line(args: list[str]) -> tuple[int, str]:
    """Run the command line in this process: its exit code and standard error (argparse's exit 2 counted)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(args)
        except SystemExit as exit_:  # argparse refusing an argument: usage and one error line
            code = exit_.code
    return code, err.getvalue()


def assert_clean(code: int, err: str, allowed: tuple[int, ...]) -> None:
    assert code in allowed, err
    assert "Traceback" not in err
    if code == 2 and not err.startswith("usage:"):
        assert err.startswith("spacefit: error: ") and err.count("\n") == 1, err


def check_command_line_render(plate: dict[str, Any], data: st.DataObject) -> None:
    """`spacefit render --set KEY=VALUE` with random keys and TOML text: exit 0 with the image, or 2 and nothing written."""
    names = sorted(plate["keys"])
    sets = data.draw(st.lists(st.tuples(st.one_of(st.sampled_from(names), st.text(max_size=10)), TOML_TEXT), min_size=1, max_size=3))
    out = Path(tempfile.mkdtemp(dir=plate["dir"])) / "out"
    args = ["render", str(plate["toml"]), "--out", str(out), "--quiet"]
    for key, value in sets:
        args += ["--set", f"{key}={value}"]
    code, err = command_line([*args, "--set", "render.resolution=[8, 8]", "--set", "render.spp=1"])
    assert_clean(code, err, (0, 2))
    assert (out / "radiance.exr").exists() if code == 0 else not out.exists()


FIT_OPTIONS = ["--spp", "--spp-grad", "--max-steps", "--solver", "--loss", "--stop", "--start", "--sigma", "--resolution", "--free",
               "--set", "--row-order", "--unit", "--response", "--sensor-value", "--mask"]


def check_command_line_fit(plate: dict[str, Any], data: st.DataObject) -> None:
    """`spacefit fit` with random option values: a fit's exit code, a file error (1), or 2 in one line."""
    options = data.draw(st.lists(st.tuples(st.sampled_from(FIT_OPTIONS), TOML_TEXT), min_size=1, max_size=3))
    out = Path(tempfile.mkdtemp(dir=plate["dir"])) / "out"
    args = ["fit", str(plate["ref"]), "--scene", str(plate["toml"]), "--out", str(out), "--quiet", "--max-steps", "1",
            "--free", "parts.plate.kd"]
    for option, value in options:
        args += [option, *([value, value] if option == "--resolution" else [value])]
    code, err = command_line(args)
    # a fit that ran ends 0 or with its verdict (3 to 6); a mask or sensor file not found is a file error (1)
    assert_clean(code, err, (0, 1, 2, 3, 4, 5, 6))


CHECKS = [check_scene_values, check_camera, check_constructors, check_fit, check_observation, check_sensor, check_studies,
          check_command_line_render, check_command_line_fit]


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
@FAST
@given(data=st.data())
def test_fuzz(plate, check, data):
    check(plate, data)


@pytest.mark.slow
@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
@SLOW
@given(data=st.data())
def test_fuzz_long(plate, check, data):
    check(plate, data)
