"""Articulation and attitude laws (spacefit.geometry.articulation, .attitude, .rotations): a sun-tracking part's normal against
geometry, the body's attitude laws against hand-built frames, the quaternion table's interpolation and
refusals, the scene keys and their errors, and renders of a tracked array lit face-on."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import spacefit as sf
from spacefit.geometry.articulation import AxisAngle, Fixed, SunTracking
from spacefit.geometry.attitude import FixedAttitude, NadirSun, QuaternionTable, SunPointing
from spacefit.geometry.rotations import axis_rotation, quaternion_matrix, tracking_rotation
from spacefit.geometry.frames import attitude_matrix
from spacefit.materials import Lambert
from spacefit.precision import float64
from spacefit.scene.assembly import assemble
from spacefit.scene.toml import scene_from_dict
from spacefit.studies.observing import nadir_sun_frame
from spacefit.studies.plates import Plate, plates_irradiance

SCENES = Path(__file__).resolve().parents[1] / "data" / "scenes"
X, Y, Z = np.eye(3)


def unit(*v: float) -> np.ndarray:
    return np.array(v, float) / np.linalg.norm(v)


@pytest.mark.parametrize("i", range(3))
def test_an_angle_about_an_axis_is_the_attitude_angles_convention(i):
    angles = np.zeros(3)
    angles[i] = 0.7
    assert np.array_equal(axis_rotation(np.eye(3)[i], 0.7), attitude_matrix(angles))


@pytest.mark.parametrize("sun, normal, expected", [
    (X, Y, X),                                   # a quarter turn: the normal onto the sun
    (unit(1, 0, 1), Y, X),                       # the sun's part across the axis only: n . s = 1 / sqrt(2)
    (-Y, Y, -Y),                                 # half a turn
    (unit(-1, 0, 0), unit(0, 1, 1), unit(-1, 0, 1)),  # a normal off the axis's plane keeps its part along the axis
])
def test_a_sun_tracking_normal_faces_the_sun_as_closely_as_one_turn_allows(sun, normal, expected):
    turn = tracking_rotation(Z, normal, sun)
    assert np.allclose(turn @ normal, expected, atol=1e-15)
    assert np.allclose(turn @ turn.T, np.eye(3), atol=1e-15) and math.isclose(np.linalg.det(turn), 1.0)
    assert np.allclose(turn @ Z, Z, atol=1e-15)  # a turn about the axis
    grid = [axis_rotation(Z, a) @ normal @ sun for a in np.linspace(-np.pi, np.pi, 3601)]
    assert (turn @ normal) @ sun >= max(grid) - 1e-12


@pytest.mark.parametrize("sun", [Z, -Z, unit(1e-12, 0, 1)])
def test_with_the_sun_along_the_axis_the_part_keeps_its_placed_attitude(sun):
    assert np.array_equal(tracking_rotation(Z, Y, sun), np.eye(3))


@float64
def test_tracking_is_differentiable_in_the_sun_everywhere():
    """JAX gives the NumPy turn, and finite derivatives with the sun along the axis too."""
    sun = jnp.asarray(np.stack([unit(1, 2, 3), unit(-1, 0.5, 0.2), Z]))
    turn = tracking_rotation(jnp.asarray(Z), jnp.asarray(Y), sun, xp=jnp)
    assert np.allclose(turn, np.stack([tracking_rotation(Z, Y, np.asarray(s)) for s in sun]), rtol=0, atol=1e-15)
    grad = jax.jacfwd(lambda s: tracking_rotation(jnp.asarray(Z), jnp.asarray(Y), s, xp=jnp) @ jnp.asarray(Y))(sun)
    assert np.all(np.isfinite(grad))
    # away from the axis: d n / d s of n = (s_x, s_y, 0) / |(s_x, s_y)| against central differences
    s0, h = np.asarray(unit(1, 2, 3)), 1e-6
    fd = np.stack([(tracking_rotation(Z, Y, s0 + h * e) @ Y - tracking_rotation(Z, Y, s0 - h * e) @ Y) / (2 * h) for e in np.eye(3)], 1)
    assert np.allclose(grad[0][:, 0, :], fd, rtol=1e-8, atol=1e-9)


def test_articulation_laws_turn_parts_in_the_body():
    assert np.array_equal(Fixed().rotation(Y, X), np.eye(3))
    assert np.array_equal(AxisAngle((1, 0, 0), 30.0).rotation(Y, X), attitude_matrix(np.radians([30.0, 0, 0])))
    assert np.allclose(SunTracking((0, 0, 2)).rotation(Y, unit(1, 1, 0)) @ Y, unit(1, 1, 0))
    with pytest.raises(sf.InputError, match=r"`axis` \[0.0, 1.0, 0.0\] must not be parallel to `normal`"):
        SunTracking((0, 1, 0)).rotation(Y, X)


def test_nadir_sun_is_lumos_sats_frame():
    """By hand: nadir -z and the sun at (1, 0, 1) put body y on world x; against the observing frame's
    rows at random geometry."""
    assert np.allclose(NadirSun().rotation(-Z, unit(1, 0, 1)), np.stack([-Y, X, Z], axis=1), atol=1e-15)
    rng = np.random.default_rng(3)
    position, sun = rng.normal(size=(5, 3)) * 7e6, rng.normal(size=(5, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    for p, s, rows in zip(position, sun, nadir_sun_frame(position, sun)):
        assert np.allclose(NadirSun().rotation(-p, s), rows.T, atol=1e-12)


def test_sun_pointing_by_hand():
    """The sun along world y, nadir -z: body +z to y, body +x to nadir, body y = z cross x."""
    rotation = SunPointing().rotation(-Z, Y)
    assert np.allclose(rotation, np.stack([-Z, -X, Y], axis=1), atol=1e-15)
    assert np.array_equal(FixedAttitude((10.0, 20.0, 30.0)).rotation(), attitude_matrix(np.radians([10.0, 20.0, 30.0])))


@pytest.mark.parametrize("law", [NadirSun(), SunPointing()])
def test_two_axis_laws_refuse_the_sun_along_nadir(law):
    with pytest.raises(sf.InputError, match=r"must not be parallel"):
        law.rotation(-Z, Z)
    with pytest.raises(sf.InputError, match=r"`sun_axis` \[0.0, 0.0, -1.0\] must not be parallel to `nadir_axis`"
                       if isinstance(law, NadirSun) else r"`nadir_axis` \[0.0, 0.0, 1.0\] must not be parallel to `sun_axis`"):
        type(law)((0, 0, -1), (0, 0, -1)) if isinstance(law, NadirSun) else type(law)((0, 0, 1), (0, 0, 1))


def write_table(path: Path, rows: list[str], header: str = "time_utc,qw,qx,qy,qz") -> Path:
    path.write_text("\n".join(["# attitude of a test satellite", header, *rows]) + "\n")
    return path


def test_quaternions_are_right_handed_and_map_body_to_world():
    """90 deg about x, right-handed (w = cos 45 deg, x = sin 45 deg), is the attitude angle -90 deg."""
    c = math.cos(math.pi / 4)
    assert np.allclose(quaternion_matrix([c, c, 0, 0]), attitude_matrix(np.radians([-90.0, 0, 0])), atol=1e-15)
    assert np.allclose(quaternion_matrix([c, c, 0, 0]) @ Y, Z, atol=1e-15)


@pytest.mark.parametrize("sign", [1.0, -1.0])  # q and -q are one rotation: slerp takes the shorter arc
def test_a_quaternion_table_is_interpolated_by_slerp(tmp_path, sign):
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    table = QuaternionTable.read(write_table(tmp_path / "q.csv", [
        "2024-03-01T04:00:00Z,1,0,0,0", f"2024-03-01T04:00:10Z,{sign * c},0,0,{sign * s}"]))
    quarter = math.radians(22.5)  # a quarter of the way: 22.5 deg of the 90 deg turn about z
    expected = np.array([[math.cos(quarter), -math.sin(quarter), 0], [math.sin(quarter), math.cos(quarter), 0], [0, 0, 1]])
    assert np.allclose(table.rotation("2024-03-01 04:00:02.5"), expected, atol=1e-12)
    assert np.allclose(table.rotation("2024-03-01T04:00:00"), np.eye(3), atol=1e-15)
    assert np.allclose(table.rotation("2024-03-01T04:00:10"), quaternion_matrix([c, 0, 0, s]), atol=1e-12)
    for outside in ("2024-03-01T03:59:59.9", "2024-03-01T04:00:10.1"):
        with pytest.raises(sf.InputError, match=rf"`time_utc` '{outside}' is outside the quaternion table .*q.csv', which spans "
                                                r"2024-03-01T04:00:00 to 2024-03-01T04:00:10 UTC"):
            table.rotation(outside)


@pytest.mark.parametrize("rows, header, message", [
    (["2024-03-01T04:00:00,1,0,0,0"], "time_utc,qx,qy,qz,qw", r"must have the header time_utc,qw,qx,qy,qz \(scalar first\), got time_utc,qx"),
    (["2024-03-01T04:00:10,1,0,0,0", "2024-03-01T04:00:00,1,0,0,0"], None, r"times must increase, but row 2 is not later than row 1"),
    (["2024-03-01T04:00:00,2,0,0,0"], None, r"row 1's quaternion \[2.0, 0.0, 0.0, 0.0\] has norm 2"),
    (["2024-03-01T04:00:00,1,0,0"], None, r"row 1: 4 values, 5 needed"),
    (["yesterday,1,0,0,0"], None, r"row 1 time_utc` must be an ISO 8601 time \(UTC, 2024-03-01T04:00:00\), got 'yesterday'"),
    (["2024-03-01T04:00:00,1,0,0,x"], None, r"row 1: the quaternion must be 4 numbers"),
    ([], None, r"has no rows"),
])
def test_a_bad_quaternion_table_is_refused_naming_row_and_value(tmp_path, rows, header, message):
    with pytest.raises(sf.InputError, match=message):
        QuaternionTable.read(write_table(tmp_path / "q.csv", rows, header or "time_utc,qw,qx,qy,qz"))


def box_wing(**changes: dict) -> dict:
    """The shipped box-wing scene's table, without wrinkles, direct light only, with changes by section."""
    import tomllib

    data = tomllib.loads((SCENES / "box-wing.toml").read_text())
    data["wrinkles"] = {"enabled": False}
    data["render"] = {"resolution": [48, 48], "spp": 4, "depth": 1}
    for key, value in changes.items():
        if key == "parts":
            for part, table in value.items():
                data["parts"][part] = {**data["parts"][part], **table}
        else:
            data[key] = {**data.get(key, {}), **value}
    if data["target"].get("attitude", "fixed") != "fixed" and "attitude_deg" not in changes.get("target", {}):
        del data["target"]["attitude_deg"]  # the box-wing's angles: a law sets the attitude
    return data


