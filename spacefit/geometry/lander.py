"""The built-in lander: a simplified Chang'e-4-like lander as in thesis section 2.1.

Three parts that differ in material, in the object frame (metres, +z up, origin at the body's
centre). The thesis scaled its sizes from photos ("of no reference value"); these are plausible:

* ``body``: a 2.6 x 2.6 x 1.4 m box wrapped in MLI (12 triangles, closed; wrinkles refine it);
* ``panels``: two 2.2 x 1.5 x 0.04 m solar panels spanning along +-x from the body's top edges.
  Their texture coordinates put ``alpha_x`` along the span (x) and ``alpha_y`` along the chord (y)
  on the large faces;
* ``legs``: four struts (radius 0.08 m) from the body's lower corners down and out to footpads
  (radius 0.25 m, 0.05 m thick) 2.3 m below the body centre, 1.9 m out along each diagonal axis.

Overall about 7.0 m across the panels and 3.0 m tall.
"""

from __future__ import annotations

import numpy as np
import trimesh

from spacefit.geometry.mesh import PartMesh

BODY_SIZE = (2.6, 2.6, 1.4)
PANEL_SIZE = (2.2, 1.5, 0.04)
LEG_RADIUS = 0.08
FOOT_RADIUS = 0.25
FOOT_THICKNESS = 0.05
FOOT_OFFSET = (1.9, -2.3)  # (out along x and y, down along z), metres
LEG_SECTIONS = 12


def _panel(center_x: float) -> PartMesh:
    """A thin box with its own vertices per face and uv = (x, in-face second axis)."""
    box = trimesh.creation.box(extents=PANEL_SIZE)
    box.apply_translation([center_x, 0.0, BODY_SIZE[2] / 2 - PANEL_SIZE[2] / 2])
    tri = box.vertices[box.faces]  # (m, 3, 3): unshared vertices give each face its own uv chart
    normals = box.face_normals
    span = np.array([1.0, 0.0, 0.0])
    # Faces that contain the span axis use it as u; the 4 cm end faces (normal along x) use y.
    u_axis = np.where(np.abs(normals @ span)[:, None] > 0.5, [0.0, 1.0, 0.0], span)
    v_axis = np.cross(normals, u_axis)
    uv = np.stack([np.einsum("mkj,mj->mk", tri, u_axis), np.einsum("mkj,mj->mk", tri, v_axis)], axis=-1)
    return PartMesh(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3), uv.reshape(-1, 2))


def _legs() -> PartMesh:
    meshes = []
    hx, hy, hz = (s / 2 for s in BODY_SIZE)
    for sx, sy in [(1, 1), (-1, 1), (-1, -1), (1, -1)]:
        top = np.array([sx * hx * 0.9, sy * hy * 0.9, -hz])
        foot = np.array([sx * FOOT_OFFSET[0], sy * FOOT_OFFSET[0], FOOT_OFFSET[1] + FOOT_THICKNESS])
        meshes.append(trimesh.creation.cylinder(radius=LEG_RADIUS, segment=[top, foot], sections=LEG_SECTIONS))
        pad = trimesh.creation.cylinder(radius=FOOT_RADIUS, height=FOOT_THICKNESS, sections=2 * LEG_SECTIONS)
        pad.apply_translation([foot[0], foot[1], FOOT_OFFSET[1] + FOOT_THICKNESS / 2])
        meshes.append(pad)
    legs = trimesh.util.concatenate(meshes)
    return PartMesh(np.asarray(legs.vertices, float), np.asarray(legs.faces))


def builtin_lander() -> dict[str, PartMesh]:
    """The default lander's parts by name: ``body``, ``panels``, ``legs``."""
    body = trimesh.creation.box(extents=BODY_SIZE)
    panel_x = BODY_SIZE[0] / 2 + PANEL_SIZE[0] / 2
    left, right = _panel(-panel_x), _panel(panel_x)
    panels = PartMesh(
        np.concatenate([left.vertices, right.vertices]),
        np.concatenate([left.faces, right.faces + len(left.vertices)]),
        np.concatenate([left.uv, right.uv]),
    )
    return {
        "body": PartMesh(np.asarray(body.vertices, float), np.asarray(body.faces)),
        "panels": panels,
        "legs": _legs(),
    }
