"""
Your own mesh
=============

A target of your own is a mesh file with one named group per part (``g`` in an OBJ file) and a
scene file that gives each group's material in a ``[parts.NAME]`` table. Here a small probe made
on the fly with trimesh, a cylindrical bus and a dish (the side of a cone), written as an OBJ file, rendered,
and each part's pixels counted.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import trimesh

import spacefit as sf

folder = Path(tempfile.mkdtemp())
bus = trimesh.creation.cylinder(radius=0.8, height=2.0, sections=24)  # m, axis along z
cone = trimesh.creation.cone(radius=1.2, height=0.5, sections=24)
dish = trimesh.Trimesh(
    cone.vertices, cone.faces[cone.triangles_center[:, 2] > 1e-9]
)  # its side, no base
dish.apply_transform(
    trimesh.transformations.rotation_matrix(np.pi, [1, 0, 0])
)  # opening upwards ...
dish.apply_translation([0.0, 0.0, 1.6])  # ... above the bus
lines, first = [], 1
for name, part in {"bus": bus, "dish": dish}.items():
    lines += [f"g {name}", *(f"v {x:.6g} {y:.6g} {z:.6g}" for x, y, z in part.vertices)]
    lines += [f"f {a + first} {b + first} {c + first}" for a, b, c in part.faces]
    first += len(part.vertices)
(folder / "probe.obj").write_text("\n".join(lines) + "\n")

(folder / "probe.toml").write_text("""
[render]
resolution = [96, 96]
spp = 16

[camera]
position_m = [0.0, -60.0, 25.0]
look_at_m = [0.0, 0.0, 0.5]
focal_length_mm = 1000.0
pixel_pitch_mm = 0.8

[sun]
direction = [-0.5, 0.6, -0.6]

[target]
mesh = "probe.obj"
attitude_deg = [0.0, 0.0, 0.0]

[wrinkles]
enabled = false

[parts.bus]
material = "mli_thesis"

[parts.dish]
material = "white_paint"
""")
renderer = sf.Renderer(sf.load_scene(folder / "probe.toml"))
radiance = renderer.render()
parts = renderer.part_image()
print(
    parts.table(radiance)[["pixels", "mean_radiance"]]
    .to_dataframe()
    .round(3)
    .to_string()
)

fig, (left, right) = plt.subplots(1, 2, figsize=(8, 4), layout="constrained")
left.imshow(
    np.clip(radiance / np.percentile(radiance[radiance > 0], 99.5), 0, 1) ** (1 / 2.2)
)
left.set_title("radiance (display gamma 2.2)")
right.imshow(
    np.ma.masked_less(parts.ids, 0),
    cmap="tab10",
    vmin=0,
    vmax=9,
    interpolation="nearest",
)
right.set_title("the part each pixel sees")
right.legend(
    handles=[
        plt.Rectangle((0, 0), 1, 1, color=plt.get_cmap("tab10")(i))
        for i in range(len(parts.names))
    ],
    labels=list(parts.names),
    loc="lower right",
    fontsize=9,
)
for ax in (left, right):
    ax.set_axis_off()