@pytest.mark.parametrize("parts, target, message", [
    ({"wing_left": {"articulation": "tracking"}}, {},
     r"`parts.wing_left.articulation` must be one of 'angle', 'fixed', 'sun_tracking'; got 'tracking'. Did you mean 'sun_tracking'\?"),
    ({"wing_left": {"articulation": "sun_tracking"}}, {}, r"`parts.wing_left.axis` is missing: articulation 'sun_tracking' takes axis"),
    ({"wing_left": {"articulation": "angle", "axis": [0, 1, 0]}}, {}, r"`parts.wing_left.angle_deg` is missing"),
    ({"wing_left": {"articulation": "fixed", "axis": [0, 1, 0]}}, {},
     r"`parts.wing_left.axis` = \[0, 1, 0\] is not a key of articulation 'fixed' \(it takes none\)"),
    ({"wing_left": {"articulation": "sun_tracking", "axis": [0, 1, 0], "angle_deg": 5.0}}, {},
     r"`parts.wing_left.angle_deg` = 5.0 is not a key of articulation 'sun_tracking' \(it takes axis, and pivot_m\)"),
    ({"wing_left": {"axis": [0, 1, 0]}}, {}, r"`parts.wing_left.articulation` is missing: axis belong to an articulation"),
    ({"wing_left": {"articulation": "angle", "axis": [0, 1, 0], "angle_deg": 400.0}}, {},
     r"`parts.wing_left.angle_deg` must be in \[-360, 360\] deg, got 400"),
    ({"wing_left": {"articulation": "sun_tracking", "axis": [0, 0, 0]}}, {}, r"`parts.wing_left.axis` must not be the zero vector"),
    ({"wing_left": {"articulation": "sun_tracking", "axis": [0, 0, 1]}}, {},
     r"`parts.wing_left.axis` \[0.0, 0.0, 1.0\] must not be parallel to the part's normal \(its \+z in the body\) \[0.0, 0.0, 1.0\]"),
    ({}, {"attitude": "nadir"}, r"`target.attitude` must be one of 'fixed', 'nadir_sun', 'sun', 'table'; got 'nadir'. Did you mean 'nadir_sun'\?"),
    ({}, {"attitude": "nadir_sun"}, r"`target.nadir` is missing: `target.attitude` = 'nadir_sun' takes nadir"),
    ({}, {"nadir": [0.0, 0.0, -1.0]}, r"`target.nadir` = \[0.0, 0.0, -1.0\] is not used by `target.attitude` = 'fixed' \(it takes attitude_deg\)"),
    ({}, {"attitude": "table", "quaternions": "q.csv"}, r"`target.time_utc` is missing: `target.attitude` = 'table' takes quaternions and time_utc"),
    ({}, {"attitude": "sun", "nadir": [0, 0, 0]}, r"`target.nadir` must not be the zero vector"),
    ({}, {"attitude": "nadir_sun", "nadir": [-0.3, 0.2, 1.0]},
     r"`target.nadir` \[-0.3, 0.2, 1.0\] is along the sun's direction .* `target.attitude` = 'nadir_sun' is undefined"),
    ({}, {"attitude": "table", "quaternions": "q.csv", "time_utc": "noon"}, r"`target.time_utc` must be an ISO 8601 time"),
    ({}, {"attitude": "nadir_sun", "nadir": [0.0, 0.0, -1.0], "attitude_deg": [0.0, 0.0, 5.0]},
     r"`target.attitude_deg` = \[0.0, 0.0, 5.0\] is not used by `target.attitude` = 'nadir_sun', which sets the attitude"),
])
def test_scene_errors_name_the_key_value_and_allowed_values(parts, target, message):
    with pytest.raises(sf.InputError, match=message):
        scene_from_dict(box_wing(parts=parts, target=target))


