"""Sphinx configuration of spacefit's documentation (``make docs``; warnings are errors there).

Sphinx with the PyData theme, MyST-NB and sphinx-gallery: the generator xarray, astropy and NumPy use,
so the API reference is made from the docstrings, notebooks and the gallery's scripts run at build
time and make their own figures. ``SPACEFIT_DOCS_FAST=1`` skips running the gallery and the
notebooks (a quick build while editing text); ``make docs`` and the docs test run them all.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent / "_ext"))
FAST = os.environ.get("SPACEFIT_DOCS_FAST") == "1"

import spacefit  # noqa: E402
from gallery_figures import FigureScraper  # noqa: E402

project = "spacefit"
author = "spacefit authors"
copyright = "spacefit authors, BSD-3-Clause"
release = version = "0.1.0"

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "offline_mathjax",  # sphinx.ext.mathjax with MathJax from the site itself (docs/_ext/offline_mathjax.py)
    "sphinxarg.ext",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "gallery/*.ipynb", "gallery/*.py", "gallery/*.zip",
                    "gallery/*.md5", "gallery/*.json", "examples/*", "jupyter_execute", "_generated/*", "_ext/*", "_static/*"]
suppress_warnings = ["config.cache"]  # sphinx-gallery's conf holds functions, which Sphinx cannot pickle

# MyST: headings get anchors so pages can link to sections
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

# MyST-NB: the notebooks under notebooks/ run at every build, in their own folder (outputs are not stored)
nb_execution_mode = "off" if FAST else "force"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

# API reference from the docstrings of the public names (``sf.__all__``)
autosummary_generate = True
autodoc_default_options = {"members": True, "undoc-members": False, "member-order": "bysource"}
autodoc_typehints = "description"
autodoc_typehints_format = "short"
add_module_names = False
napoleon_google_docstring = True  # the docstrings' "Args:", "Returns:", "Attributes:"
napoleon_numpy_docstring = False
napoleon_use_ivar = True



sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "gallery",
    "filename_pattern": r"/plot_",
    "plot_gallery": "False" if FAST else "True",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    "image_scrapers": (FigureScraper(),),  # every figure once, pyplot's and spacefit's (docs/_ext/gallery_figures.py)
    "reset_modules": ("matplotlib",),
    "write_computation_times": False,  # its page loads DataTables from a CDN: the site serves every asset itself
    "ignore_repr_types": r"matplotlib[._]",  # a block's last line that draws shows no "Text(...)" or "Legend" line
}

html_theme = "pydata_sphinx_theme"
html_title = "spacefit"
html_static_path = ["_static"]
html_css_files = ["spacefit.css"]  # wider pages for the code cells
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "header_links_before_dropdown": 7,
    "secondary_sidebar_items": ["page-toc"],
}
html_sidebars = {"index": [], "getting-started": []}  # the sections' pages: the section's own navigation
html_show_sourcelink = False


def _constant_docstring(app, what, name, obj, options, lines) -> None:
    """A public constant (a dict or tuple such as ``sf.PARAMETERS``) would show its type's docstring:
    show the ``#:`` comment above it in its home module, else say what it holds."""
    from sphinx.pycode import ModuleAnalyzer

    home = spacefit._EXPORTS.get(name.removeprefix("spacefit."))
    comment = ModuleAnalyzer.for_module(home[0]).find_attr_docs().get(("", home[1])) if what == "data" and home else None
    if comment:
        lines[:] = list(comment)
    elif isinstance(obj, (dict, tuple, list, frozenset)) and lines and lines[0].startswith(("dict(", "Built-in", "tuple(", "list(")):
        lines[:] = [f"A {type(obj).__name__} of {len(obj)} entries: " + ", ".join(f"``{k}``" for k in list(obj)[:12])
                    + (", ..." if len(obj) > 12 else "") + "."]


def _code_length(docname: str) -> int:
    """The length of a page's executed code: its MyST ``code-cell`` blocks, or a notebook's code cells (0: none)."""
    base = Path(__file__).parent / docname
    if base.with_suffix(".ipynb").exists():
        cells = json.loads(base.with_suffix(".ipynb").read_text())["cells"]
        return sum(len("".join(c["source"])) for c in cells if c["cell_type"] == "code")
    page = base.with_suffix(".md")
    return sum(map(len, re.findall(r"```\{code-cell\}[^\n]*\n(.*?)```", page.read_text(), re.S))) if page.exists() else 0


def _deal_executed_pages(app, env, docnames: list[str]) -> None:
    """Sphinx reads the pages in chunks of consecutive (sorted) names, a process a chunk, and the executed pages'
    kernels take nearly all of the reading: sorted, the tutorials fell in one chunk, run one after another in
    one process while the other waited (258 of 382 s of kernels). Deal them out over the chunks instead, back
    and forth, the longest code first (their code's length stands for their time); the other pages fill up."""
    if FAST or app.parallel <= 1:
        return
    from sphinx.util.parallel import make_chunks

    chunks = make_chunks(docnames, app.parallel)
    executed = sorted((d for d in docnames if _code_length(d)), key=_code_length, reverse=True)
    dealt: list[list[str]] = [[] for _ in chunks]
    for i, docname in enumerate(executed):
        turn, k = divmod(i, len(chunks))
        dealt[k if turn % 2 == 0 else len(chunks) - 1 - k].append(docname)
    rest = iter(d for d in docnames if d not in executed)
    docnames[:] = [d for chunk, mine in zip(chunks, dealt) for d in [*mine, *itertools.islice(rest, len(chunk) - len(mine))]] + list(rest)


def setup(app) -> None:
    app.connect("autodoc-process-docstring", _constant_docstring)
    app.connect("env-before-read-docs", _deal_executed_pages)


def _parameter_table() -> None:
    """The free parameters' table (guide/fitting.md includes it), written from the registry itself."""
    target = Path(__file__).parent / "_generated" / "parameters.md"
    target.parent.mkdir(exist_ok=True)
    target.write_text(spacefit.parameter_table() + "\n")


def _front_picture() -> None:
    """The front page's picture: the default scene rendered now, small (its preview.png)."""
    import shutil
    import tempfile

    target = Path(__file__).parent / "_generated" / "lander.png"
    target.parent.mkdir(exist_ok=True)
    scene = spacefit.load_scene(None, {"render.resolution": [240, 240], "camera.pixel_pitch_mm": 3.5, "render.spp": 16})
    with tempfile.TemporaryDirectory() as tmp:
        spacefit.render_to_folder(scene, Path(tmp) / "render", quiet=True)
        shutil.copyfile(Path(tmp) / "render" / "preview.png", target)


_parameter_table()
_front_picture()
