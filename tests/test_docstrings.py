"""The reference pages teach: every public name's docstring (the API pages are made from them) runs its
``Example:`` as written and sends the reader to public names and pages, never to a private module."""

from __future__ import annotations

import doctest
import inspect
import re

import numpy as np
import pytest
from sphinx.pycode import ModuleAnalyzer

import spacefit as sf

# Examples that take more than about a second (a render, a fit): run with ``-m slow``, each with its reason.
RENDERS = "renders the default scene at 48 x 48 px (a few seconds with Mitsuba's start)"
EXPENSIVE: dict[str, str] = {
    "render": RENDERS, "Renderer": RENDERS, "PartImage": RENDERS, "render_to_folder": RENDERS,
    "render_function": "renders and differentiates", "jacobian": "renders and differentiates", "Jacobian": "renders and differentiates",
    **dict.fromkeys(["fit_brdf_table", "fitted_material", "compare_brdf_models", "BRDFTableObservation", "write_table_fit", "fit",
                     "FitResult", "format_result"],
                    "fits a BRDF table: JAX compiles the solver (about 10 s)"),
    **dict.fromkeys(["fit_plates", "fitted_plates"], "fits plates to a light curve: JAX compiles the solver (about 13 s)"),
    **dict.fromkeys(["pass_geometry", "PassGeometry"], "loads astropy's coordinate frames (about 5 s)"),
    **dict.fromkeys(["sweep", "verify_store", "StoreReport", "sensitivity", "Sensitivity", "light_curve", "LightCurve"],
                    "renders several points of the default scene at 48 x 48 px"),
    **dict.fromkeys(["PlateLightCurve", "fit_design", "predict_design", "MagnitudePrediction", "design_noise_mag",
                     "predictive_intervals", "Prediction", "residual_noise"], "fits plates to a light curve (about 15 s)"),
    **dict.fromkeys(["identifiability", "Identifiability"], "renders and differentiates"),
    "target_plates": "builds the lander's wrinkled mesh (about 9 s)",
    "plot_convergence": "fits a BRDF table: JAX compiles the solver (about 10 s)",
    "read_fit": "fits a BRDF table: JAX compiles the solver (about 10 s)",
    **dict.fromkeys(["RenderedLightCurve", "compare_plates_to_render", "PlatesVsRender", "choose_light_curve_model", "ChosenLightCurve",
                     "light_curve_convergence", "simulate_pass", "PassObservation"], "renders the default scene at 48 x 48 px"),
}


def docstring(name: str) -> str:
    """The text the API page of ``sf.<name>`` shows: a class's or function's docstring, or for a constant the
    ``#:`` comment above its assignment in its home module (the docs' ``conf.py`` shows the same)."""
    obj = getattr(sf, name)
    if inspect.isclass(obj) or inspect.isfunction(obj):
        return inspect.getdoc(obj) or ""
    module, attr = sf._EXPORTS[name]
    return "\n".join(ModuleAnalyzer.for_module(module).find_attr_docs().get(("", attr), []))


def member_docstrings(name: str) -> list[tuple[str, str]]:
    """The public methods' and properties' docstrings of class ``sf.<name>`` (its page lists them), as (name, text)."""
    obj = getattr(sf, name)
    if not inspect.isclass(obj):
        return []
    out = []
    for member, value in vars(obj).items():
        if member.startswith("_"):
            continue
        doc = inspect.getdoc(value.fget if isinstance(value, property) else getattr(value, "__func__", value))
        if callable(value) or isinstance(value, (property, classmethod, staticmethod)):
            out.append((f"{name}.{member}", doc or ""))
    return out


PRIVATE = re.compile(r"\bspacefit\.(?!toml\b)[a-z_]\w*|\bspacefit/\w+\.py\b|\bmodule\s+docstring\b")


@pytest.mark.parametrize("name", sorted(sf.__all__))
def test_docstring_points_to_public_names(name):
    """A docstring names public things (``sf.fit``, :class:`FitResult`, a docs page), never a private module such as
    ``spacefit.fitting.params`` or "the module docstring": the reader cannot import it and its page does not exist."""
    for where, text in [(name, docstring(name)), *member_docstrings(name)]:
        assert not PRIVATE.findall(text), f"{where}'s docstring names private modules: {PRIVATE.findall(text)}"


def test_private_reference_is_caught():
    """The scan above finds a private module named in the ways docstrings did."""
    assert PRIVATE.findall("see `spacefit.fitting.params` and :func:`spacefit.sensor.read_sensor_file`") == [
        "spacefit.fitting", "spacefit.sensor"]
    assert PRIVATE.findall("the formats of the module\n    docstring") == ["module\n    docstring"]
    assert not PRIVATE.findall("a scene file (spacefit.toml) read by `sf.load_scene`")


def with_example() -> list:
    """The public names whose docstring has an example (``>>>``), the expensive ones marked slow."""
    return [pytest.param(name, marks=pytest.mark.slow) if name in EXPENSIVE else name
            for name in sorted(sf.__all__) if ">>>" in docstring(name)]


@pytest.mark.parametrize("name", with_example())
def test_docstring_example_runs(name, tmp_path, monkeypatch):
    """The ``Example:`` of ``sf.<name>``'s page runs and prints what it shows (in a fresh folder, for the files
    it writes)."""
    monkeypatch.chdir(tmp_path)
    test = doctest.DocTestParser().get_doctest(docstring(name), {"sf": sf, "np": np}, f"sf.{name}", None, 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def test_example_failure_is_caught(tmp_path, monkeypatch):
    """An example whose output differs from what it shows fails (the runner above compares, not only runs)."""
    test = doctest.DocTestParser().get_doctest(">>> 1 + 1\n3\n", {}, "wrong", None, 0)
    runner = doctest.DocTestRunner()
    runner.run(test, out=lambda _: None)
    assert runner.failures == 1


def test_expensive_examples_exist():
    """Every name marked expensive has an example to run."""
    assert all(">>>" in docstring(name) for name in EXPENSIVE), [n for n in EXPENSIVE if ">>>" not in docstring(n)]
