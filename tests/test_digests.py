"""Inputs recorded by content (spacefit.digests): a watched file's status catches an edit within the
same second, and every mesh file a scene reads is recorded, its parts' as well as its target's."""

from __future__ import annotations

import os
from pathlib import Path

from helpers import small_scene, write_sphere_obj

from spacefit.digests import Watch, status


def edit_in_place(path: Path, data: bytes, mtime_ns: int) -> None:
    """Rewrite ``path`` in place (same inode) with ``data`` and set its modification time."""
    with open(path, "r+b") as f:
        f.write(data)
    os.utime(path, ns=(mtime_ns, mtime_ns))


def test_an_edit_within_the_same_second_keeping_size_and_inode_is_caught_by_the_status(tmp_path):
    mesh = tmp_path / "part.obj"
    mesh.write_bytes(b"v 0 0 0\n")
    second = 1_700_000_000 * 10**9
    os.utime(mesh, ns=(second + 100_000_000, second + 100_000_000))
    watch = Watch([mesh])
    before = status([str(mesh)])
    edit_in_place(mesh, b"v 1 0 0\n", second + 900_000_000)  # 0.8 s later, within the same whole second
    assert status([str(mesh)]) != before
    assert watch.check() == [str(mesh)]  # the status moved, so the SHA-256 was compared


def test_every_part_s_mesh_file_is_recorded_and_an_edit_of_it_caught(tmp_path):
    target = write_sphere_obj(tmp_path / "sphere.obj")
    part = write_sphere_obj(tmp_path / "ball.obj", subdivisions=1)
    scene = small_scene(target, {"material": "white_paint"}, parts={"ball": {"file": str(part), "material": "white_paint"}})
    assert scene.mesh_files() == [str(target), str(part)]
    watch = Watch(scene.mesh_files())
    assert set(watch.recorded) == {str(target), str(part)}
    key = status(scene.mesh_files())  # what a sweep's worker keys its loaded scene by
    text = part.read_text()
    part.write_text(text.replace("v ", "v  ", 1))  # one more byte: another mesh file
    assert watch.check() == [str(part)] and watch.final() == [str(part)]
    assert status(scene.mesh_files()) != key
