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


@pytest.fixture(autouse=True)
def in_a_scratch_folder(tmp_path, monkeypatch) -> None:
    """Every case runs in a folder of its own: a path drawn from JUNK ("auto", "1", "plate") is a name relative to it,
    so that an output written there (``sf.write_table_fit("auto", fit)`` rightly makes that folder) is not left in the
    checkout, as one was in a ``make slow`` run."""
    monkeypatch.chdir(tmp_path)


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
        # a valid count past 3 is that many Jacobians, rightly rendered: 215433 of them (drawn) ran for hours
        seeds = data.draw(st.one_of(JUNK, st.integers(-2, 3)).filter(lambda s: not (isinstance(s, int) and 3 < s <= 2**30)))
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
    # a fit that ran ends 0 or with its verdict (3 to 6, 9); a mask or sensor file not found is a file error (1)
    assert_clean(code, err, (0, 1, 2, 3, 4, 5, 6, 9))



# Cells of a measured table: numbers in and out of range, non-numbers, non-finite and empty ones.
CELLS = st.one_of(st.sampled_from(["0", "10", "45", "89.9", "90", "95", "-10", "-95", "180", "400", "0.1", "1e-3", "-0.5", "0",
                                   "nan", "inf", "-inf", "abc", "", "1e999", "1,5", '"3"', "2020-01-01T00:00:00"]),
                  st.floats(-200, 200).map(repr), st.text(max_size=4))
BRDF_HEADERS = ["theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr", "theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr,sigma_sr",
                "theta_i_deg,phi_i_deg,brdf_sr", "a,b,c,d,e", "", None]  # None: the Starlink format's unnamed columns
TIMES = st.sampled_from(["2020-03-01T04:00:00", "2020-03-01 04:10:00", "2020-03-01", "yesterday", "", "5", "nan", "2020-13-45T99:00:00",
                         "1000000-01-01T00:00:00", "J2000", "2020-03-01T04:00:00Z", "1850-01-01T00:00:00"])
LIGHT_CURVE_HEADERS = ["time_utc,magnitude,sun_x,sun_y,sun_z,observer_x,observer_y,observer_z,range_m",
                       "time_utc,magnitude,magnitude_sigma,altitude_deg,azimuth_deg,height_m",
                       "observation_time,satellite_height,satellite_altitude,satellite_azimuth,ab_magnitude",
                       "time_utc,magnitude", "magnitude,range_m", ""]
GARBAGE = st.one_of(st.binary(max_size=40), st.sampled_from([b"", b"\n\n", b"# only a comment\n", b"\xff\xfe\x00x", b"\x00" * 8]))


# Plausible cells of each column (the general formats' names; the Starlink BRDF format's by position).
PLAUSIBLE = {"brdf": ["0.1", "0.5", "2"], "sigma": ["0.01", "0.1"], "time": ["2020-03-01T04:00:00", "2020-03-01T04:10:00"],
             "magnitude": ["5", "6.5"], "sun": ["0.2", "1", "-0.5"], "observer": ["0.3", "1", "-0.5"], "range": ["5e5", "1e6"],
             "altitude": ["30", "60", "-10"], "azimuth": ["0", "120"], "height": ["550", "5.5e5"], "deg": ["0", "10", "45", "80"]}


def column_cells(column: str) -> st.SearchStrategy:
    """Cells of a column: plausible nine times in ten (by the first key of :data:`PLAUSIBLE` its name holds), else random."""
    plausible = next((v for k, v in PLAUSIBLE.items() if k in column), PLAUSIBLE["deg"])
    return st.one_of(*[st.sampled_from(plausible)] * 9, st.one_of(CELLS, TIMES))


def table_text(data: st.DataObject, header: str | None, columns: list[str]) -> bytes:
    """A text table: ``header`` (None: none) and up to 4 rows of cells of ``columns`` (sometimes one too few or too
    many), separated as CSV or by spaces."""
    width = data.draw(st.sampled_from([len(columns)] * 8 + [len(columns) - 1, len(columns) + 1]))
    cells = st.tuples(*[column_cells((columns + ["deg"])[min(i, len(columns))]) for i in range(width)]).map(list)
    rows = data.draw(st.lists(cells, min_size=1, max_size=4))
    sep = "," if header is not None else data.draw(st.sampled_from([" ", ",", "\t"]))
    lines = ([header] if header is not None else []) + [sep.join(r) for r in rows]
    return ("\n".join(lines) + "\n").encode()


