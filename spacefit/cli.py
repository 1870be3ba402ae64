"""Command line: ``spacefit render|scene|export-stl [SCENE.toml] --out PATH [--set key=value ...]``."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from spacefit.errors import InputError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="spacefit", description="Simulate and fit images of space targets.")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene to radiance.exr, preview.png, scene.toml, render.json")
    r.add_argument("scene", nargs="?", help="scene TOML file (default: the thesis's Table 4-2 scene)")
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set camera.focal_length_mm=5000 (repeatable)")
    r.add_argument("--quiet", action="store_true", help="no progress output")
    w = sub.add_parser("scene", help="write the resolved scene (defaults: Table 4-2) as TOML to start from")
    w.add_argument("scene", nargs="?", help="scene TOML file to resolve (default: the thesis's scene)")
    w.add_argument("--out", required=True, help="TOML file to write")
    w.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    e = sub.add_parser("export-stl", help="write a part (wrinkled body by default) as binary STL")
    e.add_argument("scene", nargs="?", help="scene TOML file (default: the thesis's scene)")
    e.add_argument("--part", default="body")
    e.add_argument("--out", required=True, help="STL file to write")
    e.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit code (2 for bad input)."""
    args = _parser().parse_args(argv)
    from spacefit.output import write_text
    from spacefit.pipeline import export_part_stl, render_to_folder
    from spacefit.scene.config import load_scene

    try:
        scene = load_scene(args.scene, args.overrides)
        if args.command == "render":
            render_to_folder(scene, args.out, quiet=args.quiet)
        elif args.command == "scene":
            write_text(args.out, scene.to_toml())
        else:
            print(export_part_stl(scene, args.part, args.out))
    except InputError as err:
        print(f"spacefit: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
