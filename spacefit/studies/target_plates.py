"""A target's flat plates derived from its own parts: the plate level of detail of the path-traced target.

:func:`target_plates` turns the parts of a scene, as :func:`~spacefit.scene.assembly.assemble` loads
them (a mesh file's groups, a part's own file, the primitives of :mod:`spacefit.geometry.primitives`),
into :class:`Plate` s in the target's body frame: each part's triangles
grouped by normal (and by tangent where its material is anisotropic), their areas summed. A box
gives its six faces, a plate primitive one plate, a cylinder its facets and its two caps. Each plate carries its part's name (the plates of one
part share its parameters, ``parts.<part>.<field>``), the material the renderer gives the part, and
the tangent the renderer uses for an anisotropic conductor's ``alpha_x``: Mitsuba's shading frame,
dp/du made normal to the face, from the part's texture coordinates (a primitive's u runs along its
z where the face contains it, else along x), else along the triangle's first edge (what Mitsuba does
without texture coordinates; ``spacefit.geometry.mesh.PartMesh``).

A closed part's faces are lit and seen from outside only (``two_sided=False``: their backs are
inside it); an open part's are thin sheets, lit and seen from both sides, as the renderer's
``twosided`` BSDFs shade them. What the plates cannot know, the path tracer adds: a face covered by
another part (a wing's root against the bus), a concave part's faces turned towards each other, one
part shadowing or hiding another, and light bounced between parts (the scene's ``render.depth``
bounces; the plates have one). A wrinkled part (the W-M fractal wrinkles of
:mod:`spacefit.geometry.wrinkle`) is not a flat plate: its plates are its flat base with the
material the renderer gives it, its own where the renderer displaces the wrinkles (the wrinkles'
slopes, shadowing and masking are the path tracer's alone) and the effective rough material where
the renderer draws the part flat (:mod:`spacefit.scene.lod`). :func:`plate_notes` says which of these
apply to a target; :mod:`spacefit.studies.plates_vs_render` measures what they amount to and chooses
between the plates and the path tracer.

The path tracer's own light curve of observed magnitudes is :func:`rendered_light_curve`: each
observation's geometry as scene values (:func:`observation_points`), the target's attitude law fixed
at the scene's sun (:func:`body_fixed`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.spatial.transform import Rotation

from spacefit.errors import InputError, check_type
from spacefit.geometry.articulation import SunTracking
from spacefit.geometry.mesh import PartMesh, _trimesh
from spacefit.materials import Material
from spacefit.scene.assembly import assemble, body_to_world
from spacefit.scene.conversions import sun_angles_deg
from spacefit.scene.schema import Scene
from spacefit.scene.sections import check_scene
from spacefit.studies.lightcurve_fit import RenderedLightCurve
from spacefit.studies.lightcurve_observations import LightCurveObservations
from spacefit.studies.plates import Plate

# Triangles whose unit normals and tangents differ by less than this (1 - cos) are one plate's.
SAME_DIRECTION = 1e-9
# The geometry keys of a rendered point: the target's attitude and the sun's angles (the camera stays).
POINT_KEYS = ("target.attitude_x_deg", "target.attitude_y_deg", "target.attitude_z_deg", "sun.elevation_deg", "sun.azimuth_deg")


def _triangle_frames(part: PartMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each triangle's unit normal (by its winding), area (m^2) and Mitsuba's tangent: dp/du from the
    part's uv, else the first edge, made normal to the face."""
    v = np.asarray(part.vertices, float)[np.asarray(part.faces)]
    dp0, dp1 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    cross = np.cross(dp0, dp1)
    twice_area = np.linalg.norm(cross, axis=1)
    normal = cross / twice_area[:, None]
    tangent = dp0
    if part.uv is not None:
        uv = np.asarray(part.uv, float)[np.asarray(part.faces)]
        duv0, duv1 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        det = duv0[:, 0] * duv1[:, 1] - duv0[:, 1] * duv1[:, 0]
        safe = np.where(det != 0, det, 1.0)[:, None]
        tangent = np.where((det != 0)[:, None], (duv1[:, 1:2] * dp0 - duv0[:, 1:2] * dp1) / safe, dp0)
    tangent = tangent - np.einsum("ij,ij->i", tangent, normal)[:, None] * normal
    return normal, 0.5 * twice_area, tangent / np.linalg.norm(tangent, axis=1, keepdims=True)