def table_path(plate: dict[str, Any], data: st.DataObject, make: Callable[[], bytes]) -> Any:
    """A file of ``make()``'s bytes or of garbage, or a value that is not a path."""
    kind = data.draw(st.sampled_from(["table"] * 6 + ["garbage", "junk"]))
    if kind == "junk":
        return data.draw(st.one_of(st.none(), st.integers(), st.just(""), st.lists(st.text(max_size=3), max_size=2)))
    path = Path(tempfile.mkdtemp(dir=plate["dir"])) / "table.csv"
    path.write_bytes(make() if kind == "table" else data.draw(GARBAGE))
    return path


@pytest.fixture(scope="module")
def brdf_table(tmp_path_factory) -> dict[str, Any]:
    """A small measured BRDF table with errors, and a fit of a Lambert model to it."""
    from spacefit.fitting.brdf_table import simulate_brdf_table

    table = simulate_brdf_table(sf.Lambert(0.4), [10.0, 40.0], [0.0, 30.0, 60.0], relative_error=0.05)
    return {"table": table, "fit": sf.fit_brdf_table(table, "lambert", max_steps=5)}


def check_read_brdf_table(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.read_brdf_table of garbage files and paths: refused, or rows with unit directions above the
    surface, finite BRDF values above the floor and positive errors."""
    header = data.draw(st.sampled_from(BRDF_HEADERS))
    columns = header.split(",") if header else ["deg", "deg", "deg", "deg", "brdf"]
    path = table_path(plate, data, lambda: table_text(data, header, columns))
    floor = data.draw(st.sampled_from([0.0, 0.0, 0.0, 1e-3, -1.0, None, "0.1", math.nan]))
    table = outcome(lambda: sf.read_brdf_table(path, floor=floor))
    event("read" if table is not None else "refused")
    if table is not None:
        assert len(table) > 0 and np.all(np.isfinite(table.value)) and np.all(table.value > floor)
        for w in (table.wi, table.wo):
            assert w.shape == (len(table), 3)
            np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0)
        assert table.sigma is None or np.all(table.sigma > 0)


def check_fit_brdf_table(plate: dict[str, Any], data: st.DataObject, brdf_table: dict[str, Any]) -> None:
    """sf.fit_brdf_table, sf.compare_brdf_models, sf.fitted_material and sf.write_table_fit with
    some arguments random: refused, or finite values and a material."""
    table, fit = brdf_table["table"], brdf_table["fit"]
    call = data.draw(st.sampled_from(["fit", "compare", "material", "write"]))
    event(call)
    if call == "fit":
        valid = {"table": table, "model": "lambert", "relative_error": None, "start": {"kd": 0.3}, "fixed": None, "max_steps": 2}
        odd = {"model": st.one_of(JUNK, st.sampled_from(["ggx", "lambert+ggx_aniso", "phong"])),
               "start": st.one_of(JUNK, st.dictionaries(st.sampled_from(["kd", "alpha", "k"]), JUNK, max_size=2)),
               "fixed": st.one_of(JUNK, st.dictionaries(st.sampled_from(["kd", "eta", "k"]), JUNK, max_size=2)),
               "relative_error": st.one_of(JUNK, st.sampled_from([0.05, 0.0, -1.0]))}
        bad = data.draw(st.lists(st.sampled_from(sorted(valid)), min_size=1, max_size=3, unique=True))
        args = {k: (data.draw(odd.get(k, JUNK)) if k in bad else v) for k, v in valid.items()}
        result = outcome(lambda: sf.fit_brdf_table(**args))
        assert result is None or np.all(np.isfinite(list(result.values.values())))
    elif call == "compare":
        models = data.draw(st.one_of(JUNK, st.lists(st.sampled_from(["lambert", "ggx", "phong"]), max_size=2)))
        fixed = data.draw(st.one_of(st.none(), JUNK))
        relative_error = data.draw(st.one_of(st.none(), JUNK))
        result = outcome(lambda: sf.compare_brdf_models(table, models, relative_error=relative_error, fixed=fixed))
        assert result is None or set(result.fits) <= set(sf.BRDF_MODELS)
    elif call == "material":
        model = data.draw(st.one_of(JUNK, st.sampled_from(sorted(sf.BRDF_MODELS))))
        result = outcome(lambda: sf.fitted_material(model, data.draw(st.one_of(st.just(fit), JUNK))))
        assert result is None or isinstance(result, sf.Lambert)
    else:
        folder = Path(tempfile.mkdtemp(dir=plate["dir"]))
        if data.draw(st.booleans()):
            (folder / "notes.txt").write_text("mine")
        before = sorted(p.name for p in folder.iterdir())
        out = data.draw(st.one_of(st.just(folder), st.just(folder / "new"), JUNK))
        inputs = data.draw(st.one_of(st.none(), st.just({"table": "t.csv"}), JUNK))
        result = outcome(lambda: sf.write_table_fit(out, data.draw(st.one_of(st.just(fit), JUNK)), inputs=inputs))
        if result is None:
            assert sorted(p.name for p in folder.iterdir()) == before
        else:
            assert sorted(p.name for p in Path(result).iterdir()) == ["fit.json", "report.txt"]


def check_read_light_curve(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.read_light_curve of garbage files, sites and bands: refused, or finite magnitudes and unit directions."""
    header = data.draw(st.sampled_from(LIGHT_CURVE_HEADERS))
    path = table_path(plate, data, lambda: table_text(data, header, header.split(",")))
    site = data.draw(st.sampled_from([sf.Site(32.4, -110.8, 2791.0)] * 4 + [None, "Tucson", (32.4, -110.8)]))
    band = data.draw(st.sampled_from(["V"] * 4 + ["AB532", None, "Q", 5]))
    obs = outcome(lambda: sf.read_light_curve(path, site=site, band=band))
    event("read" if obs is not None else "refused")
    if obs is not None:
        n = len(obs)
        assert n > 0 and np.all(np.isfinite(obs.magnitude)) and np.all(obs.range_m > 0)
        for w in (obs.sun, obs.observer):
            assert w.shape == (n, 3)
            np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0)


