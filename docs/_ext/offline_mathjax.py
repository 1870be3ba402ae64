"""MathJax served from the site itself, so that the equations render offline.

Sphinx's ``sphinx.ext.mathjax`` loads MathJax from a CDN by default, which fails silently without a
network. The PyPI package ``sphinx-mathjax-offline`` ships MathJax 3 (scripts and fonts); this
extension points ``mathjax_path`` at its copy under ``_static/mathjax`` and copies it there after a
build. (The package's own ``setup`` does the same but does not declare itself safe for a parallel
build, which ``-j auto`` with ``-W`` turns into an error.)
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from sphinx.application import Sphinx
from sphinx.util.fileutil import copy_asset

PACKAGE = "sphinx-mathjax-offline"
MISSING = f"the docs need MathJax served offline: pip install {PACKAGE} (the docs extra, pip install -e '.[docs]')"


def mathjax_folder() -> Path:
    """The package's MathJax folder (``static/mathjax``, tex-chtml.js and its fonts)."""
    spec = importlib.util.find_spec(PACKAGE)
    if spec is None or spec.origin is None:
        raise RuntimeError(MISSING)
    return Path(spec.origin).parent / "static" / "mathjax"


def _copy(app: Sphinx, exception: Exception | None) -> None:
    if exception is None and app.builder.format == "html":
        copy_asset(str(mathjax_folder()), str(Path(app.outdir) / "_static" / "mathjax"))


def setup(app: Sphinx) -> dict[str, bool]:
    mathjax_folder()  # fail at once, naming the package, where it is missing
    app.setup_extension("sphinx.ext.mathjax")
    app.config.mathjax_path = "mathjax/tex-chtml.js"
    app.connect("build-finished", _copy)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