def _closed(part: PartMesh) -> bool:
    """Whether the part is a closed surface once vertices at equal positions are merged (as
    :func:`spacefit.geometry.mesh.validate_part` judges it)."""
    mesh = _trimesh().Trimesh(np.asarray(part.vertices, float), np.asarray(part.faces), process=False)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    return bool(mesh.is_watertight)


def anisotropic(material: Material) -> bool:
    """Whether the material's BRDF depends on the tangent: its ``alpha_x`` and ``alpha_y`` differ."""
    return getattr(material, "alpha_x", None) != getattr(material, "alpha_y", None)


def part_plates(name: str, part: PartMesh, material: Material) -> list[Plate]:
    """One part's plates: its triangles grouped by normal (within :data:`SAME_DIRECTION`), and by
    tangent too where the material is :func:`anisotropic` (an isotropic part's plates take their first
    triangle's tangent: a fit that frees its ``alpha_x`` alone needs them apart), areas summed,
    one-sided where the part is closed (module docstring)."""
    normal, area, tangent = _triangle_frames(part)
    two_sided = not _closed(part)
    by_tangent = anisotropic(material)
    left = np.ones(len(area), bool)
    plates = []
    while left.any():
        first = int(np.argmax(left))
        same = left & (normal @ normal[first] > 1 - SAME_DIRECTION)
        if by_tangent:
            same &= tangent @ tangent[first] > 1 - SAME_DIRECTION
        n = (area[same, None] * normal[same]).sum(axis=0)
        plates.append(Plate(name, float(area[same].sum()), tuple(n / np.linalg.norm(n)), material, tuple(tangent[first]), two_sided))
        left &= ~same
    return plates


def target_plates(scene: Scene) -> tuple[Plate, ...]:
    """The flat plates of ``scene``'s target in its body frame, derived from its parts as the renderer
    assembles them (the guide "BRDF tables and light curves as observations"): per part, its triangles grouped by normal (and tangent,
    :func:`part_plates`), with the part's name, the material the renderer gives it and Mitsuba's
    tangent; a closed part's plates one-sided, an open part's two-sided. A wrinkled part gives its
    flat base. A sun-tracking part's plates carry its axis and normal (``tracking_axis``,
    ``tracking_normal``): they turn with it to each observation's sun.

    Raises:
        InputError: a part whose material has no BRDF towards an observer (a mirror), naming it.

    Args:
        scene: the scene.

    Returns:
        The plates (:class:`Plate`), for :class:`PlateLightCurve` and :func:`predict_magnitudes`.

    Example:
        >>> import spacefit as sf
        >>> plates = sf.target_plates(sf.default_scene())
        >>> sorted({p.name for p in plates})
        ['body', 'legs', 'panels']
    """
    check_scene(scene)
    assembly = assemble(scene)
    sun = assembly.to_world[:3, :3].T @ -assembly.sun_direction  # towards the sun, body frame
    plates: list[Plate] = []
    for name, part in assembly.parts.items():
        law = scene.parts[name].articulation
        if isinstance(law, SunTracking):  # its faces turn together, the part's normal (as assembled) to each sun
            normal = law.rotation(scene.parts[name].reference_normal(), sun) @ scene.parts[name].reference_normal()
            plates += [dataclasses.replace(p, tracking_axis=law.axis, tracking_normal=tuple(normal))
                       for p in part_plates(name, part, assembly.materials[name])]
        else:
            plates += part_plates(name, part, assembly.materials[name])
    return tuple(plates)


def plate_notes(scene: Scene) -> tuple[str, ...]:
    """What the plates of ``scene``'s target leave out and the path tracer has (module docstring): its
    wrinkled parts, parts that could shadow or hide each other, open parts seen from both sides, and
    the bounces beyond the first; one line each."""
    check_scene(scene)
    assembly = assemble(scene)
    notes = []
    for name, choice in assembly.lod.items():
        if choice.model == "geometry":
            notes.append(f"part {name!r} is wrinkled (W-M, D = {scene.wrinkles.D:g}, G = {scene.wrinkles.G:g} m): its plates are its "
                         "flat base with its own material; the wrinkles' slopes, shadowing and masking are the path tracer's alone")
        else:
            notes.append(f"part {name!r} is wrinkled and rendered flat with the effective rough material "
                         f"({choice.reason}): its plates have that material")
    for name, part in assembly.parts.items():
        if not _closed(part):
            notes.append(f"part {name!r} is open: its plates are lit and seen from both sides")
        elif not _trimesh().Trimesh(part.vertices, part.faces).is_convex:
            notes.append(f"part {name!r} is not convex: its faces may shadow and hide each other, which plates do not")
    if len(assembly.parts) > 1:
        notes.append(f"{len(assembly.parts)} parts: plates count every face, also one covered, shadowed or hidden by another part")
    if scene.render.depth > 1:
        notes.append(f"the path tracer follows {scene.render.depth} bounces (render.depth), the plates one")
    return tuple(notes)


