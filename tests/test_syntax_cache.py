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


def imported(path: Path, module: str):
    """The file at ``path`` imported as ``module``."""
    spec = importlib.util.spec_from_file_location(module, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def load(path: Path, module: str):
    """Import the file at ``path`` as ``module`` and decorate its count_to as Mitsuba's modules do."""
    mod = imported(path, module)
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


METHOD = textwrap.dedent("""
    import drjit as dr
    from drjit.llvm import Float, UInt32

    class Integrator:
        def count_to(self, n: int, step=2):
            i = UInt32(0)
            total = Float(0)
            while i < n:
                total += Float(i) * step
                i += 1
            return total
""")


def test_a_method_is_read_back_as_dr_jit_s_rewrite(calls, tmp_path):
    """Mitsuba's integrators' functions are methods: Dr.Jit compiles a method's source alone, under its bare name."""
    src = tmp_path / "method.py"
    src.write_text(METHOD)
    method = imported(src, "mitsuba.fake_method").Integrator.count_to
    method.__module__ = "mitsuba.fake_method"
    first = syntax_cache.cached_syntax(method)
    second = syntax_cache.cached_syntax(method)
    assert calls == ["Integrator.count_to"] and len(entries(tmp_path)) == 1  # read from the disk the second time
    assert same_code(second, first) and same_code(second, drjit.ast.syntax(method))
    assert second(None, 5)[0] == 20.0


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
    """Two processes: the first fills the cache with Mitsuba's AD integrators, the second reads them all (Dr.Jit
    rewrites none), and its PRB integrator's rewritten functions are the first's byte for byte."""
    script = (
        "import marshal, hashlib, spacefit.rendering.backend as b, spacefit.rendering.syntax_cache as c\n"
        "rewritten = []\n"
        "rewrite = c._dr_syntax\n"
        "c._dr_syntax = lambda f, **kw: rewritten.append(f.__qualname__) or rewrite(f, **kw)\n"
        "b.mi.set_variant('llvm_ad_rgb')\n"
        "prb = b.mi.ad.integrators.prb.PRBIntegrator.sample\n"
        "print(hashlib.sha256(marshal.dumps(prb.__code__)).hexdigest(), len(rewritten))\n"
    )
    env = {"SPACEFIT_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    runs = [subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True).stdout.split()
            for _ in range(2)]
    assert len(entries(tmp_path)) >= 5  # PRB, its basic, volumetric and projective forms
    assert int(runs[0][1]) >= 5 and runs[1][1] == "0"  # the variant's integrators: the second process rewrote none
    assert runs[0][0] == runs[1][0] and len(runs[0][0]) == 64


def same_code(f, g) -> bool:
    """Whether two functions run the same code: bytecode, constants (nested code included), names and lines."""
    return f.__code__ == g.__code__ and f.__code__.co_consts == g.__code__.co_consts and f.__code__.co_linetable == g.__code__.co_linetable


def bit_flips(data: bytes, count: int) -> list[bytes]:
    """``count`` copies of ``data``, each with one bit flipped, spread evenly over its bytes."""
    flipped = []
    for k in range(count):
        at = k * len(data) // count
        flipped.append(data[:at] + bytes([data[at] ^ (1 << (k % 8))]) + data[at + 1:])
    return flipped


def test_a_flipped_bit_anywhere_in_an_entry_is_rewritten_to_the_clean_run_s_code(calls, tmp_path):
    src = tmp_path / "fake.py"
    src.write_text(SOURCE)
    clean = load(src, "mitsuba.fake_integrator")
    (entry,) = entries(tmp_path)
    intact = entry.read_bytes()
    for n, damaged in enumerate(bit_flips(intact, 40), start=2):
        entry.write_bytes(damaged)
        again = load(src, "mitsuba.fake_integrator")
        assert len(calls) == n  # rewritten by Dr.Jit, never read
        assert same_code(again, clean) and again(5)[0] == 20.0
        assert same_code(load(src, "mitsuba.fake_integrator"), clean) and len(calls) == n  # replaced by a whole entry


OTHER = SOURCE + textwrap.dedent("""
    def count_down(n: int, step=2):
        i = UInt32(n)
        total = Float(0)
        while i > 0:
            total -= Float(i) * step
            i -= 1
        return total
""")


def test_another_function_s_valid_code_under_this_function_s_entry_is_rewritten(calls, tmp_path):
    """Another function's code, with the identity line and a checksum that holds, is not run as count_to."""
    src = tmp_path / "fake.py"
    src.write_text(OTHER)
    clean = load(src, "mitsuba.fake_integrator")
    (entry,) = entries(tmp_path)
    line = entry.read_bytes().split(b"\n", 1)[0]
    spec = importlib.util.spec_from_file_location("other_fake", src)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    wrong = drjit.ast.syntax(mod.count_down).__code__
    entry.write_bytes(syntax_cache._entry(line, wrong))
    again = load(src, "mitsuba.fake_integrator")
    assert calls == ["count_to", "count_to"]
    assert same_code(again, clean) and again(5)[0] == 20.0
    # an entry written for another function (its own identity line) is not read either
    entry.write_bytes(syntax_cache._entry(line.replace(b'"count_to"', b'"count_down"'), wrong))
    assert load(src, "mitsuba.fake_integrator")(5)[0] == 20.0 and len(calls) == 3


NESTED = textwrap.dedent("""
    import drjit as dr
    from drjit.llvm import Float, UInt32

    def outer(n: int):
        def inner(m):
            i = UInt32(0)
            total = Float(0)
            while i < m:
                total += 1
                i += 1
            return total
        return inner(n)
""")


def test_recursive_and_plain_rewrites_are_separate_entries(calls, tmp_path):
    src = tmp_path / "nested.py"
    src.write_text(NESTED)
    mod = imported(src, "mitsuba.nested")
    mod.outer.__module__ = "mitsuba.nested"
    plain = syntax_cache.cached_syntax(mod.outer)
    deep = syntax_cache.cached_syntax(mod.outer, recursive=True)
    assert calls == ["outer", "outer"] and len(entries(tmp_path)) == 2
    assert same_code(deep, drjit.ast.syntax(mod.outer, recursive=True))
    assert same_code(plain, drjit.ast.syntax(mod.outer))
    assert not same_code(plain, deep)
    again = syntax_cache.cached_syntax(mod.outer, recursive=True)
    assert calls == ["outer", "outer"] and same_code(again, deep)