def test_a_time_outside_the_scenes_quaternion_table_is_refused_before_rendering(tmp_path):
    write_table(tmp_path / "q.csv", ["2024-03-01T04:00:00,1,0,0,0", "2024-03-01T04:01:00,1,0,0,0"])
    scene = scene_from_dict(box_wing(target={"attitude": "table", "quaternions": "q.csv", "time_utc": "2024-03-01T05:00:00"}), tmp_path)
    with pytest.raises(sf.InputError, match=r"`target.time_utc` '2024-03-01T05:00:00' is outside the quaternion table"):
        assemble(scene)


def test_laws_round_trip_through_the_scene_file(tmp_path):
    write_table(tmp_path / "q.csv", ["2024-03-01T04:00:00,1,0,0,0", "2024-03-01T04:01:00,0.6,0,0.8,0"])
    scene = scene_from_dict(box_wing(
        parts={"wing_left": {"articulation": "sun_tracking", "axis": [0, 1, 0]},
               "wing_right": {"articulation": "angle", "axis": [0, 1, 0], "angle_deg": 30.0, "pivot_m": [0.0, 1.0, 0.0]}},
        target={"attitude": "table", "quaternions": "q.csv", "time_utc": "2024-03-01T04:00:30"}), tmp_path)
    assert scene.parts["wing_left"].articulation == SunTracking((0, 1, 0), (0.0, -4.0, 0.0))  # pivot: the plate's position
    assert scene.parts["wing_right"].articulation == AxisAngle((0, 1, 0), 30.0, (0.0, 1.0, 0.0))
    (tmp_path / "written.toml").write_text(scene.to_toml())
    again = sf.load_scene(tmp_path / "written.toml")
    assert again.parts == scene.parts and again.target == scene.target
    turned = scene.with_values({"parts.wing_right.angle_deg": -10.0})  # the axis and pivot stay
    assert turned.parts["wing_right"].articulation == AxisAngle((0, 1, 0), -10.0, (0.0, 1.0, 0.0))
    assert scene.with_values({"parts.wing_right.articulation": "fixed"}).parts["wing_right"].articulation == Fixed()
    # the table's body-to-world rotation at 04:00:30, halfway: half of the right-handed turn about y by 2 atan(0.8 / 0.6)
    half = math.atan2(0.8, 0.6)
    expected = np.array([[math.cos(half), 0, math.sin(half)], [0, 1, 0], [-math.sin(half), 0, math.cos(half)]])
    assert np.allclose(assemble(scene).to_world[:3, :3], expected, atol=1e-12)