def body_fixed(scene: Scene) -> Scene:
    """``scene`` with its target's attitude law (``target.attitude``) replaced by the fixed attitude it
    gives at the scene's sun (its attitude angles): the points of a comparison or a rendered light curve
    set the body's attitude angles themselves, the observations' geometry being in the body frame."""
    if scene.target.attitude == "fixed":
        return scene
    angles = attitude_angles_deg(body_to_world(scene)[:3, :3])
    return scene.with_values({"target.attitude": "fixed", "target.nadir": [], "target.quaternions": "", "target.time_utc": "",
                              "target.attitude_deg": list(angles)})


def attitude_angles_deg(rotation: np.ndarray) -> tuple[float, float, float]:
    """The target's attitude angles (deg) of a body-to-world rotation, the inverse of
    :func:`~spacefit.geometry.frames.attitude_matrix` (R1(a) R2(b) R3(c) is the rotation
    x(-a) y(-b) z(-c) of the vectors, intrinsic)."""
    return tuple(float(-a) for a in Rotation.from_matrix(rotation).as_euler("XYZ", degrees=True))


def _turning(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit ``a`` to unit ``b`` (half a turn about a normal of ``a`` if opposite)."""
    axis, cos = np.cross(a, b), float(np.dot(a, b))
    if np.linalg.norm(axis) < 1e-12:
        if cos > 0:
            return np.eye(3)
        normal = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        return Rotation.from_rotvec(math.pi * normal / np.linalg.norm(normal)).as_matrix()
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * math.atan2(np.linalg.norm(axis), cos)).as_matrix()


def observation_points(scene: Scene, observations: LightCurveObservations) -> list[dict[str, float]]:
    """Each observation's geometry as scene values, the scene's camera kept: the target's attitude
    angles turning its body frame's direction towards the observer onto the camera's, and the sun's
    elevation and azimuth (deg, world) of its body direction so turned."""
    check_scene(scene)
    check_type("observations", observations, LightCurveObservations, "an sf.LightCurveObservations (sf.read_light_curve)")
    towards = np.array(scene.camera.position_m) - np.array(scene.target.position_m)
    towards /= np.linalg.norm(towards)
    points = []
    for sun, observer in zip(observations.sun, observations.observer):
        turn = _turning(observer / np.linalg.norm(observer), towards)
        elevation, azimuth = sun_angles_deg(-(turn @ sun))
        points.append(dict(zip(POINT_KEYS, (*attitude_angles_deg(turn), elevation, azimuth))))
    return points


def rendered_light_curve(scene: Scene, observations: LightCurveObservations, *, seed: int = 1) -> RenderedLightCurve:
    """The path tracer's light curve of ``observations`` of ``scene``'s target: every lit observation at
    its geometry (:func:`observation_points`, the scene's attitude law fixed: :func:`body_fixed`), its
    magnitude carried to their median range by the inverse square law (exact for an unresolved target).

    Raises:
        InputError: every observation in the Earth's shadow.
    """
    scene = body_fixed(check_scene(scene))  # type: ignore[arg-type]
    check_type("observations", observations, LightCurveObservations, "an sf.LightCurveObservations (sf.read_light_curve)")
    lit = np.flatnonzero(~observations.in_shadow)
    if not lit.size:
        raise InputError(f"every observation of {observations.source} is in the Earth's shadow: there is nothing to fit.")
    obs = observations.subset(lit)
    reference = float(np.median(obs.range_m))
    magnitude = obs.magnitude - 5.0 * np.log10(obs.range_m / reference)
    return RenderedLightCurve(scene, observation_points(scene, obs), magnitude, obs.magnitude_sigma, obs.band,
                              observer_range_m=reference, seed=seed)
