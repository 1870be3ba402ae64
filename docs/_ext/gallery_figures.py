"""sphinx-gallery's scraper for the figures spacefit returns (a module of its own: Sphinx pickles the configuration)."""

from __future__ import annotations


def figures_in(namespace: dict) -> list:
    """The matplotlib Figures of the Figures, Axes or arrays of Axes (what spacefit's plot functions
    return) that a script's variables hold, each once."""
    import numpy as np
    from matplotlib.artist import Artist
    from matplotlib.figure import Figure

    found = []
    for value in list(namespace.values()):
        if isinstance(value, (list, tuple, np.ndarray)) and len(value):
            value = np.ravel(np.asarray(value, dtype=object))[0]  # an array of axes: its first one's figure
        figure = value.figure if isinstance(value, Artist) and not isinstance(value, Figure) else value
        if isinstance(figure, Figure) and all(figure is not f for f in found):
            found.append(figure)
    return found


class FigureScraper:
    """sphinx-gallery's scraper for the figures spacefit returns: its plot functions make ``matplotlib.figure.Figure``
    objects outside pyplot (no global state) and return their axes, which the matplotlib scraper cannot see; this one
    saves each figure of :func:`figures_in` once."""

    def __repr__(self) -> str:  # sphinx-gallery keys its cache by the scrapers' reprs
        return "spacefit.FigureScraper"

    def __call__(self, block, block_vars, gallery_conf) -> str:
        from sphinx_gallery.scrapers import figure_rst

        paths = []
        for figure in figures_in(block_vars["example_globals"]):
            if not getattr(figure, "_shown_in_gallery", False):
                figure._shown_in_gallery = True
                path = next(block_vars["image_path_iterator"])
                figure.savefig(path, dpi=80)
                paths.append(path)
        return figure_rst(paths, gallery_conf["src_dir"])