def test_attitude_angles_are_refused_where_a_law_sets_the_attitude():
    scene = sf.load_scene(SCENES / "starlink-v1p5.toml")
    with pytest.raises(sf.InputError, match=r"`target.attitude_z_deg` sets an attitude angle, which `target.attitude` = "
                                            r"'nadir_sun' does not use"):
        scene.with_values({"target.attitude_z_deg": 3.0})
    with pytest.raises(sf.InputError, match=r"`target.attitude_deg` = \[0.0, 0.0, 3.0\] is not used by `target.attitude` = "
                                            r"'nadir_sun', which sets the attitude"):
        scene.with_values({"target.attitude_deg": [0.0, 0.0, 3.0]})
    fixed = scene.with_values({"target.attitude": "fixed", "target.nadir": [], "target.attitude_z_deg": 3.0})
    assert fixed.target.attitude_deg[2] == 3.0


def test_fits_refuse_angles_that_a_law_sets():
    from spacefit.rendering.values import scene_values_fn  # the rendering layer: it imports Mitsuba's seam

    tracked = assemble(scene_from_dict(box_wing(parts={"wing_left": {"articulation": "sun_tracking", "axis": [0, 1, 0]}})))
    with pytest.raises(sf.InputError, match=r"`sun.elevation_deg` cannot be set in place: parts.wing_left follow the sun"):
        scene_values_fn(tracked, ["sun.elevation_deg"])
    pointed = assemble(scene_from_dict(box_wing(target={"attitude": "sun", "nadir": [0.0, 0.0, -1.0]})))
    with pytest.raises(sf.InputError, match=r"`target.attitude_x_deg` cannot be free: `target.attitude` = 'sun' sets"):
        scene_values_fn(pointed, ["target.attitude_x_deg"])