def two_plates() -> list[Any]:
    return [sf.Plate("body", 2.0, (0.0, 0.0, -1.0), sf.Lambert(0.3)), sf.Plate("array", 4.0, (0.0, 1.0, 0.0), sf.Conductor(1.5, 0.0, 0.2, 0.2))]


def check_plates(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.Site, sf.Plate, sf.predict_magnitudes, sf.fit_plates and sf.fitted_plates with random arguments."""
    from spacefit.studies.lightcurve_observations import LightCurveObservations

    n = 6
    angle = np.linspace(0.2, 1.2, n)
    sun = np.stack([np.zeros(n), np.sin(angle), np.cos(angle)], axis=1)
    obs = LightCurveObservations(np.full(n, 5.0), np.full(n, 0.1), "V", sun, np.tile([0.0, 0.6, 0.8], (n, 1)), np.full(n, 1e6),
                                 np.zeros(n, bool), None, "fuzz")
    call = data.draw(st.sampled_from(["site", "plate", "predict", "fit", "fitted"]))
    if call == "site":
        args = data.draw(st.tuples(st.one_of(st.floats(-200, 200), JUNK), st.one_of(st.floats(-400, 400), JUNK),
                                   st.one_of(st.floats(-1e3, 2e4), JUNK)))
        site = outcome(lambda: sf.Site(*args))
        assert site is None or (abs(site.latitude_deg) <= 90 and abs(site.longitude_deg) <= 360)
    elif call == "plate":
        args = [data.draw(st.one_of(st.just(v), JUNK)) for v in ("p", 1.0, (0.0, 0.0, 1.0), sf.Lambert(0.5), (1.0, 0.0, 0.0))]
        made = outcome(lambda: sf.Plate(*args))
        if made is not None:
            e = outcome(lambda: sf.predict_magnitudes([made], obs))
            assert e is None or not np.any(np.isnan(e))
    else:
        plates = data.draw(st.one_of(st.just(two_plates()), JUNK, st.lists(st.one_of(st.just(two_plates()[0]), JUNK), max_size=2)))
        observations = data.draw(st.one_of(st.just(obs), JUNK))
        if call == "predict":
            magnitudes = outcome(lambda: sf.predict_magnitudes(plates, observations, data.draw(st.one_of(st.just(1360.0), JUNK))))
            assert magnitudes is None or not np.any(np.isnan(magnitudes))
        else:
            names = ["parts.body.kd", "parts.array.alpha", "parts.array.kd", "parts.x.kd", "target.attitude_z_deg"]
            free = data.draw(st.one_of(st.just(["parts.body.kd"]), st.lists(st.sampled_from(names), max_size=2), JUNK))
            bounds = data.draw(st.one_of(st.none(), st.just({"parts.body.kd": (0.1, 0.5)}), JUNK))
            fit = outcome(lambda: sf.fit_plates(plates, observations, free, bounds=bounds, max_steps=data.draw(st.one_of(st.just(2), JUNK))))
            if call == "fitted" and fit is not None:
                fitted = outcome(lambda: sf.fitted_plates(data.draw(st.one_of(st.just(plates), JUNK)), fit))
                assert fitted is None or len(fitted) == len(plates)


def check_fit_light_curve(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.fit_light_curve and sf.light_curve_convergence with some arguments random (at least one)."""
    scene = plate["scene"]
    if data.draw(st.booleans()):
        valid = {"scene": scene, "tolerance": 0.01, "phase_deg": [10.0, 40.0]}
        bad = data.draw(st.lists(st.sampled_from(sorted(valid)), min_size=1, max_size=2, unique=True))
        args = {k: (data.draw(JUNK) if k in bad else v) for k, v in valid.items()}
        result = outcome(lambda: sf.light_curve_convergence(args.pop("scene"), quiet=True, **args))
        assert result is None or np.all(np.isfinite(result.irradiance_w_m2))
        return
    valid = {"scene": scene, "free": ["parts.plate.kd"], "points": [{"target.attitude_z_deg": a} for a in (0.0, 20.0, 40.0)],
             "magnitude": [5.0, 5.1, 5.2], "magnitude_sigma": 0.1, "band": "V", "sun_magnitude": None, "observer_range_m": None,
             "seed": 1, "max_steps": 1}
    odd = {"points": st.one_of(JUNK, st.lists(st.dictionaries(st.sampled_from(["target.attitude_z_deg", "nope"]), JUNK,
                                                               max_size=2), max_size=3)),
           "magnitude": st.one_of(JUNK, st.lists(st.floats(), min_size=3, max_size=3)),
           "magnitude_sigma": st.one_of(JUNK, st.lists(st.floats(-1, 1), max_size=4))}
    bad = data.draw(st.lists(st.sampled_from(sorted(valid)), min_size=1, max_size=3, unique=True))
    args = {k: (data.draw(odd.get(k, JUNK)) if k in bad else v) for k, v in valid.items()}
    result = outcome(lambda: sf.fit_light_curve(**args))
    assert result is None or np.all(np.isfinite(list(result.values.values())))


def check_new_constructors(plate: dict[str, Any], data: st.DataObject) -> None:
    """sf.DiffuseConductor, sf.BRDFTable and sf.LightCurveObservations built from random values: refused or usable."""
    cls = data.draw(st.sampled_from([sf.DiffuseConductor, sf.BRDFTable, sf.LightCurveObservations]))
    goods = {sf.DiffuseConductor: (0.2, 1.5, 1.0, 0.1, 0.2, "ggx"),
            sf.BRDFTable: (np.array([[0.0, 0.0, 1.0]] * 3), np.array([[0.6, 0.0, 0.8]] * 3), np.ones(3), None, "x"),
            sf.LightCurveObservations: (np.ones(2), None, "V", np.array([[0.0, 0.0, 1.0]] * 2), np.array([[0.0, 0.6, 0.8]] * 2),
                                        np.ones(2), np.zeros(2, bool), None, "x")}
    good = goods[cls]
    bad = data.draw(st.lists(st.integers(0, len(good) - 1), min_size=1, max_size=2, unique=True))
    args = [data.draw(st.one_of(ARRAYS, JUNK)) if i in bad else v for i, v in enumerate(good)]
    made = outcome(lambda: cls(*args))
    if made is not None and cls is sf.DiffuseConductor:
        result = outcome(lambda: sf.predict_magnitudes([sf.Plate("p", 1.0, (0.0, 0.0, 1.0), made)], sf.LightCurveObservations(*goods[sf.LightCurveObservations])))
        assert result is None or not np.any(np.isnan(result))
    elif made is not None and cls is sf.BRDFTable:
        fit = outcome(lambda: sf.fit_brdf_table(made, "lambert", relative_error=0.1, max_steps=2))
        assert fit is None or np.all(np.isfinite(list(fit.values.values())))
    elif made is not None:
        result = outcome(lambda: sf.predict_magnitudes(two_plates(), made))
        assert result is None or not np.any(np.isnan(result))


CHECKS = [check_scene_values, check_camera, check_constructors, check_fit, check_observation, check_sensor, check_studies,
          check_command_line_render, check_command_line_fit, check_read_brdf_table, check_read_light_curve, check_plates,
          check_fit_light_curve, check_new_constructors]


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
@FAST
@given(data=st.data())
def test_fuzz(plate, check, data):
    check(plate, data)


# 12 examples in the suite (each of the four calls drawn; the fits' and comparisons' compiles are most of
# its time, about 2 s an example on 2 cores), many more with -m slow.
@settings(FAST, max_examples=12)
@given(data=st.data())
def test_fuzz_brdf_table_fits(plate, brdf_table, data):
    check_fit_brdf_table(plate, data, brdf_table)


@pytest.mark.slow
@settings(SLOW, max_examples=120)
@given(data=st.data())
def test_fuzz_brdf_table_fits_long(plate, brdf_table, data):
    check_fit_brdf_table(plate, data, brdf_table)


@pytest.mark.slow
@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
@SLOW
@given(data=st.data())
def test_fuzz_long(plate, check, data):
    check(plate, data)
