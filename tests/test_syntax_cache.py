"""The disk cache of Dr.Jit's @dr.syntax rewrites (spacefit.rendering.syntax_cache): the function it
returns is Dr.Jit's, a changed source or a damaged entry is rewritten again, and nothing but
Mitsuba's modules is cached."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import textwrap
from pathlib import Path

import drjit.ast
import pytest

from spacefit.rendering import syntax_cache

ROOT = Path(__file__).resolve().parents[1]

SOURCE = textwrap.dedent("""
    import drjit as dr
    from drjit.llvm import Float, UInt32

    def count_to(n: int, step=2):
        i = UInt32(0)
        total = Float(0)
        while i < n:
            total += Float(i) * step
            i += 1
        return total
""")


def load(path: Path, module: str):
    """Import the file at ``path`` as ``module`` and decorate its count_to as Mitsuba's modules do."""
    spec = importlib.util.spec_from_file_location(module, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.count_to.__module__ = module
    return syntax_cache.cached_syntax(mod.count_to)


@pytest.fixture
def calls(monkeypatch, tmp_path):
    """The cache in ``tmp_path``; a list of the functions Dr.Jit itself rewrote."""
    monkeypatch.setenv("SPACEFIT_CACHE_DIR", str(tmp_path / "cache"))
    rewritten = []

    def counting(f, **kwargs):
        rewritten.append(f.__qualname__)
        return drjit.ast.syntax(f, **kwargs)

    monkeypatch.setattr(syntax_cache, "_dr_syntax", counting)
    return rewritten


def entries(tmp_path: Path) -> list[Path]:
    folder = tmp_path / "cache" / syntax_cache.FOLDER
    return sorted(folder.iterdir()) if folder.exists() else []


def test_a_mitsuba_function_is_rewritten_once_and_then_read_as_dr_jit_s_rewrite(calls, tmp_path):
    src = tmp_path / "fake.py"
    src.write_text(SOURCE)
    first = load(src, "mitsuba.fake_integrator")
    assert calls == ["count_to"] and len(entries(tmp_path)) == 1
    second = load(src, "mitsuba.fake_integrator")
    assert calls == ["count_to"]  # read from the disk, not rewritten
    assert second.__code__ == first.__code__ == drjit.ast.syntax(load_plain(src)).__code__
    assert second.__defaults__ == (2,)
    assert second(5)[0] == first(5)[0] == 20.0  # the loop ran as a Dr.Jit loop


def load_plain(path: Path):
    spec = importlib.util.spec_from_file_location("plain_fake", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.count_to


def test_a_changed_source_is_rewritten_again(calls, tmp_path):
    src = tmp_path / "fake.py"
    src.write_text(SOURCE)
    load(src, "mitsuba.fake_integrator")
    syntax_cache._source_digest.cache_clear()  # a new process, after the file changed
    src.write_text(SOURCE.replace("* step", "* step + 1"))
    changed = load(src, "mitsuba.fake_integrator")
    assert calls == ["count_to", "count_to"] and len(entries(tmp_path)) == 2
    assert changed(5)[0] == 25.0


def test_a_damaged_entry_is_rewritten_and_replaced(calls, tmp_path):
    src = tmp_path / "fake.py"
    src.write_text(SOURCE)
    load(src, "mitsuba.fake_integrator")
    (entry,) = entries(tmp_path)
    intact = entry.read_bytes()
    entry.write_bytes(intact[: len(intact) // 2])
    again = load(src, "mitsuba.fake_integrator")
    assert calls == ["count_to", "count_to"] and again(5)[0] == 20.0
    assert entries(tmp_path) == [entry] and entry.read_bytes() == intact


def test_other_functions_and_a_cache_turned_off_go_to_dr_jit_unchanged(calls, tmp_path, monkeypatch):
    src = tmp_path / "fake.py"
    src.write_text(SOURCE)
    load(src, "users_own_module")
    assert calls == ["count_to"] and entries(tmp_path) == []
    monkeypatch.setenv("SPACEFIT_CACHE_DIR", "off")
    load(src, "mitsuba.fake_integrator")
    assert calls == ["count_to", "count_to"] and entries(tmp_path) == []


def test_mitsuba_s_integrators_set_up_from_the_cache_in_a_new_process(tmp_path):
    """Two processes: the first fills the cache with Mitsuba's AD integrators, the second reads them, and
    its PRB integrator's rewritten functions are the first's byte for byte."""
    script = (
        "import marshal, hashlib, spacefit.rendering.backend as b\n"
        "b.mi.set_variant('llvm_ad_rgb')\n"
        "prb = b.mi.ad.integrators.prb.PRBIntegrator.sample\n"
        "print(hashlib.sha256(marshal.dumps(prb.__code__)).hexdigest())\n"
    )
    env = {"SPACEFIT_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    runs = [subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    assert len(entries(tmp_path)) >= 5  # PRB, its basic, volumetric and projective forms
    assert runs[0].stdout == runs[1].stdout and len(runs[0].stdout.strip()) == 64