# The sun towards (0.6, 0, 0.8) in the body (attitude [0, 0, 0]): across the wings' axis y, so a wing
# tracking it about y faces it exactly; a fixed wing (normal +z) sees it at cos = 0.8.
FACE_ON = {"sun": {"direction": [-0.6, 0.0, -0.8], "irradiance_w_m2": 5.0}, "target": {"attitude_deg": [0.0, 0.0, 0.0]}}
DARK = {"material": "lambert", "kd": 0.0}


def test_a_tracking_wing_is_lit_face_on():
    """Lambert wing of kd 0.5 lit face-on: radiance kd E / pi in every pixel it covers wholly; fixed, 0.8 of it."""
    kd, e = 0.5, 5.0
    parts = {"bus": DARK, "wing_right": DARK, "wing_left": {"material": "lambert", "kd": kd}}
    fixed = np.asarray(sf.render(scene_from_dict(box_wing(parts=parts, **FACE_ON))))[..., 1]
    tracked_scene = scene_from_dict(box_wing(parts={**parts, "wing_left": {**parts["wing_left"], "articulation": "sun_tracking",
                                                                           "axis": [0, 1, 0]}}, **FACE_ON))
    tracked = np.asarray(sf.render(tracked_scene))[..., 1]
    for image, cosine in ((tracked, 1.0), (fixed, 0.8)):
        lit = image[image > 0]
        assert np.isclose(lit.max(), kd * e * cosine / np.pi, rtol=1e-5)
        assert np.mean(np.isclose(lit, lit.max(), rtol=1e-5)) > 0.5  # most of the wing's pixels: edges are partial
    v = assemble(tracked_scene).scene_vertices["wing_left"]
    normal = np.cross(v[1] - v[0], v[2] - v[0])
    assert np.allclose(np.abs(normal / np.linalg.norm(normal)), [0.6, 0.0, 0.8], atol=1e-12)


