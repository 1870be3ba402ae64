"""Render each point of a light curve exported by ``lightcurve_300.py`` with Blender Cycles (bpy 5.0.1), CPU.

Runs in ``.venv-peers`` (``make peers``), never in spacefit's own environment. Each sub-folder of
``POINTS_DIR`` holds one point's ``scene.json`` and PLYs (:func:`spacefit.rendering.cycles.export_view`);
each is built (:func:`cycles_render.build_scene`) and rendered once at ``--spp`` with ``--seed`` over
spacefit's window only (a render border: black space outside it), and ``cycles.exr`` (radiance,
W m^-2 sr^-1, float32 RGB) and ``timing.json`` (the render's wall time) are written beside it.

Run: ``.venv-peers/bin/python experiments/cycles_light_curve.py POINTS_DIR --spp 128 [--seed 0]``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # cycles_render, beside this file

from cycles_render import build_scene, render_once, set_border  # noqa: E402


def main() -> None:
    import bpy  # only in .venv-peers (make peers)

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("points_dir", type=Path)
    p.add_argument("--spp", type=int, required=True)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    for folder in sorted(f for f in args.points_dir.iterdir() if (f / "scene.json").is_file()):
        if (folder / "cycles.exr").is_file():
            continue  # rendered by an earlier run
        description = json.loads((folder / "scene.json").read_text())
        scene = build_scene(bpy, description, folder)
        set_border(scene, description["render"])
        seconds = render_once(bpy, scene, args.spp, args.seed)
        bpy.data.images["Render Result"].save_render(str(folder / "cycles.exr"))
        (folder / "timing.json").write_text(json.dumps({"render_s": seconds, "spp": args.spp, "seed": args.seed,
                                                         "blender": bpy.app.version_string, "threads": scene.render.threads}))
        print(f"{folder.name}: {seconds:.1f} s", flush=True)


if __name__ == "__main__":
    main()