def test_a_tracking_array_renders_as_the_array_placed_by_hand_at_its_angle():
    """The Starlink scene turned (sun moved, its attitude fixed at [0, 0, 0]) against the same array with
    the tracked angle written as its attitude: the same image to float32 rounding of its vertices."""
    sun = unit(0.7, -0.5, 0.3)
    common = {"sun": {"direction": list(sun)}, "target": {"attitude": "fixed", "attitude_deg": [0.0, 0.0, 0.0], "nadir": []},
              "render": {"resolution": [48, 48], "spp": 4}}
    import tomllib

    data = tomllib.loads((SCENES / "starlink-v1p5.toml").read_text())
    for key, value in common.items():
        data[key] = {**data[key], **value}
    tracked = scene_from_dict(data)
    # the array's normal R1(90) e_z = +y turned about body z onto the sun's (x, y) part, (-0.7, 0.5): by
    # R3(c) with R3(c) y = (sin c, cos c, 0), c = atan2(-0.7, 0.5); and R3(c) R1(90) = R1(90) R2(-c) R3(0)
    angle = -math.degrees(math.atan2(-0.7, 0.5))
    by_hand = tracked.with_values({"parts.solar_array.articulation": "fixed", "parts.solar_array.attitude_deg": [90.0, angle, 0.0]})
    v = assemble(tracked).scene_vertices["solar_array"]
    assert np.allclose(v, assemble(by_hand).scene_vertices["solar_array"], atol=1e-12)
    a, b = np.asarray(sf.render(tracked)), np.asarray(sf.render(by_hand))
    assert np.abs(a - b).max() <= 1e-5 * a.max()
    normal = np.cross(v[1] - v[0], v[2] - v[0])
    assert np.allclose(normal / np.linalg.norm(normal) * np.sign(normal[1]), unit(-0.7, 0.5, 0), atol=1e-12)


def test_the_starlink_array_tracks_to_the_published_normal_at_every_pomenis_geometry():
    """In the nadir-sun frame the sun lies in the y-z plane on the +y side: the array, sun-tracking about
    z as the shipped scene declares, keeps the published normal +y (and its tangent) at all 1,173 rows."""
    from test_observed_lightcurves import DATA, MOUNT_LEMMON  # the Pomenis reader's site

    scene = sf.load_scene(SCENES / "starlink-v1p5.toml")
    array = scene.parts["solar_array"]
    assert array.articulation == SunTracking((0, 0, 1), (0.0, 0.0, 4.45)) and scene.target.attitude == "nadir_sun"
    assert np.allclose(array.reference_normal(), Y, atol=1e-15)
    observations = sf.read_light_curve(DATA / "pomenis_observations.csv", site=MOUNT_LEMMON)
    plate = Plate("solar_array", 22.68, tuple(array.reference_normal()), Lambert(0.3), tracking_axis=array.articulation.axis)
    frames = np.asarray(plate.frames(jnp.asarray(observations.sun)))
    assert len(frames) == 1173 and np.allclose(frames, plate.frame(), atol=1e-12)


@float64
def test_a_tracking_plate_in_the_light_curve_model():
    """A plate tracking about z: its irradiance is that of the plate placed by hand facing the sun's
    horizontal part, row by row; the attitude still differentiates through it."""
    rng = np.random.default_rng(5)
    sun, observer = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    sun /= np.linalg.norm(sun, axis=1, keepdims=True)
    observer /= np.linalg.norm(observer, axis=1, keepdims=True)
    tracked = Plate("a", 2.0, (0, 1, 0), Lambert(0.4), tangent=(0, 0, 1), tracking_axis=(0, 0, 1))
    ours = np.asarray(plates_irradiance([tracked], sun, observer, np.full(3, 1e6), 1361.0))
    for i in range(3):
        facing = unit(sun[i, 0], sun[i, 1], 0)
        by_hand = Plate("a", 2.0, tuple(facing), Lambert(0.4), tangent=(0, 0, 1))
        assert np.isclose(ours[i], plates_irradiance([by_hand], sun[i:i + 1], observer[i:i + 1], np.full(1, 1e6), 1361.0)[0], rtol=1e-12)
    with pytest.raises(sf.InputError, match=r"`a.tracking_axis` \[0.0, 1.0, 0.0\] must not be parallel to `a.normal` \[0.0, 1.0, 0.0\]"):
        Plate("a", 2.0, (0, 1, 0), Lambert(0.4), tracking_axis=(0, 2, 0))

    def total(angle):
        turn = attitude_matrix(jnp.stack([angle, 0.0, 0.0]), xp=jnp)
        return plates_irradiance([tracked], jnp.asarray(sun) @ turn, jnp.asarray(observer) @ turn, np.full(3, 1e6), 1361.0).sum()

    h = 1e-6
    assert np.isclose(jax.grad(total)(0.3), (total(0.3 + h) - total(0.3 - h)) / (2 * h), rtol=1e-7)


def test_a_sweep_of_the_sun_assembles_a_tracking_scene_again():
    """The sun's angles are set in place only where nothing follows the sun; a sweep of a tracking wing's
    sun gives what the scene assembled at that sun renders."""
    from spacefit.studies.axes import in_place_names  # the studies' sweep axes

    parts = {"bus": DARK, "wing_right": DARK, "wing_left": {"material": "lambert", "kd": 0.5}}
    fixed = scene_from_dict(box_wing(parts=parts, **FACE_ON))
    tracking = fixed.with_values({"parts.wing_left.articulation": "sun_tracking", "parts.wing_left.axis": [0, 1, 0]})
    assert "sun.elevation_deg" in in_place_names(fixed) and "sun.elevation_deg" not in in_place_names(tracking)
    swept = sf.sweep(tracking, {"sun.elevation_deg": [30.0]}, quiet=True)
    there = sf.sweep(tracking.with_values({"sun.elevation_deg": 30.0}), {"render.seed": [0]}, quiet=True)
    a, b = (ds.mean_radiance.sel(region="wing_left").values.ravel() for ds in (swept, there))
    assert a[0] > 0 and a[0] == b[0]


def test_target_plates_of_tracking_parts_turn_with_each_sun():
    """The plates derived from a scene whose wing and box bus track the sun about y, evaluated at another
    sun, are the plates of the scene assembled at that sun; the Starlink array's carry its axis and +y."""
    parts = {"wing_left": {"material": "lambert", "kd": 0.5, "articulation": "sun_tracking", "axis": [0, 1, 0]},
             "bus": {"material": "lambert", "kd": 0.3, "articulation": "sun_tracking", "axis": [0, 1, 0]}}
    here = scene_from_dict(box_wing(parts=parts, **FACE_ON))
    there = here.with_values({"sun.direction": [0.5, -0.3, 0.6]})
    sun, observer = unit(-0.5, 0.3, -0.6)[None], unit(0.2, 0.1, 1.0)[None]  # the target's attitude is [0, 0, 0]
    moved = sf.target_plates(here)
    assert {p.tracking_axis for p in moved if p.name in parts} == {(0.0, 1.0, 0.0)}
    assert all(p.tracking_axis is None for p in moved if p.name not in parts)
    for plates_here, plates_there in ((moved, sf.target_plates(there)),):
        ours = float(plates_irradiance(list(plates_here), sun, observer, np.ones(1), 1361.0)[0])
        assembled = float(plates_irradiance(list(plates_there), sun, observer, np.ones(1), 1361.0)[0])
        assert ours > 0 and math.isclose(ours, assembled, rel_tol=1e-12)
    array = [p for p in sf.target_plates(sf.load_scene(SCENES / "starlink-v1p5.toml")) if p.name == "solar_array"]
    assert len(array) == 1 and array[0].tracking_axis == (0.0, 0.0, 1.0) and np.allclose(array[0].tracking_normal, Y, atol=1e-12)


def test_a_law_made_fixed_for_the_plates_comparison_keeps_the_assembled_target():
    """compare_plates_to_render sets the body's attitude angles per point: the Starlink scene's nadir_sun
    law is first replaced by the fixed attitude it gives, the target assembled the same."""
    from spacefit.studies.target_plates import body_fixed  # the plates-vs-render module

    scene = sf.load_scene(SCENES / "starlink-v1p5.toml")
    fixed = body_fixed(scene)
    assert fixed.target.attitude == "fixed" and body_fixed(fixed) is fixed
    a, b = assemble(scene), assemble(fixed)
    assert np.allclose(a.to_world, b.to_world, atol=1e-12)
    assert all(np.allclose(a.scene_vertices[n], b.scene_vertices[n], atol=1e-12) for n in scene.parts)
